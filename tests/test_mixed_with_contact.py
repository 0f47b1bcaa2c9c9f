"""The mixed (u, p) formulation with Rayleigh damping and obstacles.

* mass-proportional damping of a translating body: its momentum falls by the implicit
  Euler closed form 1/(1 + alpha h) per step (no elastic force in a rigid translation);
* stiffness-proportional damping of the displacement block (its deviatoric K_0,
  :meth:`fem_anim.problem.energy_terms.EnergyTerms._dissipation`): at nu = 0.45 a body
  shaken in shear loses what the displacement formulation's full beta K_0 takes from it;
* an exactly incompressible body (nu = 0.5) dropped on a plane obstacle: no contact point
  reaches the plane, the tangential momentum stays zero, the energy never rises.
"""

from __future__ import annotations

import numpy as np
import pytest
from scenes import make_scene

from fem_anim.simulation.loop import Simulation

H = 0.01  # s


def _box(tmp_path, name, formulation="mixed", nu=0.5, **sections):
    keys = {"name": name,
            "mesh": {"dim": 2, "size": [0.2, 0.2], "element_size": 0.1},
            "element": {"degree": 2, "formulation": formulation},
            "material": {"model": "stable_neohookean", "youngs_modulus": 1e4,
                         "poisson_ratio": nu, "density": 1000.0},
            "time": {"integrator": "implicit_euler", "dt": H, "steps": 10}}
    for k, v in sections.items():
        keys[k] = keys.get(k, {}) | v if isinstance(v, dict) else v
    return make_scene(tmp_path, keys)


def _momentum(sim, v):
    """Total momentum M v per direction (collective)."""
    p = sim.problem
    from dolfinx.fem import petsc as fem_petsc

    M = fem_petsc.assemble_matrix(p.mass_form)
    M.assemble()
    vec, out = M.createVecRight(), M.createVecLeft()
    n = vec.getLocalSize()
    vec.array[:] = v[:n]
    M.mult(vec, out)
    local = out.array.reshape(-1, 2).sum(axis=0)
    return p.comm.allreduce(local)


def test_mass_damping_decays_momentum_by_the_closed_form(tmp_path):
    """alpha = 3 1/s, implicit Euler: p_n = p_0 / (1 + alpha h)^n to round-off, nu = 0.5."""
    alpha = 3.0
    scene = _box(tmp_path, "translating", damping={"alpha": alpha, "beta": 0.0},
                 initial={"velocity": [0.5, 0.2]})
    assert scene["solver"]["preset"] == "ldlt"  # chosen for the saddle point, not named
    sim = Simulation(scene)
    state = sim.initial_state()
    p0 = _momentum(sim, state.v)
    for n in range(1, 6):
        state, stats = sim.step(state, H)
        assert stats.reason > 0
        np.testing.assert_allclose(_momentum(sim, state.v), p0 / (1 + alpha * H) ** n,
                                   rtol=1e-8)


def _shear_energies(tmp_path, formulation, beta, nu=0.45):
    """Total energy after 8 steps of a square pinned at its base, started in shear."""
    scene = _box(tmp_path, f"shear_{formulation}_{beta}", formulation=formulation, nu=nu,
                 damping={"alpha": 0.0, "beta": beta},
                 pin=[{"name": "base", "min": [-1.0, -1e-6], "max": [1.0, 1e-6]}],
                 initial={"velocity": [0.3, 0.0]})
    sim = Simulation(scene)
    state = sim.initial_state()
    sim.problem.v.x.array[:] = state.v
    start = sim.problem.energies()["total_energy"]
    for _ in range(8):
        state, stats = sim.step(state, H)
        assert stats.reason > 0
    sim.problem.v.x.array[:] = state.v
    return start, sim.problem.energies()["total_energy"]


def test_stiffness_damping_matches_the_displacement_formulation(tmp_path):
    """beta = 0.01 s at nu = 0.45: the energy the damping takes (damped against undamped
    run) agrees with the displacement formulation's within 10 % (measured: 12.7 % and
    13.6 % of the start energy; the deviatoric part carries most of it in a shear
    motion); without the term it would take nothing."""
    losses = {}
    for formulation in ("mixed", "displacement"):
        start, free = _shear_energies(tmp_path, formulation, 0.0)
        _, damped = _shear_energies(tmp_path, formulation, 0.01)
        assert damped < free <= start * (1 + 1e-9)
        losses[formulation] = (free - damped) / start
    assert losses["mixed"] > 0.05, losses
    assert losses["mixed"] == pytest.approx(losses["displacement"], rel=0.1), losses


def test_stiffness_damping_of_an_incompressible_body(tmp_path):
    """nu = 0.5 (lambda infinite, never formed): the damped run stays finite and loses
    energy against the undamped one."""
    start, free = _shear_energies(tmp_path, "mixed", 0.0, nu=0.5)
    _, damped = _shear_energies(tmp_path, "mixed", 0.01, nu=0.5)
    assert np.isfinite(damped) and damped < 0.95 * free <= start * (1 + 1e-9)


def test_incompressible_body_lands_on_a_plane(tmp_path):
    """nu = 0.5, dropped from 5 mm onto y = 0 under gravity, 25 steps of 10 ms: every
    contact point stays above the plane, the horizontal momentum stays 0, and the total
    energy (kinetic, elastic, gravity, barrier) never exceeds its start."""
    scene = _box(tmp_path, "landing", mesh={"origin": [0.0, 0.005]},
                 gravity={"acceleration": [0.0, -9.81]},
                 obstacle=[{"name": "floor", "type": "plane", "normal": [0.0, 1.0],
                            "dhat": 0.004, "stiffness": 1e4}],
                 time={"steps": 25})
    sim = Simulation(scene)
    state = sim.initial_state()
    sim.problem.v.x.array[:] = state.v
    start = sim.problem.energies()["total_energy"]
    touched = False
    for _ in range(25):
        state, stats = sim.step(state, H)
        assert stats.reason > 0
        sim.problem.u.x.array[:], sim.problem.v.x.array[:] = state.u, state.v
        energies = sim.problem.energies()
        distance = sim.problem.contact.min_distance()
        assert distance > 0.0
        touched = touched or distance < 0.004
        assert energies["total_energy"] <= start + 1e-9 * abs(start), energies
        assert abs(_momentum(sim, state.v)[0]) < 1e-10
    assert touched  # the barrier acted
    assert _momentum(sim, state.v)[1] > -0.05 * 1000 * 0.04 * 9.81 * 25 * H  # it stopped
