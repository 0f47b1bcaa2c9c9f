"""Each body's initial motion in a scene of several bodies, about its own centre.

The contract (:mod:`fem_anim.simulation.initial_state`): each ``[[body]]``'s ``initial``
gives that body the rigid velocity v + omega x (X - c_k) about its *own* centre of mass
c_k, and nothing to the other bodies. With P1 the affine field is interpolated exactly, so
the consistent mass gives each body, computed here per body from the assembled mass
matrix,

* linear momentum   P_k = m_k v_k,
* angular momentum  L_k = sum_i (x_i - c_k) x (M v)_i = I_k omega_k about c_k,
* kinetic energy    T_k = 1/2 m_k |v_k|^2 + 1/2 omega_k . I_k omega_k,

with m_k and I_k in closed form: a box a x b x c turned by R has I = R I_0 R^T,
I_0 = m/12 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2) (not from the mesh). The spinning body is
turned about two axes and placed away from the origin and from the other bodies, so a
centre taken from the whole scene, a sign of omega x r or a misplaced inertia all show.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from scipy.spatial.transform import Rotation
from test_analytic import scipy_matrix

from fem_anim import compat
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                reason="serial: the checks work on global dof arrays")

DENSITY = (1000.0, 800.0, 1200.0)
SIZES = ([0.2, 0.1, 0.1], [0.3, 0.2, 0.1], [0.1, 0.1, 0.1])
OFFSETS = ([-0.5, 0.0, 0.0], [0.6, 0.3, -0.2], [0.0, 0.8, 0.0])
ROTATION = [30.0, 60.0, 0.0]
VELOCITY = ([0.4, -0.1, 0.0], [-0.2, 0.3, 0.5], None)
OMEGA = (None, [1.5, -2.0, 3.0], [0.0, 0.0, 4.0])


def body_table(k: int) -> str:
    size = np.asarray(SIZES[k])
    initial = ", ".join(f"{key} = {value}" for key, value in
                        (("velocity", VELOCITY[k]), ("angular_velocity", OMEGA[k]))
                        if value is not None)
    rotation = f"rotation = {ROTATION}\n" if k == 1 else ""
    return (f'[[body]]\nname = "b{k}"\noffset = {OFFSETS[k]}\n{rotation}'
            f"mesh = {{ shape = \"box\", size = {SIZES[k]}, divisions = [2, 2, 2], "
            f"origin = {[float(v) for v in -size / 2]} }}\n"
            f"material = {{ youngs_modulus = 1e5, density = {DENSITY[k]} }}\n"
            f"initial = {{ {initial} }}\n")


def closed_form(k: int):
    """(mass, centre, inertia tensor about the centre) of body k."""
    a, b, c = SIZES[k]
    mass = DENSITY[k] * a * b * c
    inertia = mass / 12.0 * np.diag([b * b + c * c, a * a + c * c, a * a + b * b])
    if k == 1:
        R = Rotation.from_euler("xyz", ROTATION, degrees=True).as_matrix()
        inertia = R @ inertia @ R.T
    return mass, np.asarray(OFFSETS[k]), inertia


@pytest.fixture(scope="module")
def three_bodies(tmp_path_factory):
    path = tmp_path_factory.mktemp("bodies") / "three.toml"
    path.write_text('name = "three"\n[time]\ndt = 0.01\nsteps = 1\n'
                    + "".join(body_table(k) for k in range(3)))
    sim = Simulation(load_scene(path), MPI.COMM_WORLD)
    state = sim.initial_state()
    M = scipy_matrix(sim.problem.mass_form)
    X = sim.problem.V.tabulate_dof_coordinates()[:, :3]
    bodies = []
    for k in range(3):
        cells = np.flatnonzero(sim.problem.cell_body == k).astype(np.int32)
        dofs = np.unique(compat.dofs_of_cells(sim.problem.V, cells))
        bodies.append(dofs)
    yield M, X, state.v.reshape(-1, 3), bodies
    sim.minimiser.destroy()


def test_bodies_do_not_share_dofs(three_bodies):
    _, X, _, bodies = three_bodies
    assert sum(b.size for b in bodies) == X.shape[0] == np.unique(np.concatenate(bodies)).size


@pytest.mark.parametrize("k", range(3))
def test_each_body_moves_rigidly_about_its_own_centre(three_bodies, k):
    M, X, v, bodies = three_bodies
    mass, centre, inertia = closed_form(k)
    dofs = bodies[k]
    velocity = np.zeros(3) if VELOCITY[k] is None else np.asarray(VELOCITY[k])
    omega = np.zeros(3) if OMEGA[k] is None else np.asarray(OMEGA[k])
    Mv = (M @ v.reshape(-1)).reshape(-1, 3)
    P = Mv[dofs].sum(axis=0)
    L = np.cross(X[dofs] - centre, Mv[dofs]).sum(axis=0)
    vk = np.zeros_like(v)
    vk[dofs] = v[dofs]
    T = 0.5 * vk.reshape(-1) @ (M @ vk.reshape(-1))
    scale = mass * (np.linalg.norm(velocity) + np.linalg.norm(omega) * 0.2)
    np.testing.assert_allclose(P, mass * velocity, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(L, inertia @ omega, rtol=0, atol=1e-12 * scale)
    expected = 0.5 * mass * velocity @ velocity + 0.5 * omega @ inertia @ omega
    assert T == pytest.approx(expected, rel=1e-12)


def test_total_momentum_is_the_sum_of_the_bodies(three_bodies):
    """The scene's P is sum_k m_k v_k: no body's motion leaks into another's dofs."""
    M, _, v, _ = three_bodies
    P = (M @ v.reshape(-1)).reshape(-1, 3).sum(axis=0)
    expected = sum(closed_form(k)[0] * np.asarray(VELOCITY[k] or [0.0, 0.0, 0.0])
                   for k in range(3))
    np.testing.assert_allclose(P, expected, atol=1e-12)
