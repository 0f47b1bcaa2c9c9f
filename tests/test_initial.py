"""Initial velocity and angular velocity of a body (``[initial]``, :mod:`fem_anim.simulation.initial_state`).

* A free body (no gravity, no pins) given a velocity translates rigidly: u = v t and the
  momentum p = sum_i (M v)_i stay exact to round-off, and Newmark's a_0 is zero.
* A free body given an angular velocity about its centre of mass (the default ``center``):
  its kinetic energy at t = 0 is 1/2 m |v|^2 + 1/2 omega . I omega with the box's inertia
  tensor I = m/12 diag(b^2 + c^2, a^2 + c^2, a^2 + b^2) (computed here in closed form, not
  from the mesh), since P1 and P2 interpolate the affine velocity field exactly; p is
  conserved to round-off and Newmark's modified angular momentum
  L~ = sum_i (x_i - h^2/4 a_i) x (M v)_i (tests/test_analytic.py) to the Newton tolerance.
* a_0 is consistent with the start of the integrator: with Rayleigh damping C = alpha M a
  translating body starts with a_0 = M^-1 (f - C v_0) = -alpha v_0.
* Pinned dofs start at rest; bad ``[initial]`` values are rejected naming the key.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from scenes import DENSITY, DIVISIONS, LENGTHS, beam, make_scene, toml_list
from test_analytic import box, cross, scipy_matrix

from fem_anim.errors import SceneError
from fem_anim.simulation.initial_state import rigid_velocity
from fem_anim.simulation.loop import Simulation

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                reason="serial: the checks work on global dof arrays")

NEWTON = {"snes_rtol": "1e-12", "snes_atol": "1e-14"}
VELOCITY = (0.3, -0.2, 0.1)
OMEGA = {2: 2.0, 3: [0.5, 1.0, 1.5]}
DT, STEPS = 0.05, 10


def write_scene(directory, name: str, d: int, initial: str, *, degree: int = 1,
                extra: str = ""):
    scene = beam(name, d, element={"degree": degree}, material={"model": "neohookean"})
    return make_scene(directory, scene, f"[initial]\n{initial}\n{extra}")


def simulation(scene, d: int) -> Simulation:
    return Simulation(scene, MPI.COMM_WORLD, cli_options=NEWTON,
                      domain=box(DIVISIONS[d], LENGTHS[d]))


@pytest.mark.parametrize("d", (2, 3))
def test_free_body_translates_with_constant_momentum(tmp_path, d):
    velocity = VELOCITY[:d]
    sim = simulation(write_scene(tmp_path, f"drift{d}", d, f"velocity = {toml_list(velocity)}"),
                     d)
    M = scipy_matrix(sim.problem.mass_form)
    state = sim.initial_state()
    np.testing.assert_allclose(state.v.reshape(-1, d), np.tile(velocity, (state.v.size // d, 1)))
    assert np.abs(state.a).max() < 1e-12
    p0 = (M @ state.v).reshape(-1, d).sum(axis=0)
    mass = DENSITY * np.prod(LENGTHS[d])
    np.testing.assert_allclose(p0, mass * np.asarray(velocity), rtol=1e-12)
    for _ in range(STEPS):
        state, _ = sim.step(state, DT)
        p = (M @ state.v).reshape(-1, d).sum(axis=0)
        assert np.abs(p - p0).max() <= 1e-12 * np.abs(p0).max()
    drift = np.abs(state.u.reshape(-1, d) - np.asarray(velocity) * state.time).max()
    assert drift < 1e-10, f"rigid translation off by {drift:.2e} m"
    sim.minimiser.destroy()


def box_inertia(d: int, mass: float) -> np.ndarray:
    """Inertia tensor of the homogeneous box about its centre (2D: the scalar I_zz)."""
    a = np.asarray(LENGTHS[d])
    if d == 2:
        return mass * (a[0] ** 2 + a[1] ** 2) / 12.0
    return mass / 12.0 * np.diag([a[1] ** 2 + a[2] ** 2, a[0] ** 2 + a[2] ** 2,
                                  a[0] ** 2 + a[1] ** 2])


@pytest.mark.parametrize("d, degree", [(2, 1), (3, 1), (3, 2)])
def test_spinning_body(tmp_path, d, degree):
    """E_kin(0) = 1/2 m v^2 + 1/2 omega.I.omega; p exact, Newmark's L~ conserved."""
    omega, velocity = OMEGA[d], VELOCITY[:d]
    initial = f"velocity = {toml_list(velocity)}\nangular_velocity = {omega}"
    sim = simulation(write_scene(tmp_path, f"spin{d}{degree}", d, initial, degree=degree), d)
    p = sim.problem
    state = sim.initial_state()
    X = p.V.tabulate_dof_coordinates()[:, :d]
    center = np.asarray(LENGTHS[d]) / 2  # the centre of mass of the homogeneous box
    np.testing.assert_allclose(state.v.reshape(-1, d),
                               rigid_velocity(X, velocity, omega, center), atol=1e-12)

    mass = DENSITY * np.prod(LENGTHS[d])
    w = np.asarray(omega, dtype=float)
    expected = 0.5 * mass * np.dot(velocity, velocity) + 0.5 * w @ (box_inertia(d, mass) @ w) \
        if d == 3 else 0.5 * mass * np.dot(velocity, velocity) + 0.5 * box_inertia(d, mass) * w ** 2
    kinetic = p.energies()["kinetic"]
    assert abs(kinetic - expected) <= 1e-12 * expected, (kinetic, expected)

    M = scipy_matrix(p.mass_form)

    def momenta(s):
        x = X + s.u.reshape(-1, d)
        Mv = (M @ s.v).reshape(-1, d)
        return Mv.sum(axis=0), cross(x - DT * DT / 4 * s.a.reshape(-1, d), Mv).sum(axis=0)

    p0, L0 = momenta(state)
    assert np.abs(L0).max() > 1.0
    for _ in range(STEPS):
        state, _ = sim.step(state, DT)
        p_n, L_n = momenta(state)
        assert np.abs(p_n - p0).max() <= 1e-12 * np.abs(p0).max()
        assert np.abs(L_n - L0).max() <= 1e-11 * np.abs(L0).max(), (L_n, L0)
    assert np.abs(state.u).max() > 0.2, "the body should have turned"
    sim.minimiser.destroy()


def test_initial_acceleration_includes_damping(tmp_path):
    """Newmark's a_0 = M^-1 (f(u_0) - C v_0): -alpha v_0 for a translating body."""
    scene = write_scene(tmp_path, "damped", 3, f"velocity = {toml_list(VELOCITY)}",
                        extra="[damping]\nalpha = 2.0\n")
    sim = simulation(scene, 3)
    state = sim.initial_state()
    np.testing.assert_allclose(state.a, -2.0 * state.v, atol=1e-10)
    sim.minimiser.destroy()


def test_pinned_dofs_start_at_rest(tmp_path):
    scene = write_scene(tmp_path, "pinned", 3, "angular_velocity = [0.0, 0.0, 1.0]\n"
                        "center = [0.0, 0.0, 0.0]",
                        extra="[[pin]]\nmin = [-1e-6, -1.0, -1.0]\nmax = [1e-6, 1.0, 1.0]\n")
    sim = simulation(scene, 3)
    state = sim.initial_state()
    X = sim.problem.V.tabulate_dof_coordinates()
    v = state.v.reshape(-1, 3)
    at_wall = np.abs(X[:, 0]) < 1e-9
    assert np.all(v[at_wall] == 0.0)
    np.testing.assert_allclose(v[~at_wall, 1], X[~at_wall, 0])  # omega_z x: v_y = x
    sim.minimiser.destroy()


@pytest.mark.parametrize("d, initial, message", [
    (2, "angular_velocity = [0.0, 0.0, 1.0]", "initial.angular_velocity must be a number"),
    (3, "angular_velocity = 1.0", "initial.angular_velocity must be a list of 3 numbers"),
    (3, 'angular_velocity = "fast"', "initial.angular_velocity must be a number"),
    (3, "velocity = [1.0, 0.0]", "initial.velocity must have 3 entries"),
    (2, "velocity = [1.0, 0.0]\ncenter = [0.0]", "initial.center must be a list of 2 or 3"),
    (2, "center = [0.0, 0.0]", "[initial] needs velocity or angular_velocity"),
    (2, "spin = 1.0", "unknown key initial.spin"),
])
def test_bad_initial(tmp_path, d, initial, message):
    with pytest.raises(SceneError) as err:
        write_scene(tmp_path, "bad", d, initial)
    assert message in str(err.value)
