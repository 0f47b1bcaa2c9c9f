"""One measured configuration: a scene, a preset, a few steps, the phase split of each.

:func:`measure` builds a :class:`~fem_anim.simulation.loop.Simulation` (the library's own code,
as ``fem-anim run`` does), times the set-up, then advances ``steps`` time steps and
splits each step's wall time with :class:`~fem_anim.bench.timing.PhaseTimer`. The first
step is reported on its own (it pays the symbolic factorisation and first-touch costs);
the averages are over the later ones. :func:`run_worker` is the subprocess entry point
used by :mod:`fem_anim.bench.perf`, so that each configuration gets its own process: a
clean peak-memory figure, and its own BLAS or MPI size.
"""

from __future__ import annotations

import json
import time

import numpy as np
from mpi4py import MPI

from fem_anim.bench.timing import PhaseTimer, peak_memory_mb, split_step

__all__ = ["PHASE_COLUMNS", "measure", "run_worker"]

#: The columns of a split, in the order of the tables.
PHASE_COLUMNS = ("residual", "jacobian", "objective", "filter", "energies", "factor_symbolic",
                 "factor_numeric", "solve", "other")


def measure(scene, preset: str | None = None, steps: int = 5,
            cli_options: dict[str, str] | None = None, comm: MPI.Comm = MPI.COMM_WORLD,
            tip: bool = False) -> dict:
    """Time ``steps`` steps of ``scene``; returns sizes, the split per step and its mean.

    Under MPI the split is rank 0's (every rank does its share of each phase), the wall time
    the slowest rank's and the peak memory the sum over ranks.

    Returns:
        A dict: ``tets``, ``dofs``, ``ranks``, ``setup_s``, ``steps`` (one split per step,
        with ``newton_its`` and ``linear_its``), ``mean`` (phase means over steps 2..n, or
        step 1 if only one), ``peak_mb`` and, with ``tip``, the tip trajectory (mean
        displacement of the vertices at the largest x, rank 0).
    """
    from fem_anim.simulation.loop import Simulation

    start = time.perf_counter()
    sim = Simulation(scene, comm, cli_options, preset=preset)
    setup = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
    mesh = sim.domain.mesh
    index_map = sim.problem.V.dofmap.index_map
    timer = PhaseTimer()
    state = sim.initial_state()
    dt = scene["time"]["dt"]
    rows, tip_path = [], []
    for _ in range(steps):
        comm.Barrier()
        before = timer.snapshot()
        start = time.perf_counter()
        state, stats = sim.timed_step(state, dt)
        wall = comm.allreduce(time.perf_counter() - start, op=MPI.MAX)
        split = split_step(before, timer.snapshot(), wall)
        split.update(newton_its=stats["newton_its"], linear_its=stats["linear_its"])
        rows.append(split)
        if tip:
            tip_path.append(_tip(sim, state))
    later = rows[1:] or rows
    mean = {k: float(np.mean([r[k] for r in later])) for k in (*PHASE_COLUMNS, "wall",
                                                               "newton_its", "linear_its")}
    mean["symbolic_calls"] = int(sum(r["symbolic_calls"] for r in later))
    result = {
        "tets": mesh.topology.index_map(mesh.topology.dim).size_global,
        "dofs": index_map.size_global * index_map_bs(sim),
        "ranks": comm.size, "setup_s": setup, "steps": rows, "mean": mean,
        "first_step_s": rows[0]["wall"],
        "peak_mb": comm.allreduce(peak_memory_mb(), op=MPI.SUM),
    }
    if tip:
        result["tip"] = [list(p) for p in tip_path]
    sim.minimiser.destroy()
    return result


def index_map_bs(sim) -> int:
    return sim.problem.V.dofmap.index_map_bs


def _tip(sim, state) -> np.ndarray:
    """Mean displacement of the vertices at the largest x (rank 0; gathered)."""
    u = sim.gather.gather(state.u)
    if sim.comm.rank != 0:
        return np.zeros(sim.domain.dim)
    X = sim.domain.points
    at_tip = X[:, 0] >= X[:, 0].max() - 1e-9
    return u.reshape(len(X), -1)[at_tip].mean(axis=0)


def run_worker(scene, preset: str | None, steps: int, cli_options: dict[str, str],
               out: str, tip: bool = False) -> None:
    """Measure one configuration and write its result as JSON (rank 0)."""
    result = measure(scene, preset, steps, cli_options, tip=tip)
    if MPI.COMM_WORLD.rank == 0:
        with open(out, "w", encoding="utf-8") as f:
            json.dump(result, f)
