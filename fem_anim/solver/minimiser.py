"""The step minimiser: a PETSc SNES given the objective, gradient and Hessian (seed 3.2).

Newton's method (seed eq. 10) with a backtracking line search on the true objective
(``snes.setObjective``, STYLE rule 7) by default; every choice is a PETSc option under
the solver's prefix (default ``fem_anim_``), merged with the precedence of
:mod:`fem_anim.petsc_options` and read once by ``setFromOptions``. The scene's
``[solver]`` adds what PETSc options cannot say:

* ``method``: :data:`NONLINEAR_METHODS`, each a layer of PETSc options (Newton with
  backtracking, trust region, L-BFGS, nonlinear CG, gradient descent);
* ``stopping``: PETSc's residual-norm tests, or the Newton decrement
  lambda^2/2 = grad g^T H^-1 grad g / 2 <= ``decrement_tol`` (seed definition 4; affine
  invariant, in the units of g), computed exactly from the Newton direction in the line
  search pre-check;
* ``hessian``: exact, shifted, filtered per quadrature point (clamp, abs), the filter chosen
  per iteration by the trust-region ratio, or ``auto``: exact while the Hessian is positive
  definite, abs-filtered when it is not (:mod:`fem_anim.solver.hessian_modification`); each step's iterations are
  counted per kind of Hessian (:attr:`SolveStats.hessian_its`);
* ``max_iterations`` and ``on_budget``: a budget of Newton iterations per step (every
  direction computed: one whose line search or linear solve failed, and the polish's full
  steps, included; at most the preset's ``snes_max_it``, which it replaces).
  ``"fail"``: a step that does not meet its test within it fails (DIVERGED_MAX_IT, and the
  adaptive stepper retries with dt halved); ``"accept"``: the last iterate is kept if it
  decreased the step objective below g at the initial guess, reported with
  :data:`BUDGET_REASON` (accepted, *not* converged) and the ratio of its residual norm to
  the requested test (:attr:`SolveStats.residual_ratio`). ``max_iterations = 1`` is one
  Newton step with line search from the predictor: the linearly implicit step of
  Baraff and Witkin (seed eq. 10 with one iteration). The stopping test still ends a step
  before its budget when met;
* ``inversion_filter``: the pre-check halves the Newton step until no element has
  det F <= 0, and the objective is +inf there (:meth:`EnergyProblem.objective`), so no
  iterate with an inverted element is ever accepted;
* obstacles (``[[obstacle]]``): the pre-check scales the Newton direction so that no
  line-search trial brings a contact point onto an obstacle
  (:meth:`fem_anim.contact.obstacles.ObstacleContact.step_bound`);
* contact between surfaces (``[contact]``): likewise by ipctk's continuous collision
  detection (:meth:`fem_anim.contact.ipc.IPCContact.step_bound`), so no trial crosses.

A saddle point (``problem.saddle_point``: ``element.formulation = "mixed"``,
:mod:`fem_anim.problem.mixed_space`) is not a minimum of g, so g cannot judge a step: SNES gets no
objective, and the line search (``bt``) backtracks on the merit function ||r||^2/2, whose
Newton direction is always a descent direction (d/dalpha ||r(x - alpha y)||^2/2 = -||r||^2 at
alpha = 0). Stopping is by the residual norms only (the round-off test on g becomes one on
||r||, :data:`SADDLE_FLOOR`), and the reported Newton decrement is NaN: r^T H^-1 r of an
indefinite H is no bound on anything (``solver.stopping = "decrement"`` is refused for
it). The inversion filter works as for a minimisation (it looks at the step, not at g).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from petsc4py import PETSc

from fem_anim.errors import ConvergenceError, FemAnimError
from fem_anim.solver.hessian_reuse import HessianReuse
from fem_anim.solver.hessian_choice import FAILED_DIRECTION, HESSIAN_KINDS, HessianChoice
from fem_anim.petsc_options import DEFAULT_PREFIX, options_in_database, unused_options
from fem_anim.problem.objective import EVENTS

__all__ = ["Minimiser", "SolveStats", "ROUNDOFF_REASON", "POLISH_FAILED_REASON",
           "BUDGET_REASON", "CONVERGED_REASONS", "NONLINEAR_METHODS", "HESSIAN_KINDS"]

#: Scene ``solver.method`` -> PETSc options (lowest layer above the library defaults).
NONLINEAR_METHODS: dict[str, dict[str, str]] = {
    "newton": {"snes_type": "newtonls", "snes_linesearch_type": "bt"},
    "trust_region": {"snes_type": "newtontr"},
    "lbfgs": {"snes_type": "qn", "snes_qn_type": "lbfgs", "snes_linesearch_type": "bt",
              "snes_max_it": "2000"},
    "ncg": {"snes_type": "ncg", "snes_ncg_type": "prp", "snes_linesearch_type": "cp",
            "snes_max_it": "5000"},
    "gradient_descent": {"snes_type": "nrichardson", "snes_linesearch_type": "bt",
                         "snes_max_it": "20000"},
}
MAX_FILTER_HALVINGS = 40

#: Reason the convergence test gives when Newton stopped at the round-off floor of the
#: objective: PETSc's CONVERGED_SNORM_RELATIVE, which PETSc itself never reports here
#: (``snes_stol`` is 0). :meth:`Minimiser._polish` then decides the reason reported.
ROUNDOFF_REASON = 4
ROUNDOFF_ULPS = 4096.0
#: Reason recorded when the Newton-decrement test stopped the iteration: PETSc's
#: CONVERGED_ITS ("converged by a user test"; a plain iteration cap is DIVERGED_MAX_IT).
DECREMENT_REASON = 5
#: A saddle point's Newton is at its round-off floor when an iteration no longer halves
#: ||r|| although ||r|| is already this far below its first value (quadratic convergence
#: would go on): it stops with ROUNDOFF_REASON and :meth:`Minimiser._polish` finishes.
SADDLE_FLOOR = 1e-6
#: Reason recorded when Newton stopped at the round-off floor of g and the polish's full
#: Newton steps did not reach the requested test either (no PETSc reason is 6): the step is
#: kept, as converged as double precision allows, but it is *not* converged to the test,
#: and stats.csv, the energy report and summary.json say so.
POLISH_FAILED_REASON = 6
#: Reason recorded when ``solver.on_budget = "accept"`` kept the iterate reached after
#: ``solver.max_iterations`` Newton iterations because it decreased the step objective
#: (no PETSc reason is 7): accepted, *not* converged to the test; stats.csv, the energy
#: report and summary.json say so, and ``residual_ratio`` says by how much.
BUDGET_REASON = 7
#: Reasons of a step that met its stopping test.
CONVERGED_REASONS = (2, 3, DECREMENT_REASON)


@dataclass
class SolveStats:
    """What one minimisation cost and how it ended.

    ``newton_decrement`` is lambda^2/2 at the last Newton direction (NaN for methods
    without one); ``initial_residual_norm`` the residual norm r0 at the initial guess (the
    relative test is ``residual_norm <= snes_rtol r0``); ``shift`` the last Hessian shift c;
    times are wall seconds. ``reason`` is :data:`POLISH_FAILED_REASON` for a step kept at
    the round-off floor without meeting its test.
    ``newton_its`` counts every Newton iteration: every direction computed, those whose
    line search or linear solve failed (which PETSc leaves out) and the round-off polish's
    full steps included; ``hessian_its`` the same iterations per kind of Hessian
    (:data:`HESSIAN_KINDS`; they sum to ``newton_its`` when the Hessian is assembled at
    every iteration); ``linear_its`` every linear iteration of the step's solves (SNES's,
    the descent-direction replacements', the round-off check's and the polish's).
    ``residual_ratio`` is ``residual_norm / max(snes_atol, snes_rtol r0)``: <= 1 where
    the norm test is met, its excess for a step accepted at its budget
    (:data:`BUDGET_REASON`). ``hessian_assemblies`` counts the Hessians assembled
    (fewer than the iterations when ``solver.hessian_update`` keeps one), and
    ``factorisations`` the preconditioner set-ups (PETSc's PCSetUp events: a direct
    solver's factorisations).
    """

    newton_its: int
    linear_its: int
    reason: int
    residual_norm: float
    wall_s: float
    newton_decrement: float = float("nan")
    shift: float = 0.0
    assembly_s: float = 0.0
    factor_s: float = 0.0
    linear_solve_s: float = 0.0
    initial_residual_norm: float = float("nan")
    hessian_its: dict = field(default_factory=dict)
    residual_ratio: float = float("nan")
    hessian_assemblies: int = 0
    factorisations: int = 0


class Minimiser:
    """A SNES wired to an :class:`~fem_anim.problem.objective.EnergyProblem`.

    Args:
        problem: Provides ``objective``, ``residual``, ``jacobian``, ``create_matrix``
            and ``create_vector``.
        options: Merged PETSc options (names without prefix).
        prefix: Options prefix, ending in ``_``.
    """

    def __init__(self, problem, options: dict[str, str], prefix: str = DEFAULT_PREFIX,
                 settings: dict | None = None):
        settings = settings or {}
        self.problem = problem
        self.prefix = prefix
        self.stopping = settings.get("stopping", "norm")
        self.decrement_tol = settings.get("decrement_tol", 0.0)
        self.budget = settings.get("max_iterations")  # None: the preset's snes_max_it
        self.on_budget = settings.get("on_budget", "fail")
        self._polish_its = 0  # full Newton steps of the last polish
        self._own_linear_its = 0  # linear iterations of newton_step's solves, this step
        self._polish_assemblies = 0  # ... that assembled a Hessian
        self._restarting = False  # auto continues a failed solve (HessianChoice.restart)
        # -mat_type (aij, baij) picks the Hessian's storage; PETSc never reads it for a
        # matrix the application creates, so it is taken here
        mat_type = options.get("mat_type") or None
        if mat_type not in (None, "aij", "baij"):
            raise FemAnimError(f"mat_type: the Hessian is stored as aij or baij, not {mat_type!r}")
        self.A = problem.create_matrix(mat_type)
        self.b = problem.create_vector()
        snes = self.snes = PETSc.SNES().create(problem.comm)
        snes.setOptionsPrefix(prefix)
        self._g_cache: list[tuple[PETSc.Vec, float]] = []
        self._g_seed: tuple[PETSc.Vec, float] | None = None  # seed_objective, next solve
        self.saddle = getattr(problem, "saddle_point", False)
        if not self.saddle:
            snes.setObjective(self.objective)
        snes.setFunction(problem.residual, self.b)
        self.hessian = HessianChoice(settings.get("hessian", "exact"), problem, snes,
                                     self.objective, self.b)
        self.reuse = HessianReuse(settings.get("hessian_update", "every_iteration"),
                                  settings.get("hessian_lag", 2), problem, self.hessian.jacobian)
        snes.setJacobian(self.reuse.jacobian, self.A)
        snes.setConvergenceTest(self._converged)
        self._history: list[tuple[float, float]] = []
        self._decrements: list[float] = []
        PETSc.Log.begin()
        self._events = [PETSc.Log.Event(name) for name in ("PCSetUp", "KSPSolve")]
        self.options = dict(options)
        self._unchecked: set[str] = set()  # options that must be read by the first solve
        PETSc.Sys.pushErrorHandler("ignore")
        try:
            with options_in_database(prefix, options):
                snes.setFromOptions()
                snes.getKSP().setFromOptions()
                snes.getKSP().getPC().setFromOptions()
                self._read = set(options) - set(unused_options(prefix, options))
        except PETSc.Error as err:
            shown = " ".join(f"-{k} {v}".strip() for k, v in sorted(options.items()))
            raise FemAnimError(f"PETSc rejected the solver options (error {err.ierr}): "
                               f"{shown}") from None
        finally:
            PETSc.Sys.popErrorHandler()
        if self.budget is not None:
            snes.setTolerances(max_it=self.budget)
        if snes.getType() in ("newtonls",):
            snes.setLineSearchPreCheck(self._precheck)
        # a fieldsplit PC learns its fields from the problem, and reads its sub-solvers'
        # options when it is set up (the first solve): they are in the database then
        pc = snes.getKSP().getPC()
        if pc.getType() == "fieldsplit" and hasattr(problem, "configure_preconditioner"):
            problem.configure_preconditioner(pc)
        if self.hessian.mode == "auto":
            self.hessian.enable_inertia(self.A)

    @property
    def shift(self):
        """The Hessian shift's state (``solver.hessian = "shift"``), else None."""
        return self.hessian.shift

    def require_read(self, names) -> None:
        """Make the first :meth:`solve` fail if one of the options ``names`` (the command
        line's) was read by no PETSc object by then: a misspelt ``-ksp_tpye`` is an
        error, as an unknown scene key is. Sub-solvers read theirs only when the first
        solve sets them up, hence after it."""
        self._unchecked = set(names) - self._read

    def _check_read(self) -> None:
        if not self._unchecked:
            return
        unused = sorted(unused_options(self.prefix, self._unchecked))
        self._unchecked = set()
        if unused:
            shown = ", ".join(f"-{name}" for name in unused)
            raise FemAnimError(f"PETSc option {shown} was read by no solver object (misspelt, "
                               "or for a component this solver does not have): see "
                               "`fem-anim solvers` and PETSc's manual for the names")

    def seed_objective(self, x: PETSc.Vec, value: float) -> None:
        """g(x) just evaluated by the caller for the next :meth:`solve`'s start: remembered
        like SNES's own evaluations (:meth:`objective`), so it is not assembled again."""
        if self._g_seed is not None:  # an earlier seed no solve took
            self._g_seed[0].destroy()
        self._g_seed = (x.copy(), value)

    def solve(self, x: PETSc.Vec, what: str = "step") -> SolveStats:
        """Minimise from the initial guess ``x`` (overwritten with the minimiser).

        Raises:
            ConvergenceError: naming ``what``, the iteration count and the SNES/KSP reasons.
        """
        start = time.perf_counter()
        self._decrements = []
        assembly0 = self.problem.assembly_s
        factor0, solve0 = (e.getPerfInfo()["time"] for e in self._events)
        factorisations0 = self._events[0].getPerfInfo()["count"]
        self._clear_objective_cache()
        if self._g_seed is not None:  # a point other than x is simply never matched
            self._g_cache.append(self._g_seed)
            self._g_seed = None
        self.hessian.start_step()
        self.reuse.start_step()
        self._polish_its = self._polish_assemblies = self._own_linear_its = 0
        self._restarting = False
        g0 = self.objective(self.snes, x)
        newton_its = linear_its = 0
        while True:
            if self.budget is not None:  # an auto restart gets what is left of the budget
                self.snes.setTolerances(max_it=self.budget - newton_its)
            self._snes_solve(x, what)
            reason = self.snes.getConvergedReason()
            # a direction computed and dropped is an iteration too (PETSc leaves it out)
            newton_its += self.snes.getIterationNumber() + (reason in FAILED_DIRECTION)
            linear_its += self.snes.getLinearSolveIterations() + self.hessian.solved()
            stalled = reason == PETSc.SNES.ConvergedReason.DIVERGED_LINE_SEARCH and \
                not self.saddle and self._at_objective_roundoff(x, g0)
            spent = self.budget is not None and newton_its >= self.budget
            if not spent and not stalled and self.reuse.retry(reason, x):
                self._restarting = True  # a kept Hessian failed: on from x_k with a fresh one
                continue
            if not spent and self.hessian.restart(reason, stalled, x):
                # the exact Hessian was indefinite where no inertia showed it: continue from
                # the last iterate filtered (trust-region choice; the same stopping test)
                self._restarting = True
                continue
            break
        self.hessian.end_step()
        norm = self.snes.getFunctionNorm()
        if reason == ROUNDOFF_REASON or stalled:
            steps = 5 if self.budget is None else min(5, self.budget - newton_its)
            if self.reuse.mode == "rest":  # first with the kept factorisation
                reason, norm = self._polish(x, max_steps=steps, assemble=False)
                kept_its = self._polish_its
                if reason == POLISH_FAILED_REASON and steps - kept_its > 0:
                    reason, norm = self._polish(x, max_steps=steps - kept_its)  # exact
                    self._polish_its += kept_its
            else:
                reason, norm = self._polish(x, max_steps=steps)
            newton_its += self._polish_its  # the polish's full Newton steps are iterations
            self.hessian.count_polish(self._polish_its)
        elif reason == PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT and \
                self.budget is not None and self.on_budget == "accept":
            reason = self._accept_at_budget(x, g0, norm, what)
        linear_its += self._own_linear_its  # the round-off check's and the polish's solves
        wall = time.perf_counter() - start
        factor1, solve1 = (e.getPerfInfo()["time"] for e in self._events)
        stats = SolveStats(
            newton_its, linear_its, reason, norm,
            wall, newton_decrement=self._decrements[-1] if self._decrements else float("nan"),
            shift=self.shift.c if self.shift else 0.0,
            assembly_s=self.problem.assembly_s - assembly0, factor_s=factor1 - factor0,
            linear_solve_s=solve1 - solve0,
            initial_residual_norm=self._history[0][0] if self._history else float("nan"),
            hessian_its=self.hessian.counts(), residual_ratio=norm / self._target(),
            hessian_assemblies=self.reuse.assemblies + self._polish_assemblies,
            factorisations=self._events[0].getPerfInfo()["count"] - factorisations0)
        if reason <= 0:
            ksp_reason = self.snes.getKSP().getConvergedReason()
            raise ConvergenceError(
                f"{what}: the minimisation did not converge after {stats.newton_its} Newton "
                f"iterations (SNES reason {_reason_name(PETSc.SNES.ConvergedReason, reason)}, "
                f"KSP reason {_reason_name(PETSc.KSP.ConvergedReason, ksp_reason)}, "
                f"residual norm {stats.residual_norm:.3e})")
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return stats

    def _target(self) -> float:
        """The residual norm the norm test asks for: max(snes_atol, snes_rtol r0)."""
        rtol, atol, _, _ = self.snes.getTolerances()
        return max(atol, rtol * self._history[0][0]) if self._history else atol

    def _accept_at_budget(self, x: PETSc.Vec, g0: float, norm: float, what: str) -> int:
        """``on_budget = "accept"``: keep x, the iterate after the budget, if it improved.

        A minimisation keeps x when g(x) < g(x_0) (the initial guess), a saddle point
        when ||r(x)|| < ||r(x_0)||: the step is then :data:`BUDGET_REASON`.

        Raises:
            ConvergenceError: if it did not improve (the step fails as without a budget).
        """
        if self.saddle:
            r0 = self._history[0][0] if self._history else np.inf
            better, shown = norm < r0, f"residual norm {norm:.6e}, initially {r0:.6e}"
        else:
            g = self.objective(self.snes, x)
            better, shown = g < g0, f"g = {g:.10e}, at the initial guess {g0:.10e}"
        if not better:
            raise ConvergenceError(
                f"{what}: after its budget of {self.budget} Newton iterations "
                f"(solver.max_iterations) the step did not improve on its initial guess "
                f"({shown}), so it cannot be accepted")
        self.problem.set_state(x)
        return BUDGET_REASON

    def _snes_solve(self, x: PETSc.Vec, what: str) -> None:
        PETSc.Sys.pushErrorHandler("ignore")  # reported once, below, not as PETSc's stack
        try:  # the options again: monitors, reasons and views are read by the solve itself
            with options_in_database(self.prefix, self.options):
                self.snes.solve(None, x)
                self._check_read()
        except PETSc.Error as err:
            raise FemAnimError(f"{what}: PETSc failed inside the solver (error {err.ierr}); "
                               "check the solver options (e.g. a serial-only preconditioner "
                               "on several processes)") from None
        finally:
            PETSc.Sys.popErrorHandler()

    def objective(self, snes, x: PETSc.Vec) -> float:
        """g(x), remembered for the last two points of this solve.

        SNES asks for g at the same iterate several times: the convergence test, the start
        of the line search, the accepted trial point (copied into the solution vector), and
        :meth:`solve` itself. A point equal entry by entry (``VecEqual``, collective) to one
        of the last two evaluated reuses its value: 3 assemblies of g per Newton iteration
        become 1 plus the rejected trials. Every other callback sets the state it needs.
        """
        for vec, value in self._g_cache:
            if vec.getSize() == x.getSize() and vec.equal(x):
                return value
        value = self.problem.objective(snes, x)
        if len(self._g_cache) < 2:
            self._g_cache.append((x.copy(), value))
        else:
            oldest, _ = self._g_cache.pop(0)
            x.copy(oldest)
            self._g_cache.append((oldest, value))
        return value

    def _clear_objective_cache(self) -> None:
        for vec, _ in self._g_cache:
            vec.destroy()
        self._g_cache = []

    def _converged(self, snes, it: int, norms: tuple[float, float, float]) -> int:
        """PETSc's norm tests (atol, rtol, max_it) plus a stop at the round-off floor.

        An iteration that neither reduces the residual norm by half nor changes the
        objective by more than its floating-point resolution has nothing left to gain:
        it stops with :data:`ROUNDOFF_REASON` instead of stagnating to ``snes_max_it``.
        """
        _, _, fnorm = norms
        rtol, atol, _, max_it = snes.getTolerances()
        g = np.nan if self.saddle else self.objective(snes, snes.getSolution())
        if it == 0 and not self._restarting:
            self._history = []  # an auto restart keeps the step's first norm (snes_rtol)
        if it == 0 and self._restarting:
            self._restarting = False
            self._history.append((fnorm, g))
            return PETSc.SNES.ConvergedReason.ITERATING
        self._history.append((fnorm, g))
        if it > 0:
            self.reuse.check_step(snes.getSolution())
        R = PETSc.SNES.ConvergedReason
        if not np.isfinite(fnorm):
            return R.DIVERGED_FNORM_NAN
        if self.stopping == "decrement":
            # lambda^2/2 of the previous Newton direction (the step from it is taken)
            if it > 0 and self._decrements and self._decrements[-1] <= self.decrement_tol:
                return DECREMENT_REASON
        elif fnorm <= atol:
            return R.CONVERGED_FNORM_ABS
        elif fnorm <= rtol * self._history[0][0]:
            return R.CONVERGED_FNORM_RELATIVE
        if it > 0 and not self.saddle:
            f_prev, g_prev = self._history[-2]
            if fnorm > 0.5 * f_prev and abs(g_prev - g) <= _resolution(g, g_prev):
                return ROUNDOFF_REASON
        elif it > 0:  # a saddle point: judged by ||r|| alone (no g to see round-off in)
            f_prev = self._history[-2][0]
            if fnorm > 0.5 * f_prev and fnorm <= SADDLE_FLOOR * self._history[0][0]:
                return ROUNDOFF_REASON
        if it >= max_it:
            return R.DIVERGED_MAX_IT
        return R.ITERATING

    def _precheck(self, x: PETSc.Vec, y: PETSc.Vec) -> bool:
        """Before the line search: record lambda^2/2 and filter inverting steps.

        ``y`` is the full Newton direction (the line search tries x - alpha y) and the
        residual r at x is in ``self.b``: lambda^2 = r . y (seed definition 4). With the
        inversion filter on, y is halved until x - y has det F > 0 everywhere.
        """
        replaced = self.hessian.descent_direction(x, y, self.b)  # auto with CG
        self._decrements.append(np.nan if self.saddle else 0.5 * abs(self.b.dot(y)))
        scaled = self._contact_bound(x, y) or replaced
        if self.problem.filter_inversion:
            scaled = self._filter_inverting(x, y) or scaled
        self.hessian.record_model(x, y)
        self.reuse.record_direction(x, y)
        return scaled

    def _filter_inverting(self, x: PETSc.Vec, y: PETSc.Vec) -> bool:
        """Halve y until x - y has det F > 0 everywhere; whether it was changed."""
        trial = x.duplicate()
        EVENTS["filter"].begin()
        try:
            for halvings in range(MAX_FILTER_HALVINGS):
                x.copy(trial)
                trial.axpy(-1.0, y)
                self.problem.set_state(trial)
                if self.problem.min_det_F() > 0.0:
                    return halvings > 0
                y.scale(0.5)
            return True
        finally:
            trial.destroy()
            self.problem.set_state(x)
            EVENTS["filter"].end()

    def _contact_bound(self, x: PETSc.Vec, y: PETSc.Vec) -> bool:
        """Scale y so that no contact point of x - alpha y, 0 < alpha <= 1, nears an obstacle
        by more than :data:`fem_anim.contact.obstacles.KEEP_FRACTION` of its distance; whether it did."""
        return _bound_step(self.problem, x, y) < 1.0

    def _at_objective_roundoff(self, x: PETSc.Vec, g0: float) -> bool:
        """Whether Newton cannot decrease g any further in floating point.

        The predicted decrease of a Newton step is lambda^2/2 = r^T H^-1 r / 2 (seed
        definition 4). When it is below the resolution of g (a few thousand ulps of
        max(|g(x)|, |g(x_0)|)) the backtracking line search must fail, and x is as
        converged as double precision allows. Uses the factorisation of the last Jacobian.
        """
        g = self.objective(self.snes, x)
        self.hessian.leave_trust_region()  # the full Newton step's decrement
        r, step = self.b.duplicate(), self.b.duplicate()
        self.problem.residual(self.snes, x, r)
        decrement = self.newton_step(x, r, step, assemble_hessian=False)
        r.destroy()
        step.destroy()
        return decrement <= _resolution(g, g0)

    def newton_step(self, x: PETSc.Vec, r: PETSc.Vec, step: PETSc.Vec,
                    assemble_hessian: bool = True) -> float:
        """The full Newton step H(x)^-1 r into ``step``, for the residual ``r`` at x.

        ``assemble_hessian=False`` reuses the last Hessian and its factorisation; with
        ``hessian_update = "rest"`` an assembled one goes to a solver of its own
        (:meth:`fem_anim.solver.hessian_reuse.HessianReuse.exact_solver`).

        Returns:
            The Newton decrement lambda^2/2 = r . step / 2 (seed definition 4).
        """
        ksp, A, apart = self.snes.getKSP(), self.A, None
        if assemble_hessian:
            apart = self.reuse.exact_solver(self.snes, self.options.get("mat_type") or None,
                                            self.options, self.prefix)
            if apart is None:
                self.reuse.invalidate()  # the kept Hessian is overwritten
            else:
                ksp, A = apart
            self.problem.jacobian(self.snes, x, A, A)
            ksp.setOperators(A, A)
        if apart is None:
            ksp.solve(r, step)
        else:
            with options_in_database(self.prefix, self.options):  # MUMPS reads its own here
                ksp.solve(r, step)
        self._own_linear_its += ksp.getIterationNumber()
        return 0.5 * abs(r.dot(step))

    def _polish(self, x: PETSc.Vec, max_steps: int = 5,
                assemble: bool = True) -> tuple[int, float]:
        """Full Newton steps judged by the residual, where g can no longer judge them.

        Below the objective's round-off the line search cannot tell a good step from a bad
        one, but the residual still can: take full steps while each at least halves the
        residual norm, then apply the chosen test (norms: ``snes_atol``, ``snes_rtol``;
        or the decrement of the next Newton direction). ``assemble=False`` solves with the
        kept Hessian and its factorisation instead (``hessian_update = "rest"``, whose
        constant factorisation would otherwise be lost). If it is still not met, x is kept
        (it is as converged as double precision allows) but the step is reported as not
        converged to its test: :data:`POLISH_FAILED_REASON`.

        Returns:
            The SNES reason to report and the final residual norm.
        """
        _, atol, _, _ = self.snes.getTolerances()
        target = self._target()
        R = PETSc.SNES.ConvergedReason
        self._polish_its = self._polish_assemblies = 0
        r, step, trial, r_trial = (self.b.duplicate() for _ in range(4))
        try:
            self.problem.residual(self.snes, x, r)
            norm = r.norm()
            for _ in range(max_steps):
                if norm <= target and self.stopping == "norm":
                    break
                decrement = self.newton_step(x, r, step, assemble_hessian=assemble)
                self._polish_its += 1
                self._polish_assemblies += assemble
                self._decrements.append(np.nan if self.saddle else decrement)
                if self.stopping == "decrement" and decrement <= self.decrement_tol:
                    return DECREMENT_REASON, norm
                if _step_limit(self.problem, x, step) < 1.0:
                    break  # a full step must keep clear of obstacles and other surfaces
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
            if norm <= target and self.stopping == "norm":
                return (R.CONVERGED_FNORM_ABS if norm <= atol else R.CONVERGED_FNORM_RELATIVE,
                        norm)
            return POLISH_FAILED_REASON, norm
        finally:
            for v in (r, step, trial, r_trial):
                v.destroy()

    def destroy(self) -> None:
        self._clear_objective_cache()
        if self._g_seed is not None:  # seeded, never solved
            self._g_seed[0].destroy()
        self.hessian.destroy()
        self.reuse.destroy()
        self.snes.destroy()
        self.A.destroy()
        self.b.destroy()


def _step_limit(problem, x: PETSc.Vec, y: PETSc.Vec) -> float:
    """Largest alpha <= 1 such that x - alpha y keeps clear of obstacles (a fraction of
    each contact point's distance, :mod:`fem_anim.contact.obstacles`) and has no surface crossing
    another or itself on the way (ipctk's CCD, :mod:`fem_anim.contact.ipc`)."""
    contact, ipc = getattr(problem, "contact", None), getattr(problem, "ipc", None)
    if contact is None and ipc is None:
        return 1.0
    problem.set_state(x)
    alpha = 1.0
    if contact is not None:
        alpha = contact.step_bound(y)
    if ipc is not None:
        alpha = min(alpha, ipc.step_bound(y.array))
    return alpha


def _bound_step(problem, x: PETSc.Vec, y: PETSc.Vec) -> float:
    """Scale y by :func:`_step_limit`; the factor."""
    alpha = _step_limit(problem, x, y)
    if alpha < 1.0:
        y.scale(alpha)
    return alpha


def _resolution(*values: float) -> float:
    """The smallest change of the objective distinguishable from round-off near ``values``."""
    return ROUNDOFF_ULPS * np.finfo(float).eps * max(abs(v) for v in values)


def _reason_name(enum, value: int) -> str:
    for name in dir(enum):
        if not name.startswith("_") and getattr(enum, name) == value:
            return f"{name} ({value})"
    return str(value)
