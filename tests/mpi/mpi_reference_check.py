"""The distributed DOLFINx side against the numpy reference, under ``mpirun -n 2``.

Usage (``tests/test_reference_mpi.py`` runs it)::

    mpirun -n 2 python tests/mpi/mpi_reference_check.py [--full]

The parallel counterpart of ``tests/test_reference_comparison.py``: rank 0 makes the meshes
with :func:`fem_anim.reference.box_mesh`, :func:`fem_anim.mesh.build.mesh_from_arrays` distributes
them, and every DOLFINx result is brought back to rank 0 in input vertex order
(:class:`fem_anim.output.files.VertexGather`) and compared there with :mod:`fem_anim.reference`:

1. elastic energy, gradient (``ufl.derivative`` of ``EnergyProblem.ufl_elastic``) and Hessian
   at a randomly perturbed state; the matrices are compared through their action ``H z`` on
   random vectors (PETSc ``mult`` on the distributed matrix, result gathered);
2. the step objective, residual and Jacobian that SNES minimises (the callbacks
   ``EnergyProblem.objective``, ``residual``, ``jacobian``: assembled forms plus the constant
   terms of :mod:`fem_anim.problem.constant_terms`) with a random predictor, the mass matrix
   (``M z``) and the kinetic energy;
3. ten steps of a beam pinned at ``x = 0`` and hanging under gravity, stepped by
   :class:`fem_anim.simulation.loop.Simulation` across the ranks, against
   :func:`fem_anim.reference.simulate`.

Without ``--full``: the neo-Hookean, StVK and corotated materials (the last is the one whose
energy takes per-quadrature-point data, computed rank by rank on owned and ghost cells) and two
trajectories; with ``--full``: every material, both mass matrices, and every material with
every integrator.

Exit status 0 when every comparison passes; 1 with one line per failure (rank 0 prints a
table of all measured differences either way). An exception on any rank aborts all ranks.
"""

from __future__ import annotations

import sys
import tempfile
import traceback
from pathlib import Path

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat, reference
from fem_anim.mesh.simplex import mesh_from_arrays
from fem_anim.output.files import VertexGather
from fem_anim.problem.objective import EnergyProblem
from fem_anim.simulation.loop import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_reference_comparison import (  # noqa: E402 (the serial test's beam scenes)
    DENSITY, DT, GRAVITY, LENGTHS, PIN_MAX, PIN_MIN, POISSON_RATIO, YOUNGS_MODULUS,
    write_scene)

COMM = MPI.COMM_WORLD
EPS = np.finfo(float).eps
#: Assembly: the same sums in another order (and across ranks). Serial: <= 3e-15 relative.
ASSEMBLY_RTOL = 1e-10
#: Trajectory positions, relative to the largest: both Newton solvers stop at tight tolerances.
TRAJECTORY_RTOL = 1e-8
#: Trajectory displacements, relative to the largest one (see test_reference_comparison.py:
#: the Minimiser may stop at the objective's round-off floor, ~1e-9 relative).
DISPLACEMENT_RTOL = 1e-7

MATERIALS = ("linear", "stvk", "corotated", "neohookean", "stable_neohookean")
INTEGRATORS = ("newmark", "implicit_euler", "bdf2", "symplectic_euler")
DIVISIONS = {2: (4, 2), 3: (4, 2, 2)}
STEPS = 10  # the serial comparison runs 20; its scenes are shared (their steps unused here)
DOLFINX_NEWTON = {"snes_rtol": "1e-12", "snes_atol": "1e-14"}
REFERENCE_NEWTON = {"atol": 1e-12, "rtol": 1e-14}
NUM_PROBES = 3  # random vectors z for the matrix actions


# --- scenes and meshes ----------------------------------------------------------------------------


class Beam:
    """The reference box (arrays on rank 0) and the distributed mesh made from it."""

    def __init__(self, d: int):
        self.d = d
        if COMM.rank == 0:
            self.points, self.cells = reference.box_mesh(DIVISIONS[d], LENGTHS[d])
        else:
            self.points, self.cells = np.empty((0, d)), np.empty((0, d + 1), dtype=np.int64)
        self.domain = mesh_from_arrays(COMM, self.points, self.cells, None, f"reference box {d}D")
        # the rest positions on every rank, to place global states on local dofs
        self.X = COMM.bcast(self.points.ravel() if COMM.rank == 0 else None, root=0)


class DofMap:
    """Local dofs (owned and ghost) <-> reference dofs ``d * input vertex + component``."""

    def __init__(self, beam: Beam, V):
        d = beam.d
        self.gather = VertexGather(beam.domain, V)
        local = (self.gather.node_to_dof[:, None] * d + np.arange(d)).ravel()
        global_ = (beam.domain.input_index[:, None] * d + np.arange(d)).ravel()
        n_local = (V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts) * d
        self.to_reference = np.full(n_local, -1, dtype=np.int64)
        self.to_reference[local] = global_
        assert np.all(self.to_reference >= 0), "a local dof is not at a mesh vertex"
        self.owned = V.dofmap.index_map.size_local
        self.ghosts = V.dofmap.index_map.num_ghosts

    def scatter(self, values: np.ndarray) -> np.ndarray:
        """The local part (owned and ghost) of a global array in reference order."""
        return values[self.to_reference]

    def collect(self, local: np.ndarray) -> np.ndarray | None:
        """A local array (ghosts up to date) as a global array on rank 0, ``None`` elsewhere."""
        out = self.gather.gather(local)
        return None if out is None else out.ravel()


def bcast_array(make) -> np.ndarray:
    """``make()`` evaluated on rank 0 and broadcast (random data identical on every rank)."""
    return COMM.bcast(make() if COMM.rank == 0 else None, root=0)


# --- distributed assembly, gathered ---------------------------------------------------------------


class Distributed:
    """An :class:`EnergyProblem` on the distributed beam and its values in reference order."""

    def __init__(self, beam: Beam, scene):
        self.beam = beam
        self.problem = EnergyProblem(scene, beam.domain)
        self.map = DofMap(beam, self.problem.V)
        p = self.problem
        gradient = ufl.derivative(p.ufl_elastic, p.u, ufl.TestFunction(p.V))
        self.elastic = (fem.form(p.ufl_elastic), fem.form(gradient),
                        fem.form(ufl.derivative(gradient, p.u, ufl.TrialFunction(p.V))))

    def set_function(self, function: fem.Function, values: np.ndarray) -> None:
        function.x.array[:] = self.map.scatter(values)

    def set_positions(self, x: np.ndarray) -> None:
        """``u = x - X`` through the solver entry point (ghosts, quadrature data)."""
        work = compat.petsc_vec(self.problem.u).copy()
        with work.localForm() as local:
            local.array[:] = self.map.scatter(x - self.beam.X)
        self.problem.set_state(work)
        work.destroy()

    def scalar(self, form) -> float:
        return self.problem.assemble_scalar(form)

    def vector(self, form) -> np.ndarray | None:
        b = fem_petsc.assemble_vector(form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return self._collect(b)

    def _collect(self, b: PETSc.Vec) -> np.ndarray | None:
        b.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with b.localForm() as local:
            out = self.map.collect(local.array.copy())
        b.destroy()
        return out

    def _state(self) -> PETSc.Vec:
        return compat.petsc_vec(self.problem.u).copy()

    def step_callbacks(self, probes: list[np.ndarray]):
        """The objective, residual and Jacobian actions SNES gets at the current u (the
        assembled forms plus the constant terms, :mod:`fem_anim.problem.constant_terms`)."""
        p = self.problem
        value = p.objective(None, self._state())
        b = p.create_vector()
        p.residual(None, self._state(), b)
        A = p.create_matrix()
        p.jacobian(None, self._state(), A, A)
        return value, self._collect(b), self.actions(A, probes)

    def actions(self, form, probes: list[np.ndarray]) -> list[np.ndarray] | None:
        """``A z`` for each global ``z``, the matrix (a form: assembled) applied across the
        ranks."""
        if isinstance(form, PETSc.Mat):
            A = form
        else:
            A = fem_petsc.assemble_matrix(form)
            A.assemble()
        work = compat.petsc_vec(self.problem.u)
        z, y = work.duplicate(), work.duplicate()
        out = []
        for values in probes:
            with z.localForm() as local:
                local.array[:] = self.map.scatter(values)
            A.mult(z, y)
            y.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            with y.localForm() as local:
                out.append(self.map.collect(local.array.copy()))
        for obj in (A, z, y):
            obj.destroy()
        return out if COMM.rank == 0 else None


class Report:
    """Measured differences, printed on rank 0; failures decide the exit status."""

    def __init__(self):
        self.rows: list[tuple[bool, str, float, float]] = []

    def compare(self, what: str, actual, expected, rtol: float) -> None:
        """Relative max-norm difference (rank 0 holds both sides; other ranks pass None)."""
        if COMM.rank != 0:
            return
        actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
        if actual.shape != expected.shape:
            self.rows.append((False, f"{what}: shape {actual.shape} != {expected.shape}",
                              np.inf, rtol))
            return
        difference = float(np.abs(actual - expected).max() / np.abs(expected).max())
        self.rows.append((difference <= rtol, what, difference, rtol))

    def check(self, what: str, ok: bool) -> None:
        if COMM.rank == 0:
            self.rows.append((bool(ok), what, 0.0, 0.0))

    def finish(self) -> int:
        status = 0
        if COMM.rank == 0:
            for ok, what, difference, rtol in self.rows:
                tag = "ok  " if ok else "FAIL"
                relation = "<=" if ok else "> "
                print(f"{tag} {what:58s} {difference:9.2e} {relation} {rtol:.0e}" if rtol else
                      f"{tag} {what}")
            failures = [row for row in self.rows if not row[0]]
            print(f"{len(self.rows) - len(failures)} of {len(self.rows)} comparisons passed "
                  f"on {COMM.size} ranks")
            status = 1 if failures else 0
        return COMM.bcast(status, root=0)


def perturbed_positions(beam: Beam, seed: int) -> np.ndarray:
    """``X + a r``, ``r`` uniform in [-1, 1], ``a`` a fifth of the grid spacing (as serially)."""
    d = beam.d

    def make():
        rng = np.random.default_rng(seed)
        spacing = min(np.asarray(LENGTHS[d]) / DIVISIONS[d])
        return (beam.points + 0.2 * spacing * rng.uniform(-1.0, 1.0, beam.points.shape)).ravel()

    return bcast_array(make)


# --- the comparisons ------------------------------------------------------------------------------


def compare_assembly(report: Report, beam: Beam, directory: Path, material: str,
                     mass: str) -> None:
    d = beam.d
    label = f"{d}D {material}" + (" lumped" if mass == "lumped" else "")
    c = Distributed(beam, write_scene(directory, d, material, mass=mass))
    p = c.problem
    mu, lmbda = reference.lame_parameters(YOUNGS_MODULUS, POISSON_RATIO)
    x = perturbed_positions(beam, seed=1)
    y = perturbed_positions(beam, seed=2)
    probes = [bcast_array(lambda k=k: np.random.default_rng(10 + k).standard_normal(x.size))
              for k in range(NUM_PROBES)]
    c.set_positions(x)
    energy, gradient, hessian = c.elastic
    values = (c.scalar(energy), c.vector(gradient), c.actions(hessian, probes))

    w = (1 / 60) ** 2 / 4
    p.weight.value = w
    c.set_function(p.u_pred, y - beam.X)
    c.set_positions(x)
    step = c.step_callbacks(probes)
    M_actions = c.actions(p.mass_form, probes)
    c.set_function(p.v, probes[0])
    kinetic = c.scalar(p.energy_forms["kinetic"])

    if COMM.rank == 0:
        points, cells = beam.points, beam.cells
        args = (points, cells, material, mu, lmbda, x)
        H = reference.elastic_hessian(*args)
        ref = reference.build_problem(points, cells, material, YOUNGS_MODULUS, POISSON_RATIO,
                                      DENSITY, GRAVITY[d], lumped=mass == "lumped")
        M = ref.mass
        report.compare(f"{label}: elastic energy", values[0], reference.elastic_energy(*args),
                       ASSEMBLY_RTOL)
        report.compare(f"{label}: elastic gradient", values[1],
                       reference.elastic_gradient(*args), ASSEMBLY_RTOL)
        report.compare(f"{label}: elastic Hessian H z", np.array(values[2]),
                       np.array([H @ z for z in probes]), ASSEMBLY_RTOL)
        # DOLFINx's gravity potential -f_g . u is the reference's -f_g . x plus f_g . X
        g = 0.5 * (x - y) @ (M @ (x - y)) + w * ref.energy(x) + w * ref.gravity_force @ beam.X
        report.compare(f"{label}: step objective", step[0], g, ASSEMBLY_RTOL)
        report.compare(f"{label}: step residual", step[1], M @ (x - y) + w * ref.gradient(x),
                       ASSEMBLY_RTOL)
        J = M + w * ref.hessian(x)
        report.compare(f"{label}: step Jacobian J z", np.array(step[2]),
                       np.array([J @ z for z in probes]), ASSEMBLY_RTOL)
        report.compare(f"{label}: mass matrix M z", np.array(M_actions),
                       np.array([M @ z for z in probes]), ASSEMBLY_RTOL)
        report.compare(f"{label}: kinetic energy", kinetic, 0.5 * probes[0] @ (M @ probes[0]),
                       ASSEMBLY_RTOL)


def compare_trajectory(report: Report, beam: Beam, directory: Path, material: str,
                       integrator: str) -> None:
    d = beam.d
    label = f"{d}D {material} {integrator}"
    scene = write_scene(directory, d, material, integrator=integrator, pinned=True)
    sim = Simulation(scene, COMM, DOLFINX_NEWTON, domain=beam.domain)
    dt = DT[integrator]
    state = sim.initial_state()
    u = []
    for _ in range(STEPS):
        state, _ = sim.step(state, dt)
        u.append(sim.gather.gather(state.u))
    sim.minimiser.destroy()
    if COMM.rank == 0:
        pinned = np.repeat(np.all((beam.points >= PIN_MIN[d]) & (beam.points <= PIN_MAX[d]),
                                  axis=1), d)
        expected = reference.simulate(beam.points, beam.cells, material, YOUNGS_MODULUS,
                                      POISSON_RATIO, DENSITY, GRAVITY[d], pinned, integrator,
                                      dt, STEPS, **REFERENCE_NEWTON)
        u = np.array([frame.ravel() for frame in u])
        u_expected = expected.x[1:] - beam.X
        report.check(f"{label}: the beam moves (max |u| {np.abs(u_expected).max():.3f} m)",
                     np.abs(u_expected).max() > 1e-2)
        report.compare(f"{label}: positions, {STEPS} steps", u + beam.X, expected.x[1:],
                       TRAJECTORY_RTOL)
        report.compare(f"{label}: displacements, {STEPS} steps", u, u_expected,
                       DISPLACEMENT_RTOL)


def check_partition(report: Report, beam: Beam) -> None:
    """Every rank owns part of the mesh and some dofs are shared (else nothing is tested)."""
    V_map = compat.vector_space(beam.domain.mesh, 1).dofmap.index_map
    owned = COMM.gather(V_map.size_local, root=0)
    ghosts = COMM.gather(V_map.num_ghosts, root=0)
    if COMM.rank == 0:  # a serial run (for debugging) has nothing to distribute
        report.check(f"{beam.d}D mesh distributed: owned vertices per rank {owned}, "
                     f"ghosts {ghosts}", COMM.size == 1 or (min(owned) > 0 and sum(ghosts) > 0))


def main(full: bool) -> int:
    report = Report()
    with tempfile.TemporaryDirectory() as tmp:
        directory = Path(tmp)
        assembly = [(d, m, "consistent") for d in (2, 3) for m in
                    (MATERIALS if full else ("neohookean", "stvk", "corotated"))]
        if full:
            assembly += [(d, "linear", "lumped") for d in (2, 3)]
        trajectories = ([(d, m, i) for d in (2, 3) for m in MATERIALS for i in INTEGRATORS]
                        if full else [(3, "neohookean", "newmark"),
                                      (2, "stvk", "implicit_euler")])
        beams = {d: Beam(d) for d in (2, 3)}
        for beam in beams.values():
            check_partition(report, beam)
        for d, material, mass in assembly:
            compare_assembly(report, beams[d], directory, material, mass)
        for d, material, integrator in trajectories:
            compare_trajectory(report, beams[d], directory, material, integrator)
    return report.finish()


if __name__ == "__main__":
    try:
        status = main(full="--full" in sys.argv[1:])
    except Exception:
        print(f"rank {COMM.rank}: {traceback.format_exc()}", file=sys.stderr, flush=True)
        COMM.Abort(1)
    sys.exit(status)
