"""The ``fem-anim`` command line.

Usage::

    fem-anim run [SCENE.toml] [-o OUTDIR] [--set KEY=VALUE ...] [--solver NAME] [--preview]
                 [--quiet] [--resume OUTDIR] [PETSc options ...]
    fem-anim render OUTDIR [--set render.KEY=VALUE ...] [--quiet]
    fem-anim export OUTDIR [--format usd|obj|ply] [-o PATH] [--start-frame N] [--quiet]
    fem-anim solvers
    fem-anim bench [SCENE.toml] [--sweep KEY=V1,V2,...]... [--repeats N] [--reference KEY=V]...
                   [-o OUTDIR] | --extremes [--full] | --perf ... | --hard [--reduced]
                   | --contact [--size full|small|reduced]
    fem-anim fit [SCENE.toml] --target RUN --param KEY [--param KEY ...] [--bounds ...] [-o OUTDIR]

``run`` simulates a scene (each time step minimises the step objective g(x) of seed
section 3.1, eq. 4) and writes its run directory; ``render`` draws a saved run again;
``export`` writes a run as USD or OBJ/PLY sequences (:mod:`fem_anim.export`);
``solvers`` lists the linear solver presets; ``bench`` runs the benchmarks of
:mod:`fem_anim.bench`.

PETSc options (``-snes_*``, ``-ksp_*``, ``-pc_*``, ``-mat_*`` and global ones such as
``-log_view``) are split off before argparse sees the arguments and reach the step
solver with the highest precedence (:mod:`fem_anim.petsc_options`). Every error a user
can cause ends with one line ``fem-anim: error: ...`` on stderr and exit code 2.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fem_anim.console import OneLineParser, print_error, quiet_jit_logging
from fem_anim.errors import (ConvergenceError, FemAnimError, Interrupted, describe_library_error,
                             describe_os_error)
from fem_anim.export.export_command import add_export_parser, export_command
from fem_anim.petsc_options import check_cli_options, init_petsc, split_petsc_args

__all__ = ["main", "build_parser"]

EXIT_USAGE = 2


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``run``, ``render`` and ``solvers`` (``bench`` parses its own).

    Returns:
        A parser whose errors are one ``fem-anim: error:`` line and exit code 2.
    """
    parser = OneLineParser(prog="fem-anim", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True, parser_class=OneLineParser)
    run = sub.add_parser("run", help="simulate a scene (default: the hanging beam)")
    run.add_argument("scene", nargs="?", help="scene TOML file (default: embedded hanging beam)")
    run.add_argument("-o", "--output", help="output directory (default out/<scene name>)")
    run.add_argument("--set", dest="overrides", action="append", default=[],
                     metavar="KEY=VALUE", help="override a scene key (value parsed as TOML)")
    run.add_argument("--solver", help="linear solver preset (see `fem-anim solvers`)")
    run.add_argument("--preview", action="store_true",
                     help="solver.mode = \"preview\": one Newton step per time step, fast and "
                          "approximate")
    run.add_argument("-q", "--quiet", action="store_true",
                     help="no progress bar and no summary: print only warnings and errors")
    run.add_argument("--resume", metavar="OUTDIR",
                     help="continue the unfinished run in OUTDIR from its last checkpoint")
    render = sub.add_parser("render", help="render a saved run again (no simulation)")
    render.add_argument("outdir", help="the output directory of a finished `fem-anim run`")
    render.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="render.KEY=VALUE", help="override a [render] key")
    render.add_argument("-q", "--quiet", action="store_true", help="print nothing")
    add_export_parser(sub)
    sub.add_parser("solvers", help="list the linear solver presets and their PETSc options")
    bench = sub.add_parser("bench", add_help=False,
                           help="trade study (SCENE --sweep KEY=V1,V2 ...; -h for its options), "
                           "--extremes (stability suite), --perf (performance bench) or "
                           "--hard (hard scenes x Hessian modes) or --contact (the contact "
                           "set beside a plain ipctk + scipy IPC step)")
    bench.add_argument("bench_args", nargs=argparse.REMAINDER)
    fit = sub.add_parser("fit", add_help=False,
                         help="fit scene parameters to a reference run by the discrete adjoint "
                         "(SCENE --target RUN --param KEY ...; -h for its options)")
    fit.add_argument("fit_args", nargs=argparse.REMAINDER)
    return parser


def resume_command(argv: list[str], out: str) -> str:
    """The command that continues an interrupted run.

    Args:
        argv: The interrupted run's arguments after ``fem-anim run``.
        out: Its output directory.

    Returns:
        ``fem-anim run`` with the same arguments (scene, ``--set``, ``--solver``, PETSc
        options) without ``-o``/``--resume``, then ``--resume OUT``; shell-quoted.
    """
    import shlex

    kept, skip = [], False
    for arg in argv:
        if skip:
            skip = False
        elif arg in ("-o", "--output", "--resume"):
            skip = True
        elif not arg.startswith(("--output=", "--resume=")):
            kept.append(arg)  # a compact -oDIR stays: it names the same directory
    return shlex.join(["fem-anim", "run", *kept, "--resume", out])


def _output_directory(args, scene) -> str:
    """The run's directory; ``--resume`` and ``-o`` must agree (a resumed run continues in
    its own directory)."""
    if args.resume is not None and args.output is not None and \
            Path(args.resume).resolve() != Path(args.output).resolve():
        raise FemAnimError(f"--resume {args.resume} and -o {args.output} name different "
                           "directories: a run is resumed in its own directory (drop -o)")
    out = args.resume or args.output or scene["output"]["directory"] or f"out/{scene.name}"
    if Path(out).exists() and not Path(out).is_dir():
        raise FemAnimError(f"output directory {out} exists and is not a directory")
    return out


def _run(args, cli_options: dict[str, str], argv: list[str]) -> int:
    from mpi4py import MPI

    from fem_anim.scene.loading import load_scene

    if args.solver is not None and not args.solver.strip():
        raise FemAnimError("--solver needs a preset name (see `fem-anim solvers`), got ''")
    # --preview is solver.mode = "preview", before the --set overrides (which win)
    overrides = (['solver.mode="preview"'] if args.preview else []) + args.overrides
    scene = load_scene(args.scene, overrides)  # validate before importing dolfinx
    out = _output_directory(args, scene)
    from fem_anim.scene.joint_rules import shell_body
    if shell_body(scene.data) is not None:  # a shell beside solids: two meshes, one step
        return _run_joint(args, scene, Path(out), cli_options, argv)
    from fem_anim.scene.contact_integrator import integrator_note
    if (note := integrator_note(scene.data)) and not args.quiet and MPI.COMM_WORLD.rank == 0:
        print(f"fem-anim: {note}", file=sys.stderr)
    from fem_anim.output.provenance import software_versions
    from fem_anim.output.rundir import read_manifest, write_manifest
    from fem_anim.simulation.energy_report import (describe_energy, energy_report,
                                                   initial_energies, write_summary)
    from fem_anim.simulation.interrupt import stop_at_once
    from fem_anim.simulation.loop import Simulation

    quiet_jit_logging()
    with stop_at_once():  # a signal while meshing or compiling: stop, leave no JIT lock
        sim = Simulation(scene, MPI.COMM_WORLD, cli_options, preset=args.solver)
        initial = initial_energies(sim)
    try:
        result = sim.run(Path(out), quiet=args.quiet, resume=args.resume is not None)
    except (ConvergenceError, Interrupted) as err:
        _say_what_is_kept(err, out, argv)
    report = energy_report(result.rows, initial, scene)
    if MPI.COMM_WORLD.rank == 0:
        write_summary(result.output_dir / "summary.json", scene, result.rows, report,
                      {"versions": software_versions(MPI.COMM_WORLD),
                       "petsc_options": sim.options,
                       "wall": sim.clock.as_dict()})
        write_manifest(result.output_dir, read_manifest(result.output_dir) | {"summary.json"})
        if not args.quiet or report["flagged"]:
            last = result.rows[-1]
            print(f"{scene.name}: {last['step']} steps to t = {last['time']:.4g} s, "
                  f"total energy {last['total_energy']:.6g} J; outputs in {result.output_dir}")
            print(f"{scene.name}: {describe_energy(report, scene)}")
    return 0


def _say_what_is_kept(err, out, argv: list[str]):
    """Raise ``err`` again, saying what the stopped run keeps and how to continue it."""
    from fem_anim.output.rundir import stopped_run_error

    raise stopped_run_error(err, Path(out), resume_command(argv, str(out))) from None


def _run_joint(args, scene, out: Path, cli_options: dict[str, str], argv: list[str]) -> int:
    """``fem-anim run`` of a scene with a shell body (:mod:`fem_anim.simulation.joint_run`)."""
    from mpi4py import MPI

    from fem_anim.output.provenance import software_versions
    from fem_anim.simulation.energy_report import describe_energy
    from fem_anim.simulation.interrupt import stop_at_once
    from fem_anim.simulation.joint_loop import JointSimulation
    from fem_anim.simulation.joint_run import run_joint

    quiet_jit_logging()
    with stop_at_once():  # a signal while meshing or compiling: stop, leave no JIT lock
        sim = JointSimulation.from_scene(scene, MPI.COMM_WORLD, cli_options, args.solver)
    try:  # later a signal stops the run at a frame's end (run_joint)
        rows, report = run_joint(scene, out, MPI.COMM_WORLD, cli_options, args.quiet,
                                 {"versions": software_versions(MPI.COMM_WORLD)},
                                 preset=args.solver, resume=args.resume is not None, sim=sim)
    except (ConvergenceError, Interrupted) as err:
        _say_what_is_kept(err, str(out), argv)
    if MPI.COMM_WORLD.rank == 0 and (not args.quiet or report["flagged"]):
        last = rows[-1]
        print(f"{scene.name}: {last['step']} steps to t = {last['time']:.4g} s, total "
              f"energy {last['total_energy']:.6g} J; outputs in {out}")
        print(f"{scene.name}: {describe_energy(report, scene)}")
    return 0


def _render(args) -> int:
    """Re-render a saved run with its own ``[render]`` settings and the overrides (rank 0)."""
    import json

    from mpi4py import MPI

    from fem_anim.render.animation import check_run_directory
    from fem_anim.render.process import render_run
    from fem_anim.output.rundir import check_not_in_use
    from fem_anim.scene.loading import validate_render

    outdir = Path(args.outdir)
    check_run_directory(outdir)
    check_not_in_use(outdir)
    saved = None
    if (outdir / "scene.json").is_file():
        try:
            saved = json.loads((outdir / "scene.json").read_text())["scene"].get("render")
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
            raise FemAnimError(f"{outdir / 'scene.json'} cannot be read: {err}") from None
    settings = validate_render(saved, args.overrides)
    if MPI.COMM_WORLD.rank == 0:
        render_run(outdir, settings, quiet=args.quiet)
    return 0


def _bench(argv: list[str]) -> int:
    """``fem-anim bench``: the trade study, or with ``--extremes`` / ``--perf`` / ``--hard`` /
    ``--contact`` another bench (``--perf --hard`` is the perf bench's 60k run)."""
    if "--perf" in argv:
        from fem_anim.bench import perf

        return perf.main([a for a in argv if a != "--perf"])
    if "--hard" in argv:
        from fem_anim.bench import hard

        return hard.main([a for a in argv if a != "--hard"])
    if "--contact" in argv:
        from fem_anim.bench import contact_set

        return contact_set.main([a for a in argv if a != "--contact"])
    if "--extremes" in argv:
        from fem_anim.bench import extremes

        return extremes.main([a for a in argv if a != "--extremes"])
    from fem_anim.bench import trade

    return trade.main(argv)


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``fem-anim``.

    Args:
        argv: The arguments after the program name (default: ``sys.argv[1:]``); PETSc
            options among them go to the step solver.

    Returns:
        The exit code: 0; 2 for an error a user can cause (one line on stderr); 128 + the
        signal number for a run a signal stopped; 130 for Ctrl-C.
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    app_args, solver_options, global_args = split_petsc_args(argv)
    try:
        check_cli_options(solver_options, global_args)
    except FemAnimError as err:
        print_error(str(err))
        return EXIT_USAGE
    init_petsc(global_args)
    try:
        if app_args[:1] == ["bench"]:  # its own parser: argparse's REMAINDER drops --options
            return _bench(app_args[1:])
        if app_args[:1] == ["fit"]:  # fem_anim.adjoint.fit_command parses its own arguments
            from fem_anim.adjoint.fit_command import fit_command
            return fit_command(app_args[1:], solver_options)
        args = build_parser().parse_args(app_args)
        if args.command == "solvers":
            from fem_anim.solver.presets import describe_presets

            print(describe_presets())
            return 0
        if args.command == "export":
            return export_command(args)
        if args.command == "render":
            return _render(args)
        rest = list(argv)
        rest.remove("run")
        return _run(args, solver_options, rest)
    except Interrupted as err:
        print_error(str(err))
        return 128 + err.signum
    except FemAnimError as err:
        print_error(str(err))
        return EXIT_USAGE
    except OSError as err:  # one a library call did not name itself: the file and why
        print_error(describe_os_error(err))
        return EXIT_USAGE
    except KeyboardInterrupt:
        print_error("interrupted")
        return 130
    except (MemoryError, RuntimeError) as err:  # from a compiled library (ipctk, PETSc)
        print_error(describe_library_error(err))
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
