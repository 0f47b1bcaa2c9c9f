"""``python -m fem_anim.bench.contact_cost``: what contact between bodies costs per step.

    python -m fem_anim.bench.contact_cost [--element-size H] [--steps N] [--ranks R]
                                          [--baseline] [--out DIR]

Four soft boxes (0.1 m, ~6 (0.1/H)^3 tetrahedra each; H = 0.01 gives ~5k-6k) piling up on
the ground: two side by side on it, two turned 15 degrees and thrown down onto them, so
the IPC barrier is active from the first steps. The steps are taken as ``fem-anim run``
takes them (:class:`~fem_anim.simulation.adaptive.AdaptiveStepper`: a step that fails is
discarded and retried with dt halved). Each step is timed whole, discarded tries included
(``retries`` and their wall time ``retry_s`` are columns of the CSV), and split into the
solver's parts of its accepted substeps (assembly, factorisation, linear solves) and
ipctk's of all its tries (collision detection with the gathers to rank 0, barrier
value/gradient/Hessian with the scatter to the owners, CCD), from
:attr:`fem_anim.contact.ipc.IPCContact.timers`. ``--ranks R`` relaunches itself under
``mpirun -n R``. Prints a Markdown table and writes it (and the per-step CSV) to ``--out``.

``--baseline`` (serial only) then runs the plain ipctk + scipy IPC step of
:mod:`fem_anim.bench.ipc_baseline` in the same process on the same tetrahedra (the arrays
fem_anim's mesh was built from) for the same steps, as
:mod:`fem_anim.bench.contact_set` does: implicit Euler, IPC's stopping test, no retries.
Both runs use one OpenBLAS thread. It writes the baseline's per-step CSV
(``contact_bench_baseline.csv``) and both runs' centre-of-mass heights per step
(``contact_bench_com_heights.csv``, the physics check) and adds to the table both runs'
s/step (wall, fem_anim's discarded tries included) and Newton iterations per step and the
ratio of fem_anim's s/step to the baseline's (below 1: fem_anim is faster). Implicit Euler
is seed section 3.1 (eq. 4, w = h^2); the barrier is IPC's (Li et al. 2020).
"""

from __future__ import annotations

import argparse
import csv
import io
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from fem_anim.errors import FemAnimError
from fem_anim.output.products import check_may_write, write_product

__all__ = ["main", "pile_scene", "summarise", "PRODUCTS", "BASELINE_PRODUCTS"]

#: The files the bench writes into ``--out``.
PRODUCTS = ("contact_bench.toml", "contact_bench.csv", "contact_bench.md")
#: What ``--baseline`` writes besides.
BASELINE_PRODUCTS = ("contact_bench_baseline.csv", "contact_bench_com_heights.csv")


def pile_scene(h: float) -> str:
    """The bench's scene: four boxes of edge 0.1 m meshed with element size h."""
    box = '{{ shape = "box", size = [0.1, 0.1, 0.1], element_size = {h} }}'.format(h=h)
    bodies = [("a", [-0.105, -0.05, 0.001], [0, 0, 0], None),
              ("b", [0.005, -0.05, 0.001], [0, 0, 0], None),
              ("c", [-0.08, -0.03, 0.115], [0, 0, 15], [0, 0, -0.5]),
              ("d", [0.03, -0.03, 0.115], [0, 0, -15], [0, 0, -0.5])]
    text = ('name = "contact_bench"\n[time]\ndt = 0.01\nintegrator = "implicit_euler"\n'
            '[solver.petsc]\nsnes_max_it = 200\n'
            '[gravity]\nacceleration = [0, 0, -9.81]\n[contact]\ndhat = 0.001\n'
            '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 1]\ndhat = 0.0005\n'
            'stiffness = 1e5\n')
    for name, offset, rotation, velocity in bodies:
        text += (f'[[body]]\nname = "{name}"\noffset = {offset}\nrotation = {rotation}\n'
                 f"mesh = {box}\nmaterial = {{ youngs_modulus = 5e4, density = 1000 }}\n")
        if velocity:
            text += f"initial = {{ velocity = {velocity} }}\n"
    return text


def summarise(rows: list[dict]) -> dict:
    """The table's numbers of one run from its per-step rows (as read back from its CSV).

    Returns:
        ``s_per_step``: wall seconds per step (discarded tries included), ``cpu_per_step``:
        this process's CPU seconds per step (steadier than the wall clock on a loaded
        machine),
        ``newton_per_step``: Newton iterations of the accepted substeps per step,
        ``ipc_share``: time in ipctk over the wall time, ``retries`` and ``retry_s``: the
        discarded tries and their wall time (0 for the baseline, which has none).
    """
    n = len(rows)
    wall = sum(float(r["wall_s"]) for r in rows)
    return {"s_per_step": wall / n, "cpu_per_step": sum(float(r["cpu_s"]) for r in rows) / n,
            "newton_per_step": sum(int(r["newton_its"]) for r in rows) / n,
            "ipc_share": sum(float(r.get("contact_s", r.get("ipc_s"))) for r in rows) / wall,
            "retries": sum(int(r["retries"]) for r in rows),
            "retry_s": sum(float(r.get("retry_s", 0.0)) for r in rows)}


def _fem_anim_steps(sim, steps: int, keep_frames: bool):
    """fem_anim's steps as ``fem-anim run`` takes them; per step a CSV row (and, with
    ``keep_frames``, the vertex displacements at rest and after each step and the initial
    vertex velocities, which the baseline starts from)."""
    from fem_anim.simulation.adaptive import AdaptiveStepper

    ipc, dt = sim.problem.ipc, sim.scene["time"]["dt"]
    split = dict.fromkeys(ipc.timers, 0.0)
    reset = sim._contact_stats

    def counted(row: bool = True) -> dict:  # every try's ipctk time, before it is reset
        for key, value in ipc.timers.items():
            split[key] += value
        return reset(row)

    sim._contact_stats = counted
    try:
        return _steps(sim, AdaptiveStepper(sim, dt, sim.scene["time"]), split, steps,
                      keep_frames)
    finally:
        sim._contact_stats = reset


def _steps(sim, stepper, split: dict, steps: int, keep_frames: bool):
    """:func:`_fem_anim_steps`'s loop; ``split`` gathers ipctk's time of every try."""
    from mpi4py import MPI

    comm, ipc, dt = sim.comm, sim.problem.ipc, sim.scene["time"]["dt"]
    state = sim.initial_state()
    rows, shots = [], [sim.gather.gather(state.u)] if keep_frames else []
    velocity = sim.gather.gather(state.v) if keep_frames else None
    solver = ("newton_its", "assembly_s", "factor_s", "linear_solve_s", "retries",
              "retry_wall_s")
    for k in range(steps):
        for key in split:  # ipc.timers too: the set-up's time is no step's
            split[key] = ipc.timers[key] = 0.0
        totals = dict.fromkeys(solver, 0.0)
        start, cpu = time.perf_counter(), time.process_time()
        for state, row in stepper.advance(state, (k + 1) * dt):
            for key in solver:
                totals[key] += row[key]
            pairs = row["contact_pairs"]
        wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
        cpu = comm.allreduce(time.process_time() - cpu, op=MPI.MAX)
        timers = {key: comm.bcast(value, root=0) for key, value in split.items()}
        rows.append({"step": k + 1, "wall_s": wall, "cpu_s": cpu,
                     "newton_its": int(totals["newton_its"]),
                     "retries": int(totals["retries"]), "retry_s": totals["retry_wall_s"],
                     "pairs": comm.bcast(pairs, root=0), **timers,
                     "contact_s": sum(timers.values()), "assembly_s": totals["assembly_s"],
                     "factor_s": totals["factor_s"],
                     "linear_solve_s": totals["linear_solve_s"]})
        if keep_frames:
            shots.append(sim.gather.gather(state.u))
    return rows, shots, velocity


def _baseline_lines(out: Path, fa_rows: list[dict], bl_rows: list[dict]) -> list[str]:
    """The baseline's part of the table, from the two runs' rows."""
    from fem_anim.bench.ipc_baseline import MAX_NEWTON

    fa, bl = summarise(fa_rows), summarise(bl_rows)
    unconverged = sum(1 - int(r["converged"]) for r in bl_rows)
    heights = list(csv.DictReader(io.StringIO(
        (out / "contact_bench_com_heights.csv").read_text())))
    diff = max(abs(float(r["fem_anim_m"]) - float(r["baseline_m"])) for r in heights)
    ratio = fa["s_per_step"] / bl["s_per_step"]
    cpu_ratio = fa["cpu_per_step"] / bl["cpu_per_step"]
    return ["", "| run | s/step | CPU s/step | Newton its/step | ipctk share | "
            "retries (wall s) |", "|---|---|---|---|---|---|",
            f"| fem_anim | {fa['s_per_step']:.3f} | {fa['cpu_per_step']:.3f} | "
            f"{fa['newton_per_step']:.1f} | {100 * fa['ipc_share']:.0f} % | "
            f"{fa['retries']} ({fa['retry_s']:.1f}) |",
            f"| ipctk + scipy baseline | {bl['s_per_step']:.3f} | {bl['cpu_per_step']:.3f} | "
            f"{bl['newton_per_step']:.1f} | {100 * bl['ipc_share']:.0f} % | - |", "",
            f"ratio of fem_anim's s/step to the baseline's: {ratio:.2f} "
            f"({'fem_anim faster' if ratio < 1 else 'the baseline faster'}; by CPU time "
            f"{cpu_ratio:.2f}); "
            f"baseline steps not meeting IPC's test in {MAX_NEWTON} iterations: "
            f"{unconverged}; "
            f"largest centre-of-mass height difference between the runs: {1e3 * diff:.2f} mm"]


def _measure(h: float, steps: int, out: Path, baseline: bool = False) -> None:
    """Run the bench in this process (every rank); rank 0 writes the results."""
    from mpi4py import MPI

    from fem_anim.bench import contact_set
    from fem_anim.scene.loading import load_scene
    from fem_anim.simulation.loop import Simulation

    comm = MPI.COMM_WORLD
    scene_path = out / "contact_bench.toml"
    if comm.rank == 0:
        write_product(scene_path, pile_scene(h).encode())
    comm.Barrier()
    scene = load_scene(scene_path)
    threads = contact_set._blas_threads(1) if baseline else None
    try:
        sim = Simulation(scene, comm)
        tets = sim.domain.mesh.topology.index_map(3).size_global
        dofs = sim.problem.V.dofmap.index_map.size_global * 3
        rows, shots, velocity = _fem_anim_steps(sim, steps, baseline)
        if baseline:
            bl_rows, bl_shots = contact_set._baseline_run(scene, sim.domain, steps, velocity)
    finally:
        if threads is not None:
            contact_set._blas_threads(threads)
    if comm.rank == 0:
        write_product(out / "contact_bench.csv", contact_set._csv(rows))
        total = {k: sum(r[k] for r in rows) for k in rows[0] if k != "step"}
        n = len(rows)
        load = os.getloadavg()[0]
        lines = [f"Four boxes, {tets} tetrahedra ({tets // 4} per body), {dofs} dofs, "
                 f"{comm.size} rank(s), {n} steps, load average {load:.1f} at the end",
                 "", "| per step | s | share |", "|---|---|---|"]
        names = {"assembly_s": "assembly_s (incl. detection and barrier)",
                 "retry_s": "retry_s (discarded tries)"}
        for key in ("wall_s", "retry_s", "contact_s", *(k for k in sim.problem.ipc.timers),
                    "assembly_s", "factor_s", "linear_solve_s"):
            lines.append(f"| {names.get(key, key)} | {total[key] / n:.3f} | "
                         f"{100 * total[key] / total['wall_s']:.0f} % |")
        lines.append(f"| Newton iterations | {total['newton_its'] / n:.1f} | |")
        lines.append(f"| retries | {total['retries']} | |")
        lines.append(f"| active pairs (last step) | {rows[-1]['pairs']} | |")
        if baseline:
            domain = sim.domain
            write_product(out / "contact_bench_baseline.csv", contact_set._csv(bl_rows))
            body = domain.cell_markers - 1
            com = [contact_set._com_heights(domain.points, domain.cells, body, s)
                   for s in (shots, bl_shots)]
            write_product(out / "contact_bench_com_heights.csv", contact_set._csv(
                [{"step": k, "body": b, "fem_anim_m": com[0][k, b], "baseline_m": com[1][k, b]}
                 for k in range(com[0].shape[0]) for b in range(com[0].shape[1])]))
            lines += _baseline_lines(out, rows, bl_rows)
        text = "\n".join(lines)
        write_product(out / "contact_bench.md", (text + "\n").encode())
        print(text, flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fem_anim.bench.contact_cost")
    parser.add_argument("--element-size", type=float, default=0.01)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--ranks", type=int, default=1)
    parser.add_argument("--baseline", action="store_true",
                        help="also run the plain ipctk + scipy IPC step (serial)")
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="contact_bench_"))
    try:
        if args.baseline and args.ranks > 1:
            raise FemAnimError("--baseline runs serially (the baseline is one process): "
                               "leave out --ranks")
        check_may_write(out, PRODUCTS + (BASELINE_PRODUCTS if args.baseline else ()))
    except FemAnimError as err:
        print(f"fem-anim: error: {err}", file=sys.stderr)
        return 2
    if args.ranks > 1 and not args.worker:
        mpirun = [shutil.which("mpirun") or "mpirun", "--allow-run-as-root", "-n",
                  str(args.ranks)]
        cmd = mpirun + [sys.executable, "-m", "fem_anim.bench.contact_cost", "--worker",
                        "--element-size", str(args.element_size), "--steps", str(args.steps),
                        "--out", str(out)]
        return subprocess.run(cmd).returncode
    try:
        _measure(args.element_size, args.steps, out, args.baseline)
    except FemAnimError as err:  # e.g. a step failing at time.min_dt
        print(f"fem-anim: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
