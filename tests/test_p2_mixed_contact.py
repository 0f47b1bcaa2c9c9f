"""P2 and mixed (u, p) bodies in IPC contact (``[contact]``).

* the P2 contact surface (:mod:`fem_anim.contact.p2_surface`): each boundary triangle split
  in four on its edge-midpoint dofs; the same triangles as the independent check's
  (:mod:`fem_anim.contact.intersection`, which orders the nodes by their coordinates); in 2D
  each boundary edge split in two at its midpoint dof;
* the barrier inside the step objective of a P2 body and of a mixed one (its rows are the
  displacement block of the unknown w = (u, p~)): Taylor tests of the gradient and the
  exact Hessian at a state with active pairs;
* two bodies thrown at each other, P2 (nu = 0.3) and exactly incompressible mixed
  (nu = 0.5): every state intersection free on the refined surface (the independent check),
  the total momentum conserved to round-off through the impact, the energy never rising;
* an incompressible body dropped on another (pinned) one under gravity: intersection free,
  the energy never rising, the ``ldlt`` preset chosen without being named.

Serial: the states are read on the rank's own dofs.
"""

from __future__ import annotations

from pathlib import Path

import ipctk
import numpy as np
import pytest
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from conftest import step_taylor_remainders
from scenes import make_scene

from fem_anim import compat
from fem_anim.contact.intersection import boundary_triangles, crossed_frames, tetra10_cells
from fem_anim.contact.p2_surface import surface_faces
from fem_anim.scene import load_scene
from fem_anim.scene.modes import MIXED_CONTACT_PETSC
from fem_anim.simulation.loop import Simulation

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: local dofs")

H = 0.01  # s



def _material(nu: float) -> dict:
    return {"model": "neohookean", "youngs_modulus": 2e4, "poisson_ratio": nu,
            "density": 1000.0}


def _thrown(tmp_path, name: str, formulation: str, nu: float, gap: float = 0.04,
            speed: float = 1.0):
    """Two 0.1 m cubes, one element across (P2), thrown face on at each other; the right
    one turned 10 degrees so no edges are parallel."""
    cube = {"shape": "box", "size": [0.1, 0.1, 0.1], "element_size": 0.1}
    return make_scene(tmp_path, {
        "name": name,
        "element": {"degree": 2, "formulation": formulation},
        "time": {"integrator": "implicit_euler", "dt": H, "steps": 10},
        "contact": {"dhat": 0.005},
        "body": [{"name": "left", "offset": [-0.1 - gap / 2, 0.0, 0.0], "mesh": cube,
                  "material": _material(nu), "initial": {"velocity": [speed, 0.1, 0.0]}},
                 {"name": "right", "offset": [gap / 2, 0.0, 0.0], "rotation": [0, 0, 10],
                  "mesh": cube, "material": _material(nu),
                  "initial": {"velocity": [-speed, 0.0, 0.0]}}]})


def _p2_check(sim: Simulation):
    """The rest nodes and tetra10 cells of the P2 displacement, from coordinates alone."""
    V, mesh = sim.problem.V, sim.domain.mesh
    points = V.tabulate_dof_coordinates()
    corners = mesh.geometry.x[compat.geometry_dofmap(mesh)]
    return points, tetra10_cells(corners, compat.cell_dofs(V), points)


def _momentum(sim: Simulation, v: np.ndarray) -> np.ndarray:
    M = fem_petsc.assemble_matrix(sim.problem.mass_form)
    M.assemble()
    vec, Mv = M.createVecs()
    vec.array[:] = v[: vec.getLocalSize()]
    M.mult(vec, Mv)
    out = Mv.array.reshape(-1, 3).sum(axis=0)
    for obj in (vec, Mv, M):
        obj.destroy()
    return out


def test_p2_surface_splits_each_facet_on_its_midpoint_dofs():
    """Every sub-triangle's vertices are P2 dofs at the facet's vertices and edge
    midpoints, and the surface equals the independent check's, built from coordinates."""
    mesh = dmesh.create_box(MPI.COMM_WORLD, [[0, 0, 0], [1.0, 0.7, 0.5]], [2, 2, 1])
    V = compat.vector_space(mesh, 2)
    tdim = 3
    mesh.topology.create_connectivity(tdim - 1, tdim)
    mesh.topology.create_connectivity(tdim - 1, 0)
    mesh.topology.create_connectivity(tdim, 0)
    facets = dmesh.exterior_facet_indices(mesh.topology)
    f_to_v = mesh.topology.connectivity(tdim - 1, 0).array.reshape(-1, tdim)
    c_to_v = mesh.topology.connectivity(tdim, 0).array.reshape(-1, tdim + 1)
    faces, parent = surface_faces(V, f_to_v[facets], c_to_v)
    assert faces.shape == (4 * facets.size, 3)
    assert np.array_equal(parent, np.repeat(np.arange(facets.size), 4))
    X = V.tabulate_dof_coordinates()
    # the vertex coordinates of each facet (geometry P1, vertex order = f_to_v)
    x_geo = mesh.geometry.x
    v_to_geo = np.empty(c_to_v.max() + 1, np.int64)
    v_to_geo[c_to_v.ravel()] = compat.geometry_dofmap(mesh).ravel()
    a, b, c = (x_geo[v_to_geo[f_to_v[facets, i]]] for i in range(3))
    expected = np.stack([np.stack(t, 1) for t in (
        (a, (a + b) / 2, (c + a) / 2), ((a + b) / 2, b, (b + c) / 2),
        ((c + a) / 2, (b + c) / 2, c), ((a + b) / 2, (b + c) / 2, (c + a) / 2))], 1)
    np.testing.assert_allclose(X[faces].reshape(expected.shape), expected, atol=1e-14)
    # the same triangles as the independent check's
    corners = x_geo[compat.geometry_dofmap(mesh)]
    independent = boundary_triangles(tetra10_cells(corners, compat.cell_dofs(V), X))
    as_set = lambda t: {tuple(r) for r in np.sort(t, axis=1)}  # noqa: E731
    assert as_set(independent) == as_set(faces)


def test_tetra10_cells_refuses_nodes_off_the_midpoints():
    corners = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]], float)
    points = np.concatenate([corners[0], np.full((6, 3), 0.3)])
    with pytest.raises(ValueError, match="edge midpoints"):
        tetra10_cells(corners, np.arange(10)[None, :], points)


@pytest.mark.parametrize("formulation,nu", [("displacement", 0.3), ("mixed", 0.5)])
def test_barrier_taylor_on_p2_and_mixed_unknowns(tmp_path, formulation, nu):
    """At a state with active pairs (the right cube moved to within d_hat of the left),
    the step objective's gradient and exact Hessian (the barrier's rows on the P2 dofs,
    for mixed on the displacement block of w) pass Taylor tests: remainders O(h^2)."""
    scene = _thrown(tmp_path, f"taylor_{formulation}", formulation, nu)
    scene.data["solver"]["hessian"] = "exact"
    sim = Simulation(scene)
    p = sim.problem
    state = sim.initial_state()
    p.stage(state.u, state.u, H ** 2, H, H)
    right = p.cell_body == 1
    blocks = np.unique(compat.dofs_of_cells(p.V, np.flatnonzero(right).astype(np.int32)))
    u = np.zeros_like(state.u).reshape(-1, 3)
    x = p.x_work.duplicate()
    for _ in range(200):  # slide the right cube left in 0.25 mm moves until pairs appear
        u[blocks, 0] -= 0.00025
        p.load_guess(u.ravel(), x, apply_bcs=False)
        p.set_state(x)
        if p.ipc.step_stats()["contact_pairs"] > 0:
            break
    assert p.ipc.step_stats()["contact_pairs"] > 0 and np.isfinite(p.objective(None, x))
    # the first 0.25 mm move that brings a pair within d_hat: the distance (m, not squared)
    assert 0.005 - 0.00025 <= p.ipc.step_stats()["min_distance"] < 0.005
    p.ipc.projection = ipctk.PSDProjectionMethod.NONE
    rng = np.random.default_rng(1)
    dx = x.duplicate()
    dx.array[:] = 3e-5 * rng.standard_normal(dx.getLocalSize())  # ~30 um
    if p.mixed:  # a pressure part too: the barrier must not see it
        dx.array[p.fields.p_dofs[p.fields.p_dofs < dx.getLocalSize()]] *= 0.1
    du = p.fields.displacement_part(dx).array.copy() if p.mixed else dx.array.copy()
    p.set_state(x)
    alpha = p.ipc.step_bound(-du)
    assert alpha > 0.5  # a direction the pairs feel, not one the CCD shrinks to nothing
    dx.scale(alpha)
    first, second = step_taylor_remainders(p, sim.minimiser.A, x, dx)
    for remainders in (first, second):
        rates = np.log2(np.array(remainders[:-1]) / np.array(remainders[1:]))
        assert np.all(rates > 1.8), (first, second)


@pytest.mark.parametrize("formulation,nu", [("displacement", 0.3), ("mixed", 0.5)])
def test_thrown_bodies_meet_without_crossing(tmp_path, formulation, nu):
    """Ten steps through the impact: each state intersection free on the refined P2
    surface (independent check), momentum conserved to 1e-8, energy never rising."""
    scene = _thrown(tmp_path, f"thrown_{formulation}", formulation, nu)
    if formulation == "mixed":
        assert scene["solver"]["preset"] == "ldlt"  # the saddle point's, not named
    sim = Simulation(scene)
    p = sim.problem
    state = sim.initial_state()
    P0 = _momentum(sim, state.v)
    p.u.x.array[:], p.v.x.array[:] = state.u, state.v
    start = p.energies()["total_energy"]
    states, pairs = [state], []
    for _ in range(10):
        state, stats = sim.step(state, H)
        assert stats.reason > 0
        states.append(state)
        pairs.append(sim._contact_stats()["contact_pairs"])
        P = _momentum(sim, state.v)
        assert np.linalg.norm(P - P0) <= 1e-8 * np.linalg.norm(P0), (len(states), P, P0)
        p.u.x.array[:], p.v.x.array[:] = state.u, state.v
        assert p.energies()["total_energy"] <= start * (1 + 1e-9)
    assert max(pairs) > 0  # they met
    points, cells = _p2_check(sim)
    frames = [s.u.reshape(-1, 3) for s in states]
    assert crossed_frames(points, cells, frames) == []


def test_incompressible_body_dropped_on_another(tmp_path):
    """nu = 0.5 mixed, a cube falling under gravity onto a pinned slab: intersection free
    on every state, the energy (with gravity's) never above its start."""
    slab = {"shape": "box", "size": [0.2, 0.2, 0.05], "element_size": 0.1}
    cube = {"shape": "box", "size": [0.1, 0.1, 0.1], "element_size": 0.1}
    scene = make_scene(tmp_path, {
        "name": "drop_mixed",
        "element": {"degree": 2, "formulation": "mixed"},
        "time": {"integrator": "implicit_euler", "dt": H, "steps": 8},
        "gravity": {"acceleration": [0.0, 0.0, -9.81]},
        "contact": {"dhat": 0.004},
        "body": [{"name": "slab", "mesh": slab, "material": _material(0.5),
                  "pin": [{"name": "floor", "min": [-1, -1, -1e-6], "max": [1, 1, 1e-6]}]},
                 {"name": "cube", "offset": [0.05, 0.05, 0.06], "mesh": cube,
                  "material": _material(0.5), "initial": {"velocity": [0, 0, -0.5]}}]})
    sim = Simulation(scene)
    p = sim.problem
    state = sim.initial_state()
    p.u.x.array[:], p.v.x.array[:] = state.u, state.v
    start = p.energies()["total_energy"]
    states, pairs = [state], []
    for _ in range(8):
        state, stats = sim.step(state, H)
        assert stats.reason > 0
        states.append(state)
        pairs.append(sim._contact_stats()["contact_pairs"])
        p.u.x.array[:], p.v.x.array[:] = state.u, state.v
        assert p.energies()["total_energy"] <= start + 1e-9 * abs(start)
    assert max(pairs) > 0
    points, cells = _p2_check(sim)
    assert crossed_frames(points, cells, [s.u.reshape(-1, 3) for s in states]) == []


def test_p2_surface_in_2d_splits_each_edge_at_its_midpoint_dof():
    mesh = dmesh.create_rectangle(MPI.COMM_WORLD, [[0, 0], [1.0, 0.6]], [3, 2])
    V = compat.vector_space(mesh, 2)
    mesh.topology.create_connectivity(1, 2)
    mesh.topology.create_connectivity(1, 0)
    mesh.topology.create_connectivity(2, 0)
    facets = dmesh.exterior_facet_indices(mesh.topology)
    f_to_v = mesh.topology.connectivity(1, 0).array.reshape(-1, 2)
    c_to_v = mesh.topology.connectivity(2, 0).array.reshape(-1, 3)
    faces, parent = surface_faces(V, f_to_v[facets], c_to_v)
    assert faces.shape == (2 * facets.size, 2)
    X = V.tabulate_dof_coordinates()[:, :2]
    v_to_geo = np.empty(c_to_v.max() + 1, np.int64)
    v_to_geo[c_to_v.ravel()] = compat.geometry_dofmap(mesh).ravel()
    a, b = (mesh.geometry.x[v_to_geo[f_to_v[facets, i]], :2] for i in range(2))
    m = (a + b) / 2
    expected = np.stack([np.stack([a, m], 1), np.stack([m, b], 1)], 1)
    np.testing.assert_allclose(X[faces].reshape(expected.shape), expected, atol=1e-14)
    assert np.array_equal(parent, np.repeat(np.arange(facets.size), 2))


DROP = Path(__file__).resolve().parents[1] / "docs" / "contact_scenes" / "incompressible_drop.toml"


def test_mixed_contact_scene_gets_the_secant_line_search():
    """A mixed scene with contact gets ``l2`` unless it names a line search; without contact,
    and for the displacement formulation, the minimiser's own (``bt``) stays."""
    assert load_scene(DROP, [])["solver"]["petsc"] == MIXED_CONTACT_PETSC
    named = load_scene(DROP, ['solver.petsc.snes_linesearch_type="bt"'])
    assert named["solver"]["petsc"] == {"snes_linesearch_type": "bt"}
    mixed_alone = ['element.degree=2', 'element.formulation="mixed"', "damping.beta=0",
                   'material.model="neohookean"']
    assert "snes_linesearch_type" not in load_scene(None, mixed_alone)["solver"]["petsc"]


def test_incompressible_drop_impact_steps_are_not_retried():
    """The documented drop, its impact (steps 1-3 of 10 ms, pairs from step 2): every step
    is solved at the full dt (backtracking on ||r||^2 failed at step 2 and was retried)."""
    sim = Simulation(load_scene(DROP, ["time.steps=3"]))
    state = sim.initial_state()
    pairs = []
    for _ in range(3):
        state, stats = sim.step(state, H)
        assert stats.reason > 0
        pairs.append(sim._contact_stats()["contact_pairs"])
    assert max(pairs) > 0
