"""Rayleigh damping (a dissipation potential in the step objective) and animated pins.

Newmark with a linear material satisfies the discrete energy identity
E_{n+1} - E_n = -h v_m^T C v_m exactly, v_m = (v_n + v_{n+1})/2, C = alpha M + beta K_0:
the test checks it step by step, for mass- and stiffness-proportional damping.
"""

from __future__ import annotations

import numpy as np
import pytest
import scenes
import ufl
from dolfinx import fem
from mpi4py import MPI

from fem_anim.errors import SceneError
from fem_anim.forms.damping import dissipation_potential
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation


def bar(tmp_path, integrator="newmark", alpha=None, beta=None, extra=""):
    damping = None
    if alpha is not None or beta is not None:
        damping = {"alpha": alpha or 0.0, "beta": beta or 0.0}
    scene = scenes.make_scene(tmp_path, scenes.bar(
        "bar", material={"model": "linear", "youngs_modulus": 1e5},
        time={"integrator": integrator, "dt": 0.005, "steps": 40}, damping=damping,
        pin=[{"name": "wall", "min": [-0.01, -1, -1], "max": [0.01, 1, 1]}]), extra)
    sim = Simulation(scene, MPI.COMM_WORLD, {"snes_rtol": "1e-12"})
    state = sim.initial_state()
    X = sim.problem.V.tabulate_dof_coordinates()
    state.v = np.zeros_like(state.u)
    state.v.reshape(-1, 3)[:, 2] = 0.5 * X[:, 0] ** 2  # a bending-like initial velocity
    if sim.integrator.name == "newmark":
        state.a = sim.acceleration(state.u, state.v)
    return sim, state


def mechanical_energy(sim, state) -> float:
    p = sim.problem
    p.u.x.array[:] = state.u
    p.v.x.array[:] = state.v
    e = p.energies()
    return e["kinetic"] + e["elastic"]


@pytest.mark.parametrize("alpha, beta", [(2.0, 0.0), (0.0, 2e-3), (1.0, 1e-3)])
def test_newmark_discrete_energy_identity(tmp_path, alpha, beta):
    sim, state = bar(tmp_path, alpha=alpha, beta=beta)
    p = sim.problem
    v_mid = fem.Function(p.V)
    half_vCv = fem.form(dissipation_potential(v_mid, ufl.as_vector([0.0] * 3), 1.0, alpha, beta,
                                              p.rho, p.mu, p.lmbda, p.dx_mass, p.dx_elastic))
    h = 0.005
    energy = mechanical_energy(sim, state)
    start = energy
    for _ in range(40):
        new, _ = sim.step(state, h)
        v_mid.x.array[:] = 0.5 * (state.v + new.v)
        dissipated = h * 2.0 * p.assemble_scalar(half_vCv)
        new_energy = mechanical_energy(sim, new)
        assert new_energy - energy == pytest.approx(-dissipated, rel=1e-7, abs=1e-12 * start)
        energy, state = new_energy, new
    assert energy < start


def test_newmark_undamped_conserves_energy(tmp_path):
    sim, state = bar(tmp_path)
    start = mechanical_energy(sim, state)
    for _ in range(40):
        state, _ = sim.step(state, 0.005)
    assert mechanical_energy(sim, state) == pytest.approx(start, rel=1e-9)


@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2"])
def test_damping_adds_to_numerical_dissipation(tmp_path, integrator):
    energies = []
    for alpha in (None, 2.0):
        sim, state = bar(tmp_path, integrator=integrator, alpha=alpha)
        for _ in range(20):
            state, _ = sim.step(state, 0.005)
        energies.append(mechanical_energy(sim, state))
    assert energies[1] < energies[0]


def test_no_damping_section_builds_no_damping_term(tmp_path):
    sim, _ = bar(tmp_path)
    coefficients = {c.name for c in sim.problem.ufl_objective.coefficients()}
    assert "damping_anchor" not in coefficients and sim.problem.damping_force_form is None
    sim, _ = bar(tmp_path, alpha=1.0)
    assert "damping_anchor" in {c.name for c in sim.problem.ufl_objective.coefficients()}


def test_zero_damping_section_is_the_undamped_scene(tmp_path):
    """``[damping]`` with alpha = beta = 0 (a sweep's zero) builds no term and runs as if the
    section were absent (it raised a TypeError from the empty form before)."""
    sim, state = bar(tmp_path, alpha=0.0, beta=0.0)
    assert not sim.scene.damped and sim.problem.damping_force_form is None
    plain, plain_state = bar(tmp_path)
    for _ in range(3):
        state, _ = sim.step(state, 0.005)
        plain_state, _ = plain.step(plain_state, 0.005)
    assert np.array_equal(state.u, plain_state.u)


HANDLE = """
[[pin]]
name = "handle"
min = [0.99, -1, -1]
max = [1.01, 1, 1]
velocity = [0.0, 0.0, 0.2]
angular_velocity = 2.0
axis = [1, 0, 0]
center = [1.0, 0.05, 0.05]
until = 0.05
"""


def test_animated_handle_follows_its_path(tmp_path):
    sim, state = bar(tmp_path, extra=HANDLE)
    p = sim.problem
    motion = p.moving_pins[0]
    X = motion.X
    for _ in range(15):
        state, _ = sim.step(state, 0.005)
        t = min(state.time, 0.05)
        theta = 2.0 * t
        r = X - np.array([1.0, 0.05, 0.05])
        R = np.array([[1, 0, 0], [0, np.cos(theta), -np.sin(theta)],
                      [0, np.sin(theta), np.cos(theta)]])
        expected = r @ R.T - r + np.array([0.0, 0.0, 0.2 * t])
        u = state.u.reshape(-1, 3)[motion.dofs]
        np.testing.assert_allclose(u, expected, atol=1e-13)
    # the handle stops at `until` and the bar keeps its twist
    assert np.linalg.norm(state.u.reshape(-1, 3)[motion.dofs], axis=1).max() > 0.01


@pytest.mark.parametrize("override, message", [
    ("pin.0.axis=[0, 0, 0]", "pin[0].axis must not be the zero vector"),
    ("pin.0.angular_velocity=1.0", "pin[0].axis is required with pin[0].angular_velocity"),
    ("pin.0.velocity=[1, 0]", "pin[0].velocity must have 3 entries"),
    ("pin.0.until=-1", "pin[0].until must be >= 0"),
    ("damping.alpha=-1", "damping.alpha must be >= 0"),
])
def test_handle_and_damping_validation(override, message):
    with pytest.raises(SceneError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_scene(None, [override])


def test_newmark_pins_move_at_their_prescribed_rates(tmp_path):
    """A handle pulls the bar at 0.2 m/s for 0.05 s, then stops.

    Newmark's trapezoidal update alone, v_{n+1} = 2 (u_{n+1} - u_n)/h - v_n, gives the
    pinned dofs 0.4, 0, 0.4, 0, ... m/s while the handle moves (and the kinetic energy a
    matching sawtooth); the pins' exact rates (:meth:`PinMotion.rates`) replace it.
    """
    pull = HANDLE.replace("angular_velocity = 2.0", "angular_velocity = 0.0")
    sim, state = bar(tmp_path, alpha=20.0, extra=pull)
    state.v[:] = 0.0
    state.a = sim.acceleration(state.u, state.v)
    dofs = sim.problem.moving_pins[0].dofs
    for _ in range(16):
        state, _ = sim.step(state, 0.005)
        moving = state.time < 0.05 - 1e-12
        np.testing.assert_allclose(state.v.reshape(-1, 3)[dofs],
                                   [[0.0, 0.0, 0.2 if moving else 0.0]] * len(dofs), atol=1e-14)
        assert np.abs(state.a.reshape(-1, 3)[dofs]).max() == 0.0


def test_handle_rates_are_the_derivatives_of_its_path():
    """Central differences of the displacement give the velocity and acceleration."""
    from fem_anim.problem.handles import PinMotion

    rng = np.random.default_rng(1)
    for d in (2, 3):
        X = rng.random((5, d))
        axis = np.array([1.0, 2.0, 2.0]) / 3.0
        motion = PinMotion(np.arange(5), X, rng.random(d), 1.7, axis, rng.random(d), 0.8)
        t, h = 0.3, 1e-4
        v, a = motion.rates(t)
        fd_v = (motion.displacement(t + h) - motion.displacement(t - h)) / (2 * h)
        fd_a = (motion.displacement(t + h) - 2 * motion.displacement(t)
                + motion.displacement(t - h)) / h**2
        np.testing.assert_allclose(v, fd_v, atol=1e-7)
        np.testing.assert_allclose(a, fd_a, atol=1e-5)
        assert not np.any(motion.rates(0.8)[0]) and not np.any(motion.rates(2.0)[1])
