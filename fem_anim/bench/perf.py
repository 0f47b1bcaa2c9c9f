"""``fem-anim bench --perf SCENE``: where a step's time goes, and how it grows.

    python -m fem_anim.bench.perf [SCENE] [--sizes H,H,...] [--presets P,P] [--steps N]
        [--mpi] [--blas] [--options] [--hard] [--peers] [--out DIR] [--set KEY=VALUE ...]
        [PETSc options ...]

For every mesh element size (``mesh.element_size`` overrides) and preset, one subprocess
(:mod:`fem_anim.bench.worker`) builds the scene with the library's own code and times a few
implicit steps, split by PETSc's log events into residual, Jacobian, objective (line search
and convergence tests), inversion filter, energies, symbolic and numeric factorisation,
linear solve and everything else (:mod:`fem_anim.bench.timing`). The growth exponent of the
step time against the number of dofs is fitted per preset. Optional sections:

* ``--mpi``: the largest mesh with ``mpirun -n 2`` and the parallel preset, against serial,
  ``--repeats`` back-to-back pairs (median and every repeat's speed-up);
* ``--blas``: reference BLAS/LAPACK against OpenBLAS (``LD_LIBRARY_PATH`` in the worker);
* ``--options``: Jacobian lagging, Eisenstat-Walker forcing, BAIJ storage: time and the
  tip's deviation from the exact run (:mod:`fem_anim.bench.options`);
* ``--hard``: the ~60k-tetrahedron run plain Newton cannot finish (:mod:`fem_anim.bench.hard`);
* ``--peers``: the same beam in the numpy reference and pbatoolkit
  (:mod:`fem_anim.bench.peers`).

Writes ``perf.csv``, ``perf.md`` and ``perf.png`` (and the sections' tables) to ``--out``;
a file of these names there that fem_anim did not write is refused before the sweep starts
(:mod:`fem_anim.output.products`).
Errors a user can cause end with one line ``fem-anim: error: ...`` and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fem_anim.console import OneLineParser
from fem_anim.errors import FemAnimError, describe_os_error
from fem_anim.output.products import check_may_write

__all__ = ["main", "build_parser", "run_config", "DEFAULT_SIZES", "DEFAULT_PRESETS"]

#: gmsh element sizes of the sweep on the default beam: ~1.8k to ~280k tetrahedra.
DEFAULT_SIZES = (0.05, 0.025, 0.0175, 0.0125, 0.009)
DEFAULT_PRESETS = ("cholesky", "cg-icc")
#: Direct presets stop at this element size (~94k tetrahedra: ~30 s per step here; the
#: ~270k mesh would take a quarter of an hour per configuration).
DIRECT_MIN_SIZE = 0.0125
REFERENCE_BLAS = ("/usr/lib/x86_64-linux-gnu/blas", "/usr/lib/x86_64-linux-gnu/lapack")


def _floats(text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v]
    except ValueError:
        raise FemAnimError(f"--sizes: not a comma-separated list of numbers: {text}") from None
    if not values or any(not 0 < v < 10 for v in values):
        raise FemAnimError(f"--sizes: element sizes must be in (0, 10) m: {text}")
    return values


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="fem-anim bench --perf", description=__doc__.split("\n")[0])
    p.add_argument("scene", nargs="?", help="scene TOML (default: the hanging beam)")
    p.add_argument("--sizes", type=_floats, default=list(DEFAULT_SIZES),
                   help="comma-separated mesh.element_size values")
    p.add_argument("--presets", default=",".join(DEFAULT_PRESETS),
                   help="comma-separated solver presets")
    p.add_argument("--steps", type=int, default=3, help="timed steps per configuration")
    p.add_argument("--direct-min-size", type=float, default=DIRECT_MIN_SIZE,
                   help="smallest element size for direct presets (their cost grows fastest)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE")
    p.add_argument("--out", default="demos/results/perf", help="output directory")
    p.add_argument("--mpi", action="store_true", help="mpirun -n 2 on the largest mesh")
    p.add_argument("--repeats", type=int, default=3,
                   help="serial/mpirun pairs per preset in --mpi (the median is reported)")
    p.add_argument("--blas", action="store_true", help="reference BLAS against OpenBLAS")
    p.add_argument("--options", action="store_true", help="lagging, Eisenstat-Walker, BAIJ")
    p.add_argument("--hard", action="store_true", help="the 60k run plain Newton fails")
    p.add_argument("--peers", action="store_true", help="numpy reference and pbatoolkit")
    p.add_argument("--worker", metavar="JSON", help=argparse.SUPPRESS)
    p.add_argument("--preset", help=argparse.SUPPRESS)
    p.add_argument("--tip", action="store_true", help=argparse.SUPPRESS)
    return p


def _validate(args) -> None:
    from fem_anim.solver.presets import PRESETS

    if args.steps < 1 or args.steps > 1000:
        raise FemAnimError(f"--steps: must be between 1 and 1000, got {args.steps}")
    if not 1 <= args.repeats <= 20:
        raise FemAnimError(f"--repeats: must be between 1 and 20, got {args.repeats}")
    for name in args.presets.split(","):
        if name not in PRESETS:
            raise FemAnimError(f"--presets: unknown preset {name!r} (see `fem-anim solvers`)")


def mpirun_prefix(n: int) -> list[str]:
    """``mpirun -n n`` (with the flags root needs), or an error if there is no mpirun."""
    import shutil

    mpirun = shutil.which("mpirun")
    if mpirun is None:
        raise FemAnimError("--mpi: mpirun is not on PATH")
    cmd = [mpirun, "-n", str(n), "--oversubscribe"]
    if os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    return cmd


def run_config(scene_path: str | None, overrides: list[str], preset: str, steps: int,
               petsc: list[str] = (), ranks: int = 1, env: dict | None = None,
               timeout: float = 1800.0, tip: bool = False) -> dict:
    """Measure one configuration in a fresh process; returns the worker's JSON result
    (with ``tip``, also the tip's path: :func:`fem_anim.bench.worker.measure`).

    Raises:
        FemAnimError: if the worker fails (its last stderr line is quoted).
    """
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "result.json"
        cmd = [sys.executable, "-m", "fem_anim.bench.perf"]
        cmd += [scene_path] if scene_path else []
        for o in overrides:
            cmd += ["--set", o]
        cmd += ["--worker", str(out), "--preset", preset, "--steps", str(steps), *petsc]
        cmd += ["--tip"] if tip else []
        if ranks > 1:
            cmd = mpirun_prefix(ranks) + cmd
        environ = {k: v for k, v in os.environ.items()
                   if not k.startswith(("OMPI_", "PMIX_", "PMI_"))}
        environ |= env or {}
        proc = subprocess.run(cmd, capture_output=True, text=True, env=environ, timeout=timeout)
        if proc.returncode != 0 or not out.exists():
            tail = (proc.stderr.strip().splitlines() or ["(no output)"])[-1]
            raise FemAnimError(f"benchmark worker failed ({preset}, {' '.join(overrides)}): "
                               f"{tail}")
        return json.loads(out.read_text())


def sweep(args, petsc: list[str], log=print) -> list[dict]:
    """Every size x preset, each in its own process; rows for the tables."""
    rows = []
    for h in args.sizes:
        for preset in args.presets.split(","):
            if is_direct(preset) and h < args.direct_min_size:
                log(f"  h={h} {preset}: skipped (direct presets stop at "
                    f"--direct-min-size {args.direct_min_size})")
                continue
            start = time.perf_counter()
            r = run_config(args.scene, [*args.overrides, f"mesh.element_size={h}"], preset,
                           args.steps, petsc)
            row = {"element_size": h, "preset": preset, "ranks": r["ranks"], "tets": r["tets"],
                   "dofs": r["dofs"], "setup_s": r["setup_s"],
                   "first_step_s": r["first_step_s"], "peak_mb": r["peak_mb"], **r["mean"]}
            rows.append(row)
            log(f"  h={h} {preset}: {r['tets']} tets, {r['dofs']} dofs, "
                f"{row['wall']:.3f} s/step, {row['newton_its']:.1f} Newton its "
                f"({time.perf_counter() - start:.0f} s)")
    return rows


def is_direct(preset: str) -> bool:
    from fem_anim.solver.presets import PRESETS

    return PRESETS[preset].get("pc_type") in ("cholesky", "lu")


def _load() -> str:
    try:
        return open("/proc/loadavg", encoding="ascii").read().split()[0]
    except OSError:
        return "?"


def _sections(args, petsc, rows, out: Path, log) -> dict:
    from fem_anim.bench import report

    extra = {}
    if args.blas:
        log("BLAS: reference against OpenBLAS")
        extra["blas"] = report.blas_rows(args, petsc, run_config, REFERENCE_BLAS)
    if args.mpi:
        log("MPI: serial against mpirun -n 2 on the largest mesh")
        extra["mpi"] = report.mpi_rows(args, petsc, run_config, rows)
    if args.options:
        from fem_anim.bench.options import options_table

        log("options: lagging, Eisenstat-Walker, BAIJ")
        extra["options"] = options_table(args.scene, args.overrides, out, log)
    if args.hard:
        from fem_anim.bench.hard import hard_run

        log("hard run")
        extra["hard"] = hard_run(args.scene, args.overrides, out, log)
    if args.peers:
        from fem_anim.bench.peers import peer_table

        log("peers")
        extra["peers"] = peer_table(args.scene, args.overrides, out, log)
    return extra


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code (2 with one error line for bad input)."""
    from fem_anim.console import print_error
    from fem_anim.petsc_options import init_petsc, split_petsc_args

    argv = list(sys.argv[1:] if argv is None else argv)
    app_args, solver_options, global_args = split_petsc_args(argv)
    init_petsc(global_args)
    try:
        args = build_parser().parse_args(app_args)
        _validate(args)
        if args.worker:
            from fem_anim.scene.loading import load_scene
            from fem_anim.bench.worker import run_worker

            scene = load_scene(args.scene, args.overrides)
            run_worker(scene, args.preset, args.steps, solver_options, args.worker, args.tip)
            return 0
        from mpi4py import MPI

        if MPI.COMM_WORLD.size > 1:
            raise FemAnimError("run the benchmark driver serially; it starts mpirun itself")
        from fem_anim.bench import report

        petsc = [tok for k, v in solver_options.items() for tok in (f"-{k}", v) if tok]
        out = Path(args.out)
        sections = [name for flag, name in ((args.options, "options.md"),
                                            (args.hard, "plain_newton.md"),
                                            (args.peers, "peers.md")) if flag]
        check_may_write(out, [*report.PRODUCTS, *sections])  # before the sweep, not after
        log = print
        log(f"perf sweep (load {_load()}): sizes {args.sizes}, presets {args.presets}")
        rows = sweep(args, petsc, log)
        extra = _sections(args, petsc, rows, out, log)
        report.write(out, rows, extra, load=_load())
        log(report.exponent_text(rows))
        log(f"wrote {out}/perf.csv, perf.md, perf.png")
        return 0
    except FemAnimError as err:
        print_error(str(err))
        return 2
    except OSError as err:
        print_error(describe_os_error(err))
        return 2
    except KeyboardInterrupt:
        print_error("interrupted")
        return 130


if __name__ == "__main__":
    sys.exit(main())
