"""fem_anim's preview and exact steps beside pbatoolkit's VBD on the peers' beam, in one run.

    python -m fem_anim.bench.preview [--divisions NX,NY,NZ ...] [--steps N] [--out DIR]

The beam of pbatoolkit's examples: a box 1 x 0.2 x 0.2 m of NX x NY x NZ cubes
cut into 6 tetrahedra each (``mesh.divisions``; 30 x 8 x 8 = 11 520 and 70 x 12 x 12 = 60 480
tetrahedra by default), pinned at x = 0, hanging under gravity from rest, stable neo-Hookean
(E = 1e5 Pa, nu = 0.3, 1000 kg/m^3), implicit Euler, dt = 1/60 s, 60 steps; the same mesh
arrays for every solver. Compared, each on its own and one after the other in one process:

* the reference: fem_anim's exact Newton with MUMPS Cholesky to its residual test
  (||grad g|| <= max(1e-12, 1e-8 ||grad g_0||));
* fem_anim's fastest exact configuration (``cg-icc``, ``solver.forcing = "adaptive"``), with
  ``solver.hessian = "auto"`` (the bent 60k beam's Hessian is indefinite from t ~ 0.5 s, where
  CG-ICC on the exact Hessian fails: that row is kept to show it);
* ``solver.mode = "preview"`` (:mod:`fem_anim.scene.modes`) and the other budgets of the
  front (:data:`CONFIGS`);
* pbatoolkit's vertex block descent (Chen et al. 2024) at each of :data:`VBD_SWEEPS` sweeps
  per step (:mod:`fem_anim.bench.pbat_worker`, in pbatoolkit's own virtual environment).

Accuracy is the tip (mean displacement of the vertices at x = 1) against the reference's:
its deviation at t = 0.5 s and t = 1 s and the largest over the run ("trajectory"), each
relative to the reference tip's largest displacement. Time is the mean wall time of steps
2..N; ratios to VBD are taken from the same run. Steps are plain (no adaptive retry): a
configuration whose step fails is listed with the step where it stopped.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from fem_anim.errors import ConvergenceError, FemAnimError
from fem_anim.output.products import check_may_write, write_product

__all__ = ["CONFIGS", "FLOOR", "SIZES", "VBD_SWEEPS", "compare", "main", "preview_table",
           "split_rows", "split_text", "tip_errors"]

SIZES = ((30, 8, 8), (70, 12, 12))
VBD_SWEEPS = (20, 100)
#: Scene keys shared by every fem_anim run (pbatoolkit's model and step).
BEAM = ['material.model="stable_neohookean"', 'time.integrator="implicit_euler"',
        "time.dt=0.016666666666666666", "output.render=false",
        "damping.beta=0"]  # pbatoolkit's beam is undamped (the default scene is not)
REFERENCE = "fem_anim exact, cholesky (reference)"
#: fem_anim's configurations after the reference: (label, preset or None, scene keys, ranks);
#: a row with ranks > 1 runs in its own process under ``mpirun -n ranks``.
EXACT = ("cg-icc", ['solver.forcing="adaptive"', 'solver.hessian="auto"'])
CONFIGS = (
    ("fem_anim exact, cg-icc, forcing adaptive, hessian auto", *EXACT, 1),
    ("fem_anim exact, cg-icc, forcing adaptive, hessian auto, mpirun -n 2", *EXACT, 2),
    ("fem_anim exact, cg-icc, forcing adaptive", "cg-icc", ['solver.forcing="adaptive"'], 1),
    ("fem_anim budget 2, cg-icc, forcing adaptive, hessian auto", "cg-icc",
     ["solver.max_iterations=2", 'solver.on_budget="accept"', 'solver.forcing="adaptive"',
      'solver.hessian="auto"'], 1),
    ('fem_anim preview (solver.mode = "preview")', None, ['solver.mode="preview"'], 1),
    ('fem_anim preview (solver.mode = "preview"), mpirun -n 2', "cg-icc",
     ['solver.mode="preview"'], 2),
    ("fem_anim preview, CG to 1e-2", None,
     ['solver.mode="preview"', "solver.petsc.ksp_rtol=1e-2"], 1),
)
TIMES = (0.5, 1.0)


def tip_errors(tip: np.ndarray, reference: np.ndarray, dt: float) -> list[float]:
    """Tip deviations at :data:`TIMES` (NaN past the run) and over the whole run.

    Each is the largest component of ``tip - reference`` at that step, relative to the
    reference tip's largest displacement component over the run.
    """
    n = min(len(tip), len(reference))
    scale = float(np.abs(reference).max())
    deviation = np.abs(np.asarray(tip[:n]) - np.asarray(reference[:n])).max(axis=1) / scale
    at = [float(deviation[k - 1]) if 1 <= (k := round(t / dt)) <= n else float("nan")
          for t in TIMES]
    return [*at, float(deviation.max())]


def compare(divisions, steps: int, python: Path | None, log=print, configs=CONFIGS,
            sweeps=VBD_SWEEPS, splits: dict | None = None) -> list[list]:
    """Rows [solver, tets, s/step, steps/s, Newton its/step, tip errors..., vs VBD] for one
    mesh; ``splits`` (if given) gets each fem_anim row's mean phase split by (tets, label)."""
    from mpi4py import MPI

    from fem_anim.mesh.build import build_mesh
    from fem_anim.scene.loading import load_scene
    from fem_anim.bench.peers import _fem_anim, _pbat

    keys = [*BEAM, f"mesh.divisions={list(divisions)}", f"time.steps={steps}"]
    scene = load_scene(None, keys)
    dt = scene["time"]["dt"]
    domain = build_mesh(MPI.COMM_SELF, scene)
    runs, failed = {}, {}
    tets = None
    for label, preset, extra, ranks in (("", "cholesky", [], 1), *configs):
        try:
            if ranks > 1:
                times, tip, r = _fem_anim_mpi([*keys, *extra], preset, steps, ranks)
            else:
                times, tip, r = _fem_anim(load_scene(None, [*keys, *extra]), preset, steps)
        except ConvergenceError as err:
            if not label:
                raise
            failed[label] = "stopped at " + str(err).split(":")[0]  # "step N (t = ...)"
            log(f"  {label}: {failed[label]}")
            continue
        except FemAnimError as err:  # mpirun missing or its worker failed to start
            failed[label] = f"not run ({err})"
            log(f"  {label}: {failed[label]}")
            continue
        its = float(np.mean([s["newton_its"] for s in r["steps"]]))
        runs[label or REFERENCE] = (times, tip, its)
        tets = r["tets"]
        if splits is not None:
            splits[(tets, label or REFERENCE)] = r["mean"]
        log(f"  {tets} tets {label or REFERENCE}: {np.mean(times[1:]):.4f} s/step")
    if python is not None:
        for n in sweeps:
            times, tip = _pbat(python, domain, scene, steps, "vbd", sweeps=n)
            runs[f"pbatoolkit VBD, {n} sweeps"] = (times, tip, float(n))
            log(f"  {tets} tets VBD {n}: {np.mean(times[1:]):.4f} s/step")
    reference = np.asarray(runs[REFERENCE][1])
    vbd = {n: float(np.mean(runs[f"pbatoolkit VBD, {n} sweeps"][0][1:]))
           for n in sweeps if f"pbatoolkit VBD, {n} sweeps" in runs}
    rows = []
    for name, (times, tip, its) in runs.items():
        per_step = float(np.mean(times[1:]))
        ratios = [v / per_step for v in vbd.values()]
        rows.append([name, tets, per_step, 1.0 / per_step, its,
                     *tip_errors(np.asarray(tip), reference, dt), *ratios])
    for name, where in failed.items():  # a run that failed: where, no figures
        rows.append([f"{name}: {where}", tets, *["-"] * (len(rows[0]) - 2)])
    return rows


#: The phases of a step (:data:`fem_anim.bench.worker.PHASE_COLUMNS`) that make its floor:
#: one Hessian assembly and one preconditioned solve per Newton iteration.
FLOOR = ("jacobian", "factor_symbolic", "factor_numeric", "solve")


def split_rows(splits: dict, labels=(CONFIGS[0][0], CONFIGS[1][0])) -> list[list]:
    """Where a step's time goes: [solver, tets, ranks, ms per phase..., ms/step, floor, x floor].

    The floor is the step's own Hessian assemblies and preconditioned solves (:data:`FLOOR`);
    the rest is what Newton with a line search adds (residuals, objectives, energies, Python).
    """
    from fem_anim.bench.worker import PHASE_COLUMNS

    rows = []
    for (tets, label), mean in splits.items():
        if label not in labels:
            continue
        floor = sum(mean[k] for k in FLOOR)
        rows.append([label, tets, *[1e3 * mean[k] for k in PHASE_COLUMNS],
                     1e3 * mean["wall"], mean["newton_its"], 1e3 * floor,
                     mean["wall"] / floor])
    return rows


def _fem_anim_mpi(overrides: list[str], preset: str, steps: int, ranks: int):
    """One configuration under ``mpirun -n ranks`` (its own process): step times, tip, result.

    Raises:
        FemAnimError: if mpirun is missing or the worker failed (its last line is quoted).
    """
    from fem_anim.bench.perf import run_config

    r = run_config(None, overrides, preset, steps, ranks=ranks, tip=True)
    return np.array([s["wall"] for s in r["steps"]]), np.array(r["tip"]), r


def preview_table(out: Path, sizes=SIZES, steps: int = 60, log=print,
                  sweeps=VBD_SWEEPS, install: bool = True) -> str:
    """The side-by-side table, also written to ``out/preview.md``."""
    from fem_anim.bench.peers import _load, peer_python
    from fem_anim.bench.report import machine_text, md_table

    python = peer_python(install)
    load = _load()
    rows, splits = [], {}
    for divisions in sizes:
        rows += compare(divisions, steps, python, log, sweeps=sweeps, splits=splits)
    shown = [n for n in sweeps] if python is not None else []
    headers = ["solver", "tets", "s/step", "steps/s", "its/step",
               *[f"tip dev. t = {t:g} s" for t in TIMES], "trajectory dev.",
               *[f"speed-up vs VBD-{n}" for n in shown]]
    note = "" if python is not None else (
        "\n\npbatoolkit could not be installed or imported here (see the message above): "
        "fem_anim's configurations only.")
    text = ("## Preview against VBD\n\n"
            f"Measured {machine_text(load)}. Regenerate: `python -m fem_anim.bench.preview`.\n"
            f"Beam 1 x 0.2 x 0.2 m of cubes cut into 6 tetrahedra, stable neo-Hookean, "
            f"implicit Euler, dt = 1/60 s, {steps} steps from rest, the same tetrahedra for "
            "every solver. 'tip dev.' is the tip's deviation from the reference run (fem_anim "
            "exact Newton, Cholesky) relative to its largest displacement; 'its/step' is "
            "Newton iterations (VBD: sweeps); 'speed-up vs VBD-n' is VBD's time per step "
            "over the row's, measured in the same run. pbatoolkit's stable neo-Hookean "
            "omits the log term of fem_anim's and is given lambda + mu (same rest response), "
            "so a converged pbatoolkit step would still differ slightly from the reference."
            "\n\n" + md_table(headers, rows) + note + "\n\n" + split_text(splits))
    write_product(out / "preview.md", (text + "\n").encode())
    return text


def split_text(splits: dict) -> str:
    """The phase table of the exact rows (serial and under mpirun), as Markdown."""
    from fem_anim.bench.report import md_table
    from fem_anim.bench.worker import PHASE_COLUMNS

    headers = ["solver", "tets", *[f"{k} ms" for k in PHASE_COLUMNS], "ms/step", "its/step",
               "floor ms", "x floor"]
    return ("### Where the exact step's time goes\n\nMean milliseconds per step (steps "
            "2..N) by phase, from PETSc's log events (:mod:`fem_anim.bench.timing`; under "
            "mpirun rank 0's split, the slowest rank's wall time). The floor is one Hessian "
            "assembly and one preconditioned solve per Newton iteration (jacobian + "
            "factorisations + solve of the same run).\n\n"
            + md_table(headers, split_rows(splits)))


def main(argv: list[str] | None = None) -> int:
    from fem_anim.console import OneLineParser, exit_status
    from fem_anim.petsc_options import init_petsc

    init_petsc([])

    p = OneLineParser(prog="python -m fem_anim.bench.preview", description=__doc__.split("\n")[0])
    p.add_argument("--divisions", action="append", default=[],
                   help="cubes per axis, NX,NY,NZ (repeat for several meshes)")
    p.add_argument("--steps", type=int, default=60)
    p.add_argument("--sweeps", default=",".join(map(str, VBD_SWEEPS)))
    p.add_argument("--no-install", action="store_true",
                   help="do not install pbatoolkit if it is missing (compare fem_anim only)")
    p.add_argument("--out", default="demos/results/preview")
    args = None

    def run() -> int:
        nonlocal args
        args = p.parse_args(list(sys.argv[1:] if argv is None else argv))
        try:
            sizes = [tuple(int(v) for v in d.split(",")) for d in args.divisions] or SIZES
            sweeps = tuple(int(v) for v in args.sweeps.split(","))
        except ValueError:
            raise FemAnimError("--divisions and --sweeps take whole numbers separated by "
                               f"commas, got {args.divisions} and {args.sweeps!r}") from None
        if any(len(d) != 3 or min(d) < 1 for d in sizes) or min(sweeps) < 1:
            raise FemAnimError(f"--divisions needs three numbers >= 1 each and --sweeps "
                               f"numbers >= 1, got {args.divisions} and {args.sweeps!r}")
        if not 2 <= args.steps <= 1000:
            raise FemAnimError(f"--steps: must be between 2 and 1000, got {args.steps}")
        out = Path(args.out)
        check_may_write(out, ["preview.md"])  # before the runs, not after
        print(preview_table(out, sizes, args.steps, sweeps=sweeps,
                            install=not args.no_install))
        return 0

    return exit_status(run, lambda: args.out)


if __name__ == "__main__":
    sys.exit(main())
