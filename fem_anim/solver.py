"""The step minimiser: a PETSc SNES given the objective, gradient and Hessian (seed 3.2).

Newton's method (seed eq. 10) with a backtracking line search on the true objective
(``snes.setObjective``, STYLE rule 7) by default; every choice is a PETSc option under
the solver's prefix (default ``fem_anim_``), merged with the precedence of
:mod:`fem_anim.petsc_options` and read once by ``setFromOptions``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from petsc4py import PETSc

from .errors import ConvergenceError, FemAnimError
from .petsc_options import DEFAULT_PREFIX, options_in_database

__all__ = ["Minimiser", "SolveStats", "ROUNDOFF_REASON"]

#: Reason recorded when Newton stopped at the round-off floor of the objective: PETSc's
#: CONVERGED_SNORM_RELATIVE, which PETSc itself never reports here (``snes_stol`` is 0).
ROUNDOFF_REASON = 4
ROUNDOFF_ULPS = 4096.0


@dataclass
class SolveStats:
    """What one minimisation cost and how it ended."""

    newton_its: int
    linear_its: int
    reason: int
    residual_norm: float
    wall_s: float


class Minimiser:
    """A SNES wired to an :class:`~fem_anim.problem.EnergyProblem`.

    Args:
        problem: Provides ``objective``, ``residual``, ``jacobian``, ``create_matrix``
            and ``create_vector``.
        options: Merged PETSc options (names without prefix).
        prefix: Options prefix, ending in ``_``.
    """

    def __init__(self, problem, options: dict[str, str], prefix: str = DEFAULT_PREFIX):
        self.problem = problem
        self.prefix = prefix
        self.A = problem.create_matrix()
        self.b = problem.create_vector()
        snes = self.snes = PETSc.SNES().create(problem.comm)
        snes.setOptionsPrefix(prefix)
        snes.setObjective(problem.objective)
        snes.setFunction(problem.residual, self.b)
        snes.setJacobian(problem.jacobian, self.A)
        snes.setConvergenceTest(self._converged)
        self._history: list[tuple[float, float]] = []
        PETSc.Sys.pushErrorHandler("ignore")
        try:
            with options_in_database(prefix, options):
                snes.setFromOptions()
                snes.getKSP().setFromOptions()
                snes.getKSP().getPC().setFromOptions()
        except PETSc.Error as err:
            shown = " ".join(f"-{k} {v}".strip() for k, v in sorted(options.items()))
            raise FemAnimError(f"PETSc rejected the solver options (error {err.ierr}): "
                               f"{shown}") from None
        finally:
            PETSc.Sys.popErrorHandler()

    def solve(self, x: PETSc.Vec, what: str = "step") -> SolveStats:
        """Minimise from the initial guess ``x`` (overwritten with the minimiser).

        Raises:
            ConvergenceError: naming ``what``, the iteration count and the SNES/KSP reasons.
        """
        start = time.perf_counter()
        g0 = self.problem.objective(self.snes, x)
        self.snes.solve(None, x)
        reason = self.snes.getConvergedReason()
        stalled = reason == PETSc.SNES.ConvergedReason.DIVERGED_LINE_SEARCH and \
            self._at_objective_roundoff(x, g0)
        norm = self.snes.getFunctionNorm()
        if reason == ROUNDOFF_REASON or stalled:
            reason, norm = self._polish(x)
        wall = time.perf_counter() - start
        stats = SolveStats(self.snes.getIterationNumber(), self.snes.getLinearSolveIterations(),
                           reason, norm, wall)
        if reason <= 0:
            ksp_reason = self.snes.getKSP().getConvergedReason()
            raise ConvergenceError(
                f"{what}: the minimisation did not converge after {stats.newton_its} Newton "
                f"iterations (SNES reason {_reason_name(PETSc.SNES.ConvergedReason, reason)}, "
                f"KSP reason {_reason_name(PETSc.KSP.ConvergedReason, ksp_reason)}, "
                f"residual norm {stats.residual_norm:.3e})")
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return stats

    def _converged(self, snes, it: int, norms: tuple[float, float, float]) -> int:
        """PETSc's norm tests (atol, rtol, max_it) plus a stop at the round-off floor.

        An iteration that neither reduces the residual norm by half nor changes the
        objective by more than its floating-point resolution has nothing left to gain:
        it stops with :data:`ROUNDOFF_REASON` instead of stagnating to ``snes_max_it``.
        """
        _, _, fnorm = norms
        rtol, atol, _, max_it = snes.getTolerances()
        g = self.problem.objective(snes, snes.getSolution())
        if it == 0:
            self._history = []
        self._history.append((fnorm, g))
        R = PETSc.SNES.ConvergedReason
        if not np.isfinite(fnorm):
            return R.DIVERGED_FNORM_NAN
        if fnorm <= atol:
            return R.CONVERGED_FNORM_ABS
        if fnorm <= rtol * self._history[0][0]:
            return R.CONVERGED_FNORM_RELATIVE
        if it > 0:
            f_prev, g_prev = self._history[-2]
            if fnorm > 0.5 * f_prev and abs(g_prev - g) <= _resolution(g, g_prev):
                return ROUNDOFF_REASON
        if it >= max_it:
            return R.DIVERGED_MAX_IT
        return R.ITERATING

    def _at_objective_roundoff(self, x: PETSc.Vec, g0: float) -> bool:
        """Whether Newton cannot decrease g any further in floating point.

        The predicted decrease of a Newton step is lambda^2/2 = r^T H^-1 r / 2 (seed
        definition 4). When it is below the resolution of g (a few thousand ulps of
        max(|g(x)|, |g(x_0)|)) the backtracking line search must fail, and x is as
        converged as double precision allows. Uses the factorisation of the last Jacobian.
        """
        g = self.problem.objective(self.snes, x)
        r = self.b.duplicate()
        self.problem.residual(self.snes, x, r)
        step = r.duplicate()
        self.snes.getKSP().solve(r, step)
        decrement = 0.5 * abs(r.dot(step))
        r.destroy()
        step.destroy()
        return decrement <= _resolution(g, g0)

    def _polish(self, x: PETSc.Vec, max_steps: int = 5) -> tuple[int, float]:
        """Full Newton steps judged by the residual, where g can no longer judge them.

        Below the objective's round-off the line search cannot tell a good step from a bad
        one, but the residual still can: take full steps while each at least halves the
        residual norm, then apply the norm tests (``snes_atol``, ``snes_rtol``). If they
        are still not met, x is as converged as double precision allows.

        Returns:
            The SNES reason to report and the final residual norm.
        """
        rtol, atol, _, _ = self.snes.getTolerances()
        target = max(atol, rtol * self._history[0][0]) if self._history else atol
        R = PETSc.SNES.ConvergedReason
        r, step, trial, r_trial = (self.b.duplicate() for _ in range(4))
        ksp = self.snes.getKSP()
        try:
            self.problem.residual(self.snes, x, r)
            norm = r.norm()
            for _ in range(max_steps):
                if norm <= target:
                    reason = R.CONVERGED_FNORM_ABS if norm <= atol else R.CONVERGED_FNORM_RELATIVE
                    return reason, norm
                self.problem.jacobian(self.snes, x, self.A, self.A)
                ksp.setOperators(self.A, self.A)
                ksp.solve(r, step)
                x.copy(trial)
                trial.axpy(-1.0, step)
                self.problem.residual(self.snes, trial, r_trial)
                trial_norm = r_trial.norm()
                if not trial_norm <= 0.5 * norm:
                    break
                trial.copy(x)
                r_trial.copy(r)
                norm = trial_norm
            self.problem.set_state(x)
            return ROUNDOFF_REASON, norm
        finally:
            for v in (r, step, trial, r_trial):
                v.destroy()

    def destroy(self) -> None:
        self.snes.destroy()
        self.A.destroy()
        self.b.destroy()


def _resolution(*values: float) -> float:
    """The smallest change of the objective distinguishable from round-off near ``values``."""
    return ROUNDOFF_ULPS * np.finfo(float).eps * max(abs(v) for v in values)


def _reason_name(enum, value: int) -> str:
    for name in dir(enum):
        if not name.startswith("_") and getattr(enum, name) == value:
            return f"{name} ({value})"
    return str(value)
