"""``fem-anim fit``: fit scene parameters to a reference run's trajectory.

    fem-anim fit [SCENE] --target RUN_DIR --param material.youngs_modulus
                 --param material.poisson_ratio [--bounds KEY=LOW,HIGH] [-o OUTDIR]

The objective is :class:`~fem_anim.adjoint.objectives.TrajectoryMatch` of the target run
(same mesh; its frames at the scene's step times), minimised by L-BFGS-B
(:mod:`fem_anim.adjoint.fit`) with the adjoint gradient. Every evaluation is printed and
written as a row of ``fit.csv`` (parameters, objective, gradient norm, whether L-BFGS-B
accepted it as an iterate); ``fit.json`` holds the final parameters under their scene keys
(e.g. ``"material.youngs_modulus"``), J, |dJ/dtheta|, and the iteration counts;
``cell_gradient.vtu`` the gradient per cell there of the parameters that have one
(:mod:`fem_anim.adjoint.cell_gradient`; ParaView reads it). The output
directory is claimed like a run directory (:func:`fem_anim.output.rundir.claim`): a folder
fem_anim did not make is never written into. A parameter the scene does not have, a target
on another mesh or a forward step that does not converge is one error line (exit code 2).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from fem_anim.console import OneLineParser, quiet_jit_logging
from fem_anim.errors import FemAnimError, describe_os_error

__all__ = ["CELL_GRADIENT", "build_fit_parser", "fit_command", "parse_bounds"]

#: The gradient per cell at the best parameters (:mod:`fem_anim.adjoint.cell_gradient`)
CELL_GRADIENT = "cell_gradient.vtu"


def build_fit_parser() -> OneLineParser:
    """The arguments of ``fem-anim fit``."""
    parser = OneLineParser(prog="fem-anim fit",
                           description="fit scene parameters to a reference run (L-BFGS-B "
                           "with the adjoint gradient)")
    parser.add_argument("scene", nargs="?", help="scene TOML file (default: the hanging beam)")
    parser.add_argument("--target", required=True, metavar="RUN_DIR",
                        help="a finished run on the same mesh whose trajectory is matched")
    parser.add_argument("--param", action="append", required=True, metavar="KEY",
                        help="a scene key to fit (material.youngs_modulus, "
                        "material.poisson_ratio, material.density, damping.alpha, "
                        "damping.beta, initial.velocity, initial.angular_velocity, "
                        "initial.displacement, pin.NAME.velocity, obstacle.NAME.friction, "
                        "contact.friction; a body's or region's: "
                        "body.NAME.material.youngs_modulus, region.NAME.material.density, "
                        "body.NAME.initial.velocity, ...; docs/gradients.md lists them)")
    parser.add_argument("--bounds", action="append", default=[], metavar="KEY=LOW,HIGH",
                        help="bounds of a parameter (default: E, rho and friction within "
                        "x1000 of the start, nu in (-0.99, 0.499))")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="override a scene key (value parsed as TOML)")
    parser.add_argument("--max-iterations", type=int, default=30,
                        help="L-BFGS-B's iteration budget (default 30)")
    parser.add_argument("--storage", default="auto",
                        choices=["auto", "memory", "revolve", "disk"],
                        help="where the forward states are kept (default auto: memory while "
                        "they fit in 256 MiB per rank, else revolve)")
    parser.add_argument("--checkpoints", type=int, default=None, metavar="C",
                        help="revolve's most states kept in memory (default: as many as fit)")
    parser.add_argument("-o", "--output", help="output directory (default out/<scene>-fit)")
    parser.add_argument("-q", "--quiet", action="store_true", help="print only errors")
    return parser


def parse_bounds(texts: list[str], names: list[str], defaults: list) -> list:
    """``KEY=LOW,HIGH`` entries over the default bounds (``initial.velocity`` bounds every
    component).

    Raises:
        FemAnimError: a malformed entry or a key not among the fitted parameters.
    """
    bounds = list(defaults)
    for text in texts:
        key, sep, values = text.partition("=")
        parts = values.split(",")
        try:
            if not sep or len(parts) != 2:
                raise ValueError
            low, high = (float(v) for v in parts)
        except ValueError:
            raise FemAnimError(f"--bounds {text}: expected KEY=LOW,HIGH") from None
        if not low < high:
            raise FemAnimError(f"--bounds {text}: LOW must be below HIGH")
        hits = [i for i, n in enumerate(names) if n == key or n.startswith(key + "[")]
        if not hits:
            raise FemAnimError(f"--bounds {key}: not one of the fitted parameters "
                               f"({', '.join(names)})")
        for i in hits:
            bounds[i] = (low, high)
    return bounds


def fit_command(argv: list[str], cli_options: dict[str, str]) -> int:
    """Run ``fem-anim fit`` (collective); errors are raised for the caller to print.

    Returns:
        0.

    Raises:
        FemAnimError: bad arguments, a bad target, a non-converged forward step.
    """
    from mpi4py import MPI

    from fem_anim.scene.loading import load_scene

    args = build_fit_parser().parse_args(argv)
    if args.max_iterations < 1:
        raise FemAnimError(f"--max-iterations must be at least 1, got {args.max_iterations}")
    scene = load_scene(args.scene, args.overrides)
    if not (Path(args.target) / "trajectory.h5").is_file():
        raise FemAnimError(f"--target {args.target}: not a finished run directory "
                           "(no trajectory.h5)")
    out = Path(args.output or f"out/{scene.name}-fit")
    if out.exists() and not out.is_dir():
        raise FemAnimError(f"output directory {out} exists and is not a directory")
    from fem_anim.adjoint.differentiate import AdjointModel
    from fem_anim.adjoint.fit import default_bounds, fit
    from fem_anim.adjoint.objectives import TrajectoryMatch
    from fem_anim.output.rundir import claim

    comm = MPI.COMM_WORLD
    quiet_jit_logging()
    model = AdjointModel(scene, args.param, comm, cli_options, storage=args.storage,
                         checkpoints=args.checkpoints)
    start = model.parameters.values()
    bounds = parse_bounds(args.bounds, model.names,
                          [default_bounds(n, t) for n, t in zip(model.names, start)])
    objective = TrajectoryMatch(args.target)
    model.bind(objective)  # a target on another mesh: refused before the first run
    lock = None
    error = None
    if comm.rank == 0:
        try:
            lock = claim(out)
        except FemAnimError as err:
            error = str(err)
    error = comm.bcast(error, root=0)
    if error is not None:
        raise FemAnimError(error)
    rows = [",".join(["evaluation", *model.names, "objective", "gradient_norm", "accepted"])]

    def report(entry: dict) -> None:
        values = ",".join(repr(float(v)) for v in entry["theta"])
        rows.append(f"{len(rows)},{values},{entry['value']!r},{entry['gradient_norm']!r},"
                    "{accepted}")
        if not args.quiet and comm.rank == 0:
            named = ", ".join(f"{n} = {v:.6g}" for n, v in zip(model.names, entry["theta"]))
            print(f"fit: {named}: J = {entry['value']:.6g}, "
                  f"|dJ/dtheta| = {entry['gradient_norm']:.3g}", flush=True)

    try:
        result = fit(model, objective, bounds, args.max_iterations, report=report)
        if result.cell_gradient:  # at the best parameters (collective: gathered to rank 0)
            from fem_anim.adjoint.cell_gradient import write_cell_gradient

            write_cell_gradient(out / CELL_GRADIENT, model, result.cell_gradient)
        error = None
        if comm.rank == 0:
            try:
                _write_results(out, rows, result, model, args)
            except OSError as err:
                error = f"cannot write the fit's results: {describe_os_error(err)}"
        error = comm.bcast(error, root=0)
        if error is not None:
            raise FemAnimError(error)
    finally:
        if lock is not None:
            os.close(lock)
    return 0


def _write_results(out: Path, rows: list[str], result, model, args) -> None:
    """fit.csv and fit.json into the claimed directory, listed in its manifest (rank 0)."""
    from fem_anim.output.rundir import read_manifest, write_atomically, write_manifest

    lines = [rows[0]] + [row.format(accepted=int(entry["accepted"]))
                         for row, entry in zip(rows[1:], result.history)]
    summary = {**model.parameters.scene_values(), "objective": result.value,
               "gradient_norm": float(sum(g * g for g in result.gradient) ** 0.5),
               "iterations": result.iterations, "evaluations": result.evaluations,
               "message": result.message, "target": str(args.target)}
    write_atomically(out / "fit.csv", ("\n".join(lines) + "\n").encode())
    write_atomically(out / "fit.json", (json.dumps(summary, indent=2) + "\n").encode())
    written = {"fit.csv", "fit.json"} | ({CELL_GRADIENT} if result.cell_gradient else set())
    write_manifest(out, read_manifest(out) | written)
    if not args.quiet:
        print(f"fit: {result.message} after {result.iterations} iterations; "
              f"results in {out}/fit.json")
