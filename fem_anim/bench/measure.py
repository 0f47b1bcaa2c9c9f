"""Run one configuration of a trade study: timings, iterations, sampled trajectory.

A configuration is built once (mesh generation and form compilation timed separately:
FFCx compiles each distinct form once per machine, later builds load the cached
kernels), then run ``repeats`` times from the initial state in-process. The first run
samples the displacement at fixed points at every comparison time (that sampling is not
counted in its time); the reported cost is the median over the runs of the stepping
wall time per simulated second.

Displacements are compared at fixed physical points, independent of the mesh
(:class:`PointSampler`: DOLFINx's bounding-box tree, colliding cells and
``Function.eval``; under MPI every rank evaluates the points inside its cells and the
values are summed over ranks and divided by the number of ranks that found each point).
"""

from __future__ import annotations

import statistics
import time
from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from fem_anim import compat
from fem_anim.simulation.energy_report import energy_report, initial_energies
from fem_anim.errors import ConvergenceError
from fem_anim.mesh.bodies import build_scene_mesh
from fem_anim.simulation.adaptive import AdaptiveStepper
from fem_anim.simulation.loop import Simulation

__all__ = ["PointSampler", "Measurement", "measure_configuration", "median_run"]


class PointSampler:
    """Evaluates a vector Function at fixed points (collective; NaN where no cell holds one)."""

    def __init__(self, mesh, points: np.ndarray):
        self.comm = mesh.comm
        n = points.shape[0]
        p3 = np.zeros((n, 3))
        p3[:, : points.shape[1]] = points
        colliding = compat.colliding_cells(mesh, p3)
        offsets = colliding.offsets
        found = np.flatnonzero(np.diff(offsets) > 0)
        self.points = p3[found]
        self.cells = colliding.array[offsets[found]]
        self.found = found
        self.n = n
        count = np.zeros(n)
        count[found] = 1.0
        self.count = np.zeros(n)
        self.comm.Allreduce(count, self.count, op=MPI.SUM)

    def sample(self, u) -> np.ndarray:
        """Values (n, value size) of ``u`` at the points, on every rank; NaN rows if outside."""
        bs = u.function_space.dofmap.index_map_bs
        local = np.zeros((self.n, bs))
        if self.found.size:
            local[self.found] = u.eval(self.points, self.cells).reshape(-1, bs)
        total = np.zeros_like(local)
        self.comm.Allreduce(local, total, op=MPI.SUM)
        with np.errstate(invalid="ignore", divide="ignore"):
            out = total / self.count[:, None]
        out[self.count == 0] = np.nan
        return out


@dataclass
class Measurement:
    """What one configuration measured (``status`` is ``ok`` or the failure message)."""

    status: str = "ok"
    dofs: int = 0
    mesh_s: float = float("nan")
    compile_s: float = float("nan")
    run_s: list[float] = field(default_factory=list)
    steps: int = 0
    retries: int = 0
    newton_its: int = 0
    linear_its: int = 0
    energy: dict = field(default_factory=dict)
    samples: np.ndarray | None = None  # (frames, points, d) at the comparison times


def _run_once(sim: Simulation, scene, stride: int, sampler: PointSampler | None):
    """One run from the initial state; returns (stepping wall time, rows, samples)."""
    dt, steps = scene["time"]["dt"], scene["time"]["steps"]
    stepper = AdaptiveStepper(sim, dt, scene["time"])
    state = sim.initial_state()
    rows, samples, sampling = [], [], 0.0
    sim.comm.barrier()
    start = time.perf_counter()
    for frame in range(1, steps + 1):
        for state, row in stepper.advance(state, frame * dt):
            rows.append(row)
        if sampler is not None and frame % stride == 0:
            t0 = time.perf_counter()
            sim.problem.u.x.array[:] = state.u
            samples.append(sampler.sample(sim.problem.u))
            sampling += time.perf_counter() - t0
    wall = sim.comm.allreduce(time.perf_counter() - start - sampling, op=MPI.MAX)
    return wall, rows, (np.array(samples) if sampler is not None else None)


def measure_configuration(scene, comm: MPI.Comm, points: np.ndarray, stride: int,
                          repeats: int, domain=None) -> Measurement:
    """Build, run and time one configuration (see the module docstring).

    Args:
        scene: The configuration's scene (``time.steps`` set for the study's duration).
        comm: MPI communicator.
        points: Sample points (n, gdim), the same on every rank.
        stride: Steps between comparison times.
        repeats: Timed runs (>= 1); the first one also samples the trajectory.
        domain: The mesh, if already built (its build time is then not measured).

    A :class:`~fem_anim.errors.ConvergenceError` during a run ends the measurement with
    its message as ``status`` (the configuration is unstable there).
    """
    m = Measurement()
    comm.barrier()
    t0 = time.perf_counter()
    domain = domain if domain is not None else build_scene_mesh(comm, scene)
    m.mesh_s = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    t0 = time.perf_counter()
    sim = Simulation(scene, comm, {}, domain=domain)
    m.compile_s = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
    V = sim.problem.V
    m.dofs = V.dofmap.index_map.size_global * V.dofmap.index_map_bs
    sampler = PointSampler(domain.mesh, points)
    initial = initial_energies(sim)
    try:
        wall, rows, m.samples = _run_once(sim, scene, stride, sampler)
        m.run_s.append(wall)
        for _ in range(repeats - 1):
            m.run_s.append(_run_once(sim, scene, stride, None)[0])
    except ConvergenceError as err:
        m.status = f"failed: {err}"
        return m
    m.steps = len(rows)
    m.retries = sum(r["retries"] for r in rows)
    m.newton_its = sum(r["newton_its"] for r in rows)
    m.linear_its = sum(r["linear_its"] for r in rows)
    m.energy = energy_report(rows, initial, scene)
    return m


def median_run(m: Measurement) -> float:
    """Median stepping wall time over the repeats (NaN if the run failed)."""
    return statistics.median(m.run_s) if m.run_s and m.status == "ok" else float("nan")
