"""The nonlinear solver menu: Hessian modification, the J > 0 filter, stopping tests, methods.

The compression scene squeezes a soft 0.2 m cube between a fixed floor and a press that
moves 5 cm per step (implicit Euler): elements are crushed, the exact Hessian becomes
indefinite and plain Newton fails.
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
from mpi4py import MPI

from fem_anim.errors import ConvergenceError
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation

SQUASH = """
name = "squash"
[mesh]
size = [0.2, 0.2, 0.2]
element_size = {element_size}
[material]
model = "{model}"
youngs_modulus = 1e4
poisson_ratio = 0.3
[time]
integrator = "implicit_euler"
dt = {dt}
steps = {steps}
[solver]
hessian = "{hessian}"
{solver}
[[pin]]
name = "floor"
min = [-1, -1, -0.001]
max = [1, 1, 0.001]
[[pin]]
name = "press"
min = [-1, -1, 0.199]
max = [1, 1, 0.201]
velocity = [0.0, 0.0, -1.0]
until = 0.17
"""


#: shift vs project: both stop at snes_rtol 1e-10 on the same minimisers; measured 7e-8
#: relative after 4 steps of the crushed StVK cube (a soft, ill-conditioned minimum).
SAME_MINIMISER_RTOL = 1e-6


def squash(tmp_path, model="stvk", hessian="exact", dt=0.05, steps=4, element_size=0.05,
           solver="", cli=None):
    path = tmp_path / f"squash_{model}_{hessian}.toml"
    # one writer (tests/mpi/mpi_trust_region_check.py runs this on 2 ranks): a rank reading
    # the file while another truncates it to write it again read a partial scene, raised
    # alone and left the other rank waiting in the mesh's broadcast (a hang under load)
    if MPI.COMM_WORLD.rank == 0:
        path.write_text(SQUASH.format(model=model, hessian=hessian, dt=dt, steps=steps,
                                      element_size=element_size, solver=solver))
    MPI.COMM_WORLD.Barrier()
    return Simulation(load_scene(path), MPI.COMM_WORLD, cli_options=cli)


def run_steps(sim, steps, dt):
    """``steps`` steps of ``dt`` from the initial state, each ending converged (a positive
    reason); the final state and the Newton iterations in all."""
    state = sim.initial_state()
    its = 0
    for _ in range(steps):
        state, stats = sim.step(state, dt)
        assert stats.reason > 0
        its += stats.newton_its
    return state, its


def test_hessian_modification_rescues_a_compression(tmp_path):
    """StVK crushed: exact Newton fails; the shifted and the projected Hessian converge, to
    the same minimisers (a modified Hessian changes the path, not the solution)."""
    # step 2 since the preset's MUMPS options (mat_mumps_cntl_1 = 0) reach the factorisation:
    # PETSc reads them when the first solve sets it up, when they used to be gone already
    with pytest.raises(ConvergenceError, match="step [12] .*did not converge"):
        run_steps(squash(tmp_path, hessian="exact"), 4, 0.05)
    results, solutions = {}, {}
    for hessian in ("shift", "project"):
        sim = squash(tmp_path, hessian=hessian, cli={"snes_rtol": "1e-10"})
        start = time.perf_counter()
        state, its = run_steps(sim, 4, 0.05)
        results[hessian] = (its, time.perf_counter() - start)
        solutions[hessian] = state.u
        assert np.all(np.isfinite(state.u))
        press = state.u.reshape(-1, 3)[sim.problem.moving_pins[0].dofs, 2]
        assert press == pytest.approx(-0.17)
    print("compression (stvk, 4 steps): Newton iterations and wall s:", results)
    difference = np.linalg.norm(solutions["shift"] - solutions["project"])
    print("shift vs project, relative difference:",
          difference / np.linalg.norm(solutions["project"]))
    assert difference <= SAME_MINIMISER_RTOL * np.linalg.norm(solutions["project"])
    assert sim.minimiser.shift is None
    assert squash(tmp_path, hessian="shift").minimiser.shift is not None


def test_shift_raises_and_relaxes(tmp_path):
    """c is raised while H + c I is indefinite, then quartered after each success."""
    sim = squash(tmp_path, model="stable_neohookean", hessian="shift")
    shift = sim.minimiser.shift
    accepted = []  # (shift, raises so far) of every successful factorisation
    succeeded = shift.succeeded

    def record():
        accepted.append((shift.c, shift.raises))
        succeeded()

    shift.succeeded = record
    run_steps(sim, 4, 0.05)
    assert shift.raises > 0  # the exact Hessian was indefinite at least once
    c = np.array([a[0] for a in accepted])
    raises = np.array([a[1] for a in accepted])
    peak = int(np.argmax(c))
    assert c[peak] > 0
    # each success quarters c for the next factorisation: where that one succeeds at once
    # (no raise in between) the next accepted c is exactly a quarter, else it was raised
    # from the quarter (the path depends on the mesh: gmsh 4.8's needs no raise after the
    # peak of 4.0, gmsh 4.13's one)
    at_once = raises[peak + 1:] == raises[peak:-1]
    np.testing.assert_allclose(c[peak + 1:][at_once], 0.25 * c[peak:-1][at_once], rtol=1e-15)
    assert np.all(c[peak + 1:][~at_once] > 0.25 * c[peak:-1][~at_once])
    assert np.count_nonzero(at_once) >= 4
    assert shift.c == 0.25 * c[-1] and shift.c < 1e-4 * c[peak]


def test_inversion_filter_prevents_a_nan(tmp_path):
    """Full Newton steps (no line search) crush a neo-Hookean element at step 7: ln J of a
    negative J is NaN. The filter halves the step before that, and the run completes."""
    kwargs = dict(model="neohookean", dt=0.025, steps=8, cli={"snes_linesearch_type": "basic"})
    sim = squash(tmp_path, solver="inversion_filter = false", **kwargs)
    with pytest.raises(ConvergenceError, match="DIVERGED_FNORM_NAN"):
        run_steps(sim, 8, 0.025)
    sim = squash(tmp_path, **kwargs)
    assert sim.problem.filter_inversion  # on by default for neo-Hookean
    state, _ = run_steps(sim, 8, 0.025)
    assert np.all(np.isfinite(state.u)) and sim.problem.min_det_F() > 0
    energies = sim.problem.energies()
    assert all(math.isfinite(v) for v in energies.values())


def test_decrement_and_norm_tests_stop_at_the_same_solution(tmp_path):
    """On a convex step (mild compression), lambda^2/2 <= eps and a tight norm test agree."""
    kwargs = dict(model="neohookean", dt=0.01, steps=3, element_size=0.1)
    by_norm, _ = run_steps(squash(tmp_path, cli={"snes_rtol": "1e-12", "snes_atol": "1e-14"},
                                  **kwargs), 3, 0.01)
    sim = squash(tmp_path, solver='stopping = "decrement"\ndecrement_tol = 1e-16', **kwargs)
    state = sim.initial_state()
    for _ in range(3):
        state, stats = sim.step(state, 0.01)
        assert stats.reason == 5 and stats.newton_decrement <= 1e-16
    assert np.linalg.norm(state.u - by_norm.u) <= 1e-10 * np.linalg.norm(by_norm.u)


@pytest.mark.parametrize("method, rtol", [("trust_region", 1e-7), ("lbfgs", 1e-5),
                                          ("ncg", 1e-4), ("gradient_descent", 1e-3)])
def test_nonlinear_methods_reach_the_same_step(tmp_path, method, rtol):
    kwargs = dict(model="neohookean", dt=0.01, steps=1, element_size=0.1)
    newton, _ = run_steps(squash(tmp_path, cli={"snes_rtol": "1e-12"}, **kwargs), 1, 0.01)
    sim = squash(tmp_path, solver=f'method = "{method}"', cli={"snes_rtol": "1e-9"}, **kwargs)
    other, its = run_steps(sim, 1, 0.01)
    assert np.linalg.norm(other.u - newton.u) <= rtol * np.linalg.norm(newton.u), its


def test_stats_carry_the_solver_figures(tmp_path):
    sim = squash(tmp_path, model="neohookean", dt=0.01, steps=2, element_size=0.1)
    state = sim.initial_state()
    state, stats = sim.step(state, 0.01)
    assert stats.newton_its >= 1 and math.isfinite(stats.newton_decrement)
    parts = stats.assembly_s + stats.factor_s + stats.linear_solve_s
    assert 0 < parts <= stats.wall_s * 1.05
    assert stats.assembly_s > 0 and stats.factor_s > 0


@pytest.mark.parametrize("dim", [2, 3])
def test_near_nullspace_is_the_rigid_body_modes(tmp_path, dim):
    """The Hessian carries the rigid-body modes (for GAMG): K_0 z = 0 for each mode."""
    import ufl
    from dolfinx import fem
    from dolfinx.fem import petsc as fem_petsc

    overrides = [] if dim == 3 else ["mesh.dim=2", "mesh.size=[1.0, 0.2]",
                                     "gravity.acceleration=[0, -9.81]", "pin.0.min=[0, 0]",
                                     "pin.0.max=[0.001, 1]"]
    sim = Simulation(load_scene(None, ["mesh.element_size=0.1"] + overrides), MPI.COMM_WORLD)
    p = sim.problem
    vectors = p.rigid_body_modes().getVecs()
    assert len(vectors) == (6 if dim == 3 else 3)
    gram = np.array([[a.dot(b) for b in vectors] for a in vectors])
    np.testing.assert_allclose(gram, np.eye(len(vectors)), atol=1e-12)
    v, du = ufl.TestFunction(p.V), ufl.TrialFunction(p.V)
    K = fem_petsc.assemble_matrix(fem.form(ufl.derivative(ufl.derivative(
        p.ufl_elastic, p.u, v), p.u, du)))
    K.assemble()
    scale = K.norm()
    for z in vectors:
        Kz = z.duplicate()
        K.mult(z, Kz)
        assert Kz.norm() <= 1e-10 * scale
    assert sim.minimiser.A.getNearNullSpace().getVecs()
