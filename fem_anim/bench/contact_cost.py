"""``python -m fem_anim.bench.contact_cost``: what contact between bodies costs per step.

    python -m fem_anim.bench.contact_cost [--element-size H] [--steps N] [--ranks R] [--out DIR]

Four soft boxes (0.1 m, ~6 (0.1/H)^3 tetrahedra each; H = 0.01 gives ~5k-6k) piling up on
the ground: two side by side on it, two turned 15 degrees and thrown down onto them, so
the IPC barrier is active from the first steps. Each step is timed whole and split into
the solver's parts (assembly, factorisation, linear solves) and ipctk's (collision
detection with the gathers to rank 0, barrier value/gradient/Hessian with the scatter to
the owners, CCD), from :attr:`fem_anim.contact.ipc.IPCContact.timers`. ``--ranks R``
relaunches itself under ``mpirun -n R``. Prints a Markdown table and writes it (and the
per-step CSV) to ``--out``.
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

__all__ = ["main", "pile_scene", "PRODUCTS"]

#: The files the bench writes into ``--out``.
PRODUCTS = ("contact_bench.toml", "contact_bench.csv", "contact_bench.md")


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


def _measure(h: float, steps: int, out: Path) -> None:
    """Run the bench in this process (every rank); rank 0 writes the results."""
    from mpi4py import MPI

    from fem_anim.scene.loading import load_scene
    from fem_anim.simulation.loop import Simulation

    comm = MPI.COMM_WORLD
    scene_path = out / "contact_bench.toml"
    if comm.rank == 0:
        write_product(scene_path, pile_scene(h).encode())
    comm.Barrier()
    sim = Simulation(load_scene(scene_path), comm)
    ipc = sim.problem.ipc
    tets = sim.domain.mesh.topology.index_map(3).size_global
    dofs = sim.problem.V.dofmap.index_map.size_global * 3
    state = sim.initial_state()
    rows = []
    for _ in range(steps):
        for key in ipc.timers:
            ipc.timers[key] = 0.0
        start = time.perf_counter()
        state, stats = sim.step(state, sim.scene["time"]["dt"])
        wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
        timers = {k: comm.bcast(v, root=0) for k, v in ipc.timers.items()}
        contact = sum(timers.values())
        rows.append({"step": state.step, "wall_s": wall, "newton_its": stats.newton_its,
                     "pairs": comm.bcast(ipc.num_pairs, root=0), **timers,
                     "contact_s": contact, "assembly_s": stats.assembly_s,
                     "factor_s": stats.factor_s, "linear_solve_s": stats.linear_solve_s})
    if comm.rank == 0:
        table = io.StringIO(newline="")
        writer = csv.DictWriter(table, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
        write_product(out / "contact_bench.csv", table.getvalue().encode())
        total = {k: sum(r[k] for r in rows) for k in rows[0] if k != "step"}
        n = len(rows)
        load = os.getloadavg()[0]
        lines = [f"Four boxes, {tets} tetrahedra ({tets // 4} per body), {dofs} dofs, "
                 f"{comm.size} rank(s), {n} steps, load average {load:.1f} at the end",
                 "", "| per step | s | share |", "|---|---|---|"]
        names = {"assembly_s": "assembly_s (incl. detection and barrier)"}
        for key in ("wall_s", "contact_s", "detection_s", "barrier_s", "ccd_s", "assembly_s",
                    "factor_s", "linear_solve_s"):
            lines.append(f"| {names.get(key, key)} | {total[key] / n:.3f} | "
                         f"{100 * total[key] / total['wall_s']:.0f} % |")
        lines.append(f"| Newton iterations | {total['newton_its'] / n:.1f} | |")
        lines.append(f"| active pairs (last step) | {rows[-1]['pairs']} | |")
        text = "\n".join(lines)
        write_product(out / "contact_bench.md", (text + "\n").encode())
        print(text, flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fem_anim.bench.contact_cost")
    parser.add_argument("--element-size", type=float, default=0.01)
    parser.add_argument("--steps", type=int, default=10)
    parser.add_argument("--ranks", type=int, default=1)
    parser.add_argument("--out", type=Path, default=None)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    out = args.out or Path(tempfile.mkdtemp(prefix="contact_bench_"))
    try:
        check_may_write(out, PRODUCTS)
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
    _measure(args.element_size, args.steps, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
