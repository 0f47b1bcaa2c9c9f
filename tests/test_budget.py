"""The solver's budget: ``solver.max_iterations`` and ``solver.on_budget``.

The bar (:func:`scenes.bar`, 1 x 0.1 x 0.1 m, pinned at x = 0) falls under gravity from
rest: a soft material (E = 2e5 Pa) bends far enough in a step of 1/30 s that Newton needs
several iterations, so a budget of 1 or 2 is really spent.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import scenes
from conftest import mpirun_command
from mpi4py import MPI
from petsc4py import PETSc
from test_cli import read_stats

from fem_anim.cli import main
from fem_anim.errors import ConvergenceError
from fem_anim.simulation.adaptive import AdaptiveStepper
from fem_anim.simulation.loop import Simulation
from fem_anim.solver.stopping import BUDGET_REASON, CONVERGED_REASONS, accept_at_budget

DT = 1.0 / 30.0
#: The accepted x of a one-step budget against x_0 - alpha H^-1 r computed here: both are
#: one MUMPS solve of the same matrix (measured 1e-15 relative; round-off of the solve).
LINEAR_STEP_RTOL = 1e-10


def falling_bar(tmp_path, name="budget_bar", adaptive=True, steps=4, **solver):
    scene = scenes.bar(name, material={"youngs_modulus": 2.0e5, "poisson_ratio": 0.3,
                                       "density": 1000.0, "model": "neohookean"},
                       gravity={"acceleration": [0.0, 0.0, -9.81]},
                       time={"integrator": "implicit_euler", "dt": DT, "steps": steps,
                             "adaptive": adaptive},
                       output={"render": False}, solver=solver or None)
    return scenes.make_scene(tmp_path, scene)


def test_one_newton_step_is_the_linearly_implicit_step(tmp_path):
    """max_iterations = 1: x = x_0 - alpha H(x_0)^-1 r(x_0), with H, r assembled here."""
    sim = Simulation(falling_bar(tmp_path, max_iterations=1, on_budget="accept"),
                     MPI.COMM_WORLD)
    problem, minimiser = sim.problem, sim.minimiser
    solve = minimiser.solve
    seen = {}

    def linear_step_then_solve(x, what="step"):
        x0, r, y = x.copy(), x.duplicate(), x.duplicate()
        A = problem.create_matrix()
        problem.residual(None, x0, r)
        problem.jacobian(None, x0, A, A)
        ksp = PETSc.KSP().create(x.getComm())
        ksp.setOperators(A, A)
        ksp.setType("preonly")
        ksp.getPC().setType("cholesky")
        ksp.getPC().setFactorSolverType("mumps")
        ksp.solve(r, y)
        stats = solve(x, what)
        d = x0.copy()
        d.axpy(-1.0, x)  # x_0 - x = alpha y
        alpha = d.dot(y) / y.dot(y)
        d.axpy(-alpha, y)
        seen.update(alpha=alpha, error=d.norm() / (abs(alpha) * y.norm()), stats=stats)
        for obj in (x0, r, y, A, ksp, d):
            obj.destroy()
        return stats

    minimiser.solve = linear_step_then_solve
    state = sim.initial_state()
    for _ in range(3):
        state, _ = sim.step(state, DT)
        stats = seen["stats"]
        assert stats.newton_its == 1 and stats.reason == BUDGET_REASON
        assert stats.residual_ratio > 1.0 and math.isfinite(stats.newton_decrement)
        assert seen["alpha"] == pytest.approx(1.0, abs=1e-12)  # the full step was taken
        assert seen["error"] <= LINEAR_STEP_RTOL


def run_rows(sim, steps=4):
    """Each accepted substep's stats row through the adaptive stepper (retries included)."""
    stepper = AdaptiveStepper(sim, DT, sim.scene["time"])
    rows, state = [], sim.initial_state()
    for state, row in stepper.advance(state, steps * DT):
        rows.append(row)
    return state, rows


def test_budget_is_never_exceeded_and_shown(tmp_path):
    """Every row within its budget; reason 7 exactly on the rows that missed the test, with
    a residual ratio above 1; stats.csv, the energy report and summary.json show them."""
    out = tmp_path / "out"
    scene = falling_bar(tmp_path, max_iterations=3, on_budget="accept", steps=6)
    assert main(["run", "-q", scene.source, "-o", str(out)]) == 0
    rows = read_stats(out / "stats.csv")
    assert len(rows) == 6 and all(r["retries"] == 0 for r in rows)
    assert all(r["newton_its"] <= 3 for r in rows)
    budget = [int(r["step"]) for r in rows if r["snes_reason"] == BUDGET_REASON]
    # the unbudgeted run needs 3 iterations per step, 4 at step 5 (measured)
    assert 0 < len(budget) < len(rows), "the case no longer mixes both kinds of steps"
    for r in rows:
        if r["snes_reason"] == BUDGET_REASON:
            assert r["newton_its"] == 3 and r["residual_ratio"] > 1.0
        else:
            assert r["snes_reason"] in CONVERGED_REASONS and r["residual_ratio"] <= 1.0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["energy"]["budget_steps"] == budget
    assert summary["energy"]["unconverged_steps"] == []


def test_fail_fails_and_the_stepper_retries(tmp_path):
    scene = falling_bar(tmp_path, max_iterations=1, adaptive=False, steps=1)
    with pytest.raises(ConvergenceError, match="DIVERGED_MAX_IT"):
        run_rows(Simulation(scene, MPI.COMM_WORLD), steps=1)
    scene = falling_bar(tmp_path, name="retried", max_iterations=2, steps=1)
    _, rows = run_rows(Simulation(scene, MPI.COMM_WORLD), steps=1)
    assert sum(r["retries"] for r in rows) >= 1 and all(r["newton_its"] <= 2 for r in rows)
    assert all(r["snes_reason"] in CONVERGED_REASONS for r in rows)


def test_a_budget_that_suffices_changes_nothing(tmp_path):
    """The stopping test ends a step before its budget: same iterations, same trajectory."""
    free, free_rows = run_rows(Simulation(falling_bar(tmp_path, name="free"), MPI.COMM_WORLD))
    needed = max(r["newton_its"] for r in free_rows)
    assert needed >= 3
    scene = falling_bar(tmp_path, name="budgeted", max_iterations=needed + 5,
                        on_budget="accept")
    budgeted, rows = run_rows(Simulation(scene, MPI.COMM_WORLD))
    assert [r["newton_its"] for r in rows] == [r["newton_its"] for r in free_rows]
    assert [r["snes_reason"] for r in rows] == [r["snes_reason"] for r in free_rows]
    assert np.array_equal(budgeted.u, free.u)


@pytest.mark.mpi
def test_budgeted_run_under_mpi_equals_serial(tmp_path):
    from test_mpi_runs import assert_same_run, run
    if mpirun_command(2) is None:
        pytest.skip("mpirun not available")
    scene = falling_bar(tmp_path, max_iterations=1, on_budget="accept")
    for n in (1, 2):
        r = run(["run", "-q", scene.source, "-o", str(tmp_path / f"n{n}")], tmp_path, n)
        assert r.returncode == 0, r.stderr
    assert_same_run(tmp_path / "n1", tmp_path / "n2")
    a, b = (read_stats(tmp_path / f"n{n}" / "stats.csv") for n in (1, 2))
    assert [r["newton_its"] for r in a] == [r["newton_its"] for r in b] == [1] * 4
    assert all(r["snes_reason"] == BUDGET_REASON for r in a + b)


@pytest.mark.parametrize("solver, message", [
    ({"max_iterations": 0}, "solver.max_iterations"),
    ({"max_iterations": 2.5}, "solver.max_iterations"),
    ({"on_budget": "maybe"}, "solver.on_budget"),
    ({"on_budget": "accept"}, "set solver.max_iterations"),
])
def test_bad_budget_keys_exit_2(tmp_path, capsys, solver, message):
    path = tmp_path / "bad.toml"
    scene = scenes.bar("bad", solver=solver)
    path.write_text(scenes.scene_toml(scene))
    code = main(["run", "-q", str(path), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("fem-anim: error: ") and message in err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_budget_covers_auto_restarts(tmp_path, monkeypatch):
    """hessian = "auto" with CG meets the crushed cube's indefinite Hessian (test_solver_menu)
    by truncated CG directions and, should one fail, by continuing the solve filtered (a
    restart): the budget counts the iterations of every SNES solve of the step. Restarts
    are forced here (truncation off) so that the path is taken."""
    from test_solver_menu import squash

    from fem_anim.solver.hessian_choice import HessianChoice

    solver = 'preset = "cg-icc"\nmax_iterations = 3\non_budget = "accept"'
    for truncate in (True, False):
        if not truncate:
            monkeypatch.setattr(HessianChoice, "_truncate_cg",
                                lambda self: setattr(self, "_truncated", False))
        (tmp_path / str(truncate)).mkdir()
        sim = squash(tmp_path / str(truncate), hessian="auto", solver=solver)
        state, indefinite = sim.initial_state(), 0
        for _ in range(4):
            state, stats = sim.step(state, 0.05)
            choice = sim.minimiser.hessian
            indefinite += choice.restarts if not truncate else choice.truncated
            assert stats.newton_its == 3 and stats.reason == BUDGET_REASON
        assert indefinite >= 1  # the indefinite Hessian was met (truncated, or restarted)


def test_accept_keeps_only_an_iterate_that_lowered_g(tmp_path):
    """on_budget = "accept" keeps x only when g(x) < g(x_0): one clear error otherwise."""
    sim = Simulation(falling_bar(tmp_path, max_iterations=1, on_budget="accept"),
                     MPI.COMM_WORLD)
    x = sim.problem.x_work
    sim.problem.load_guess(sim.initial_state().u, x)
    g = sim.minimiser.objective(sim.minimiser.snes, x)
    assert accept_at_budget(sim.minimiser, x, g + 1.0, 0.0, "step 1") == BUDGET_REASON
    with pytest.raises(ConvergenceError, match="did not improve on its initial guess"):
        accept_at_budget(sim.minimiser, x, g - 1.0, 0.0, "step 1")
