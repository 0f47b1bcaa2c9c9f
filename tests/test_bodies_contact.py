"""Several bodies in contact through the IPC Toolkit (issue 16): physics, not only running.

Every run here is checked frame by frame for intersections by an independent test: the
boundary triangles are taken from the input tetrahedra in numpy (faces of one cell only),
the positions from the frames on disk or from the states, and ipctk's ``has_intersections``
must be false on each.
"""

from __future__ import annotations

import gc

import ipctk
import meshio
import numpy as np
import pytest
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.cli import main
from fem_anim.scene import load_scene
from fem_anim.simulation import Simulation

#: Two soft cubes of different materials thrown at each other, the right one turned 10 deg.
TWO_CUBES = """
name = "two_cubes"
[time]
dt = 0.01
steps = {steps}
integrator = "implicit_euler"
[solver.petsc]
snes_atol = 1e-11
snes_rtol = 1e-14
[contact]
dhat = 0.005
[[body]]
name = "left"
offset = [-0.11, 0, 0]
mesh = {{ shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.05 }}
material = {{ youngs_modulus = 1e5, density = 1000 }}
initial = {{ velocity = [1.0, 0.2, 0] }}
[[body]]
name = "right"
offset = [0.03, 0.0, 0]
rotation = [0, 0, 10]
mesh = {{ shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.05 }}
material = {{ youngs_modulus = 2e5, density = 800 }}
initial = {{ velocity = [-1.0, 0, 0] }}
"""


@pytest.fixture(autouse=True)
def _collect():
    yield
    gc.collect()
    MPI.COMM_WORLD.Barrier()


def boundary(cells: np.ndarray) -> np.ndarray:
    """Triangles that belong to one tetrahedron only (numpy, independent of fem_anim)."""
    faces = np.sort(cells[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    return unique[counts == 1].astype(np.int32)


def intersection_free(points: np.ndarray, cells: np.ndarray, frames) -> list[bool]:
    """For each displacement in ``frames``: no surface triangle crosses another."""
    F = boundary(cells)
    used = np.unique(F)
    index = np.full(points.shape[0], -1)
    index[used] = np.arange(used.size)
    F = np.asfortranarray(index[F], dtype=np.int32)
    mesh = ipctk.CollisionMesh(np.asfortranarray(points[used]),
                               np.asfortranarray(ipctk.edges(F), dtype=np.int32), F)
    return [not ipctk.has_intersections(mesh, np.asfortranarray(points[used] + u[used]))
            for u in frames]


def scene_file(tmp_path, steps: int, text: str = TWO_CUBES):
    path = tmp_path / "two_cubes.toml"
    path.write_text(text.format(steps=steps))
    return path


def momentum(sim: Simulation, M: PETSc.Mat, v: np.ndarray) -> np.ndarray:
    """P = sum over dofs of each axis of M v (collective)."""
    vec, Mv = M.createVecs()
    vec.array[:] = v[: vec.getLocalSize()]
    M.mult(vec, Mv)
    out = np.array([Mv.array.reshape(-1, 3)[:, i].sum() for i in range(3)])
    for obj in (vec, Mv):
        obj.destroy()
    return sim.comm.allreduce(out, op=MPI.SUM)


def test_two_cubes_conserve_momentum_through_the_impact(tmp_path):
    """Implicit Euler conserves M v exactly when the forces sum to zero: elastic forces of
    each body and the barrier's pair forces (translation-invariant energies) do. Through
    the impact (pairs active) the momentum stays the initial one to 1e-8 relative."""
    sim = Simulation(load_scene(scene_file(tmp_path, 14)))
    p = sim.problem
    M = fem_petsc.assemble_matrix(p.mass_form)
    M.assemble()
    state = sim.initial_state()
    P0 = momentum(sim, M, state.v)
    assert P0[0] > 0 and P0[1] > 0  # the left cube is heavier; it also moves in y
    states, pairs = [state], []
    for _ in range(14):
        state, _ = sim.step(state, 0.01)
        states.append(state)
        pairs.append(sim._contact_stats()["contact_pairs"])
        P = momentum(sim, M, state.v)
        assert np.linalg.norm(P - P0) <= 1e-8 * np.linalg.norm(P0), (len(states), P, P0)
    assert max(pairs) > 20 and pairs[-1] == 0  # they met, and they parted
    frames = [sim.gather.gather(s.u) for s in states]
    if sim.comm.rank == 0:
        u = [f.reshape(-1, 3) for f in frames]
        assert all(intersection_free(sim.domain.points, sim.domain.cells, u))
    M.destroy()


def test_cli_run_has_no_intersection_on_any_frame(tmp_path):
    """The run's frames read back from trajectory.xdmf are all intersection free, and
    stats.csv reports the contact time and pairs."""
    out = tmp_path / "out"
    assert main(["run", "-q", "-o", str(out), "--set", "output.render=false",
                 str(scene_file(tmp_path, 8))]) == 0
    with meshio.xdmf.TimeSeriesReader(str(out / "trajectory.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(k)[1]["displacement"] for k in range(reader.num_steps)]
    tets = next(c.data for c in cells if c.type == "tetra")
    assert len(frames) == 9
    assert all(intersection_free(points, tets, frames))
    import csv

    rows = list(csv.DictReader(open(out / "stats.csv")))
    assert max(int(r["contact_pairs"]) for r in rows) > 0
    assert all(float(r["contact_s"]) > 0 for r in rows)


def test_barrier_taylor_inside_the_step_objective(tmp_path):
    """At a state with active pairs, the assembled objective's gradient and (unprojected)
    Hessian pass Taylor tests: the remainders fall as O(h^2)."""
    sim = Simulation(load_scene(scene_file(tmp_path, 5)))
    p = sim.problem
    state = sim.initial_state()
    for _ in range(4):
        state, _ = sim.step(state, 0.01)
    assert sim._contact_stats()["contact_pairs"] > 0
    p.ipc.projection = ipctk.PSDProjectionMethod.NONE
    x = p.x_work.duplicate()
    x.array[:] = state.u[: x.getLocalSize()]
    rng = np.random.default_rng(0)
    dx = x.duplicate()
    dx.array[:] = rng.standard_normal(dx.getLocalSize())
    alpha = p.ipc.step_bound(-dx.array)  # keep x + h dx clear of contact
    p.set_state(x)
    dx.scale(0.05 * alpha)
    g0 = p.objective(None, x)
    r0, r1 = x.duplicate(), x.duplicate()
    p.residual(None, x, r0)
    A = sim.minimiser.A
    p.jacobian(None, x, A, A)
    Hdx = x.duplicate()
    A.mult(dx, Hdx)
    first, second = [], []
    for h in (1.0, 0.5, 0.25, 0.125):
        xh = x.copy()
        xh.axpy(h, dx)
        first.append(abs(p.objective(None, xh) - g0 - h * r0.dot(dx)))
        p.residual(None, xh, r1)
        r1.axpy(-1.0, r0)
        r1.axpy(-h, Hdx)
        second.append(r1.norm())
        xh.destroy()
    for remainders in (first, second):
        rates = np.log2(np.array(remainders[:-1]) / np.array(remainders[1:]))
        assert np.all(rates > 1.8), remainders


@pytest.mark.mpi
def test_contact_run_under_mpi_equals_serial(tmp_path):
    """mpirun -n 2 gives the serial stats and final displacement to 1e-8 relative."""
    from test_mpi_runs import assert_same_run, run

    path = scene_file(tmp_path, 8)
    for ranks in (1, 2):
        r = run(["run", "-q", "--set", "output.render=false", "-o", str(tmp_path / f"n{ranks}"),
                 str(path)], tmp_path, ranks)
        assert r.returncode == 0, r.stderr
    assert_same_run(tmp_path / "n1", tmp_path / "n2")
