"""Hard steps: the ~60k-tetrahedron beam against plain Newton, and scenes x Hessian modes.

    fem-anim bench --hard [--reduced] [--only "PART;..."] [--modes M,...] [-o TABLE.md]
    python -m fem_anim.bench.hard --plain [SCENE] [--element-size H] [--preset P] [--out DIR]

**Scenes x Hessian modes** (:func:`hessian_table`, ``fem-anim bench --hard``): each hard scene
(:func:`hard_scenes`: the ~55k-tetrahedron hanging beam with cg-icc, the crushed cube in StVK
and stable neo-Hookean, the bar stretched to 3x, the spinning body, nu = 0.4999 with P1 and
P2, the default scene for 3000 steps) is run in this process with every ``solver.hessian``
(exact, shift, project = clamp, abs, trust_region_filter, auto): Newton iterations (and how
many used each kind of Hessian), adaptive retries, wall time of the stepping (mesh and JIT
excluded), whether it finished and, if not, the message it stopped with. ``--reduced`` runs
small variants (coarse meshes, few steps) in seconds: tests/test_hessian_modes.py runs it.

**Plain Newton** (:func:`hard_run`, ``--plain``; ``fem-anim bench --perf --hard``): each
configuration is a complete ``fem-anim run`` (60 steps of dt = 1/60 s, Newmark) in its
own process. "Plain" is what DOLFINx + SNES gives without fem_anim's safeguards: full Newton
steps (``-snes_linesearch_type basic``), no inversion filter, no adaptive dt; a variant keeps
the backtracking line search on the objective but not the filter. fem_anim's configuration
is its default (line search on g = +inf where det F <= 0, inversion filter, adaptive dt),
and the same with the shifted Hessian. Reported: whether the run finished, where and why it
stopped, Newton iterations, retries and wall time.
"""

from __future__ import annotations

import csv
import datetime
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from fem_anim.output.products import check_may_write, write_product

__all__ = ["CONFIGS", "HESSIAN_MODES", "HardScene", "hard_run", "hard_scenes", "hessian_table",
           "run_case", "run_scene"]

HARD_ELEMENT_SIZE = 0.015  # 55k tetrahedra on the default beam
CONFIGS = (
    ("plain Newton (full steps, no filter, fixed dt)",
     ["solver.inversion_filter=false", "time.adaptive=false"],
     ["-snes_linesearch_type", "basic"]),
    ("Newton + backtracking on g, no filter, fixed dt",
     ["solver.inversion_filter=false", "time.adaptive=false"], []),
    ("fem_anim default (line search on g, J > 0 filter, adaptive dt)", [], []),
    ("fem_anim, shifted Hessian", ["solver.hessian=\"shift\""], []),
)


def run_case(scene_path, overrides, petsc, preset: str, timeout: float = 3600.0) -> dict:
    """One complete run in a subprocess; its outcome, stats and wall time."""
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [sys.executable, "-m", "fem_anim", "run", *([scene_path] if scene_path else []),
               "-q", "-o", str(Path(tmp) / "run"), "--solver", preset,
               "--set", "output.render=false"]
        for o in overrides:
            cmd += ["--set", o]
        cmd += petsc
        env = {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_"))}
        start = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
        wall = time.perf_counter() - start
        stats = Path(tmp) / "run" / "stats.csv"
        if not stats.exists():
            stats = Path(tmp) / "run" / ".partial" / "stats.csv"
        rows = list(csv.DictReader(stats.open())) if stats.exists() else []
        error = [ln for ln in proc.stderr.splitlines() if ln.startswith("fem-anim: error:")]
        return {"finished": proc.returncode == 0, "wall": wall, "rows": rows,
                "error": error[-1][len("fem-anim: error: "):] if error else "",
                "steps": len(rows),
                "newton_its": sum(int(r["newton_its"]) for r in rows),
                "retries": sum(int(r["retries"]) for r in rows),
                "t_end": float(rows[-1]["time"]) if rows else 0.0}


def hard_run(scene_path, overrides, out: Path, log=print, h: float = HARD_ELEMENT_SIZE,
             preset: str = "cg-icc") -> str:
    """Run every configuration; the markdown section (also ``out/plain_newton.md``)."""
    from fem_anim.bench.report import md_table

    body = []
    for label, sets, petsc in CONFIGS:
        r = run_case(scene_path, [*overrides, f"mesh.element_size={h}", *sets], petsc, preset)
        reason = r["error"].split("; the frames so far")[0]  # without the temporary path
        outcome = "finished" if r["finished"] else f"stopped: {reason}"
        log(f"  {label}: {outcome} ({r['steps']} steps to t = {r['t_end']:.3f} s, "
            f"{r['newton_its']} Newton its, {r['retries']} retries, {r['wall']:.0f} s)")
        body.append([label, "yes" if r["finished"] else "no", f"{r['t_end']:.3f}",
                     r["newton_its"], r["retries"], r["wall"], outcome.replace("|", "/")])
    text = ("## The 60k run\n\n"
            f"Default scene (neo-Hookean beam, Newmark, dt = 1/60 s, 60 steps), "
            f"mesh.element_size = {h} (55k tetrahedra at 0.015), preset {preset}, each a "
            "complete `fem-anim run`.\n\n"
            + md_table(["configuration", "finished", "t reached, s", "Newton its", "retries",
                        "wall s", "outcome"], body))
    write_product(out / "plain_newton.md", (text + "\n").encode())
    return text


#: ``solver.hessian`` values of the table, in its column order ("project" clamps).
HESSIAN_MODES = ("exact", "shift", "project", "abs", "trust_region_filter", "auto")


@dataclass
class HardScene:
    """One hard scene: its name, how to build it, the preset, and the frames to run."""

    name: str
    data: dict | None  # a scene dictionary (extreme_cases.scene_text); None: the default scene
    overrides: tuple[str, ...] = ()
    preset: str | None = None
    steps: int = 60


def _crushed_cube(model: str, element_size: float) -> dict:
    """tests/test_solver_menu.py's compression: a 0.2 m cube, E = 1e4 Pa, the press moves
    5 cm per step of 0.05 s (implicit Euler) until it has crushed the cube to 15 %."""
    return {"name": f"crushed_{model}",
            "mesh": {"size": [0.2, 0.2, 0.2], "element_size": element_size},
            "material": {"model": model, "youngs_modulus": 1e4, "poisson_ratio": 0.3},
            "time": {"integrator": "implicit_euler", "dt": 0.05},
            "pin": [{"name": "floor", "min": [-1.0, -1.0, -0.001], "max": [1.0, 1.0, 0.001]},
                    {"name": "press", "min": [-1.0, -1.0, 0.199], "max": [1.0, 1.0, 0.201],
                     "velocity": [0.0, 0.0, -1.0], "until": 0.17}],
            "output": {"render": False}}


def hard_scenes(reduced: bool = False) -> list[HardScene]:
    """The scenes of the table (``reduced``: coarse, short variants that run in seconds)."""
    from fem_anim.bench.extreme_cases import cases

    extreme = {case.name: case for case in cases(full=not reduced)}
    out = []
    if not reduced:
        # the default beam without its Rayleigh damping (damping.beta = 1e-4): the undamped
        # beam is the harder scene
        out.append(HardScene("hanging beam, 55k tets, cg-icc, undamped", None,
                             (f"mesh.element_size={HARD_ELEMENT_SIZE}", "damping.beta=0"),
                             "cg-icc", 60))
    size = 0.1 if reduced else 0.05
    out += [HardScene("crushed cube, StVK", _crushed_cube("stvk", size), steps=4),
            HardScene("crushed cube, stable neo-Hookean",
                      _crushed_cube("stable_neohookean", size), steps=4)]
    names = ["stretched to 3x length", "nu = 0.4999, P2"] if reduced else \
        ["stretched to 3x length", "spinning body (half a turn in 1 s), neohookean",
         "nu = 0.4999, P1", "nu = 0.4999, P2"]
    for name in names:
        case = extreme[name]
        out.append(HardScene(name + (" (2D)" if reduced else ""), case.keys, steps=case.steps))
    if not reduced:
        out.append(HardScene("default scene, 3000 steps", None, (), None, 3000))
    return out


def _scene(hard: HardScene, mode: str):
    from fem_anim.bench.extreme_cases import load_case_scene
    from fem_anim.scene.loading import load_scene

    sets = [f'solver.hessian="{mode}"', f"time.steps={hard.steps}", "output.render=false"]
    if hard.data is None:
        return load_scene(None, [*hard.overrides, *sets])
    data = {k: (dict(v) if isinstance(v, dict) else v) for k, v in hard.data.items()}
    data["solver"] = dict(data.get("solver", {}), hessian=mode)
    data["time"] = dict(data["time"], steps=hard.steps)
    return load_case_scene(data)


def run_scene(hard: HardScene, mode: str, comm=None) -> dict:
    """Run a hard scene with one Hessian mode to its end or its error (in this process).

    Returns:
        finished, t reached, Newton iterations (total and per kind of Hessian), retries,
        the stepping's wall time (s) and the error message if it stopped.
    """
    from mpi4py import MPI

    from fem_anim.errors import ConvergenceError
    from fem_anim.simulation.adaptive import AdaptiveStepper
    from fem_anim.simulation.loop import Simulation
    from fem_anim.solver.hessian_choice import HESSIAN_KINDS

    comm = comm or MPI.COMM_WORLD
    scene = _scene(hard, mode)
    sim = Simulation(scene, comm, {}, preset=hard.preset)
    h = scene["time"]["dt"]
    stepper = AdaptiveStepper(sim, h, scene["time"])
    state = sim.initial_state()
    rows, error = [], ""
    start = time.perf_counter()
    try:
        for frame in range(1, hard.steps + 1):
            for state, row in stepper.advance(state, frame * h):
                rows.append(row)
    except ConvergenceError as err:
        error = str(err)
    wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    sim.minimiser.destroy()
    return {"finished": not error, "t_end": state.time, "wall": wall, "error": error,
            "newton_its": sum(r["newton_its"] for r in rows),
            "retries": sum(r["retries"] for r in rows),
            "by_kind": {k: sum(r[f"{k}_its"] for r in rows) for k in HESSIAN_KINDS}}


def hessian_table(reduced: bool = False, only: list[str] | None = None,
                  modes: tuple[str, ...] = HESSIAN_MODES, log=print) -> tuple[str, list]:
    """Every hard scene with every Hessian mode; the markdown table and the raw results."""
    from fem_anim.bench.report import md_table

    results = []
    body = []
    for hard in hard_scenes(reduced):
        if only and not any(o in hard.name for o in only):
            continue
        for mode in modes:
            r = run_scene(hard, mode)
            results.append((hard.name, mode, r))
            kinds = "/".join(str(r["by_kind"][k]) for k in ("exact", "shift", "clamp", "abs"))
            outcome = "finished" if r["finished"] else \
                "stopped: " + r["error"].replace("|", "/")
            log(f"hard: {hard.name}, {mode}: {outcome[:160]} ({r['newton_its']} Newton its, "
                f"{r['retries']} retries, {r['wall']:.1f} s)")
            body.append([hard.name, mode, "yes" if r["finished"] else "no", f"{r['t_end']:.4g}",
                         r["newton_its"], kinds, r["retries"], f"{r['wall']:.1f}",
                         "" if r["finished"] else outcome])
    table = md_table(["scene", "solver.hessian", "finished", "t reached, s", "Newton its",
                      "exact/shift/clamp/abs its", "retries", "wall s", "outcome"], body)
    return table, results


def main(argv: list[str] | None = None) -> int:
    """``fem-anim bench --hard``: the scenes x Hessian modes table (``--plain``: the 60k runs)."""
    import argparse

    from mpi4py import MPI

    p = argparse.ArgumentParser(prog="fem-anim bench --hard")
    p.add_argument("scene", nargs="?", help="--plain: the scene (default: the hanging beam)")
    p.add_argument("--plain", action="store_true", help="plain Newton against fem_anim (60k)")
    p.add_argument("--reduced", action="store_true", help="small variants (seconds)")
    p.add_argument("--only", help="parts of scene names to run, separated by ';' (names "
                   "contain commas)")
    p.add_argument("--modes", default=",".join(HESSIAN_MODES), help="comma-separated modes")
    p.add_argument("--element-size", type=float, default=HARD_ELEMENT_SIZE)
    p.add_argument("--preset", default="cg-icc")
    p.add_argument("--out", default="demos/results/hard")
    p.add_argument("-o", "--output", help="also write the table to this markdown file")
    args = p.parse_args(argv)
    if args.plain:
        out = Path(args.out)
        check_may_write(out, ["plain_newton.md"])  # before the runs, not after
        print(hard_run(args.scene, [], out, h=args.element_size, preset=args.preset))
        return 0
    from fem_anim.console import quiet_jit_logging
    from fem_anim.bench.trade import machine_description

    quiet_jit_logging()
    rank0 = MPI.COMM_WORLD.rank == 0
    if args.output:  # before the runs, not after
        check_may_write(Path(args.output).parent, [Path(args.output).name], MPI.COMM_WORLD)
    modes = tuple(args.modes.split(","))
    before = machine_description()
    table, _ = hessian_table(args.reduced, args.only.split(";") if args.only else None, modes,
                             log=lambda line: rank0 and print(line, file=sys.stderr, flush=True))
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    command = " ".join(["fem-anim bench --hard", *(argv or [])])
    text = (f"Measured {stamp} on {before} at the start and load average "
            f"{', '.join(f'{x:.2f}' for x in os.getloadavg())} at the end; `{command}`.\n\n"
            + table)
    if rank0:
        print(text)
        if args.output:
            write_product(Path(args.output), (text + "\n").encode())
    return 0


if __name__ == "__main__":
    sys.exit(main())
