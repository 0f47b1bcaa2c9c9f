"""The step minimiser: a PETSc SNES given the objective, gradient and Hessian (seed 3.2).

Newton's method (seed eq. 10) with a backtracking line search on the true objective g
(``snes.setObjective``) by default; every choice is a PETSc option under the solver's
prefix (default ``fem_anim_``), merged with the precedence of :mod:`fem_anim.petsc_options`
and read once by ``setFromOptions``. The scene's ``[solver]`` adds what PETSc options
cannot say, each in a module of its own:

* ``method``: :data:`NONLINEAR_METHODS`, each a layer of PETSc options (Newton with
  backtracking, trust region, L-BFGS, nonlinear CG, gradient descent);
* ``stopping``, ``step_tol``, ``max_iterations``, ``on_budget``: when a step stops and what
  it reports (:mod:`fem_anim.solver.stopping`; ``"auto"``: IPC's step test with contact).
  The budget counts every direction computed, one whose line search or linear solve failed
  and the polish's full steps included, and replaces the preset's ``snes_max_it``;
  ``max_iterations = 1`` is one Newton step with line search from the predictor, the
  linearly implicit step of Baraff and Witkin;
* ``hessian``: which Hessian each Newton iteration uses
  (:mod:`fem_anim.solver.hessian_choice`), each step's iterations counted per kind;
* ``hessian_update``: how often it is rebuilt (:mod:`fem_anim.solver.hessian_reuse`);
* ``inversion_filter``, obstacles and surface contact: the Newton direction is shortened
  before its line search (:mod:`fem_anim.solver.step_bounds`).

A saddle point (``problem.saddle_point``: ``element.formulation = "mixed"``) is not a
minimum of g, so g cannot judge a step: SNES gets no objective, and the line search
(``bt``) backtracks on the merit function ||r||^2/2, whose Newton direction is always a
descent direction (d/dalpha ||r(x - alpha y)||^2/2 = -||r||^2 at alpha = 0). Stopping is by
the residual norms only, and the reported Newton decrement is NaN (r^T H^-1 r of an
indefinite H bounds nothing).

With IPC's step test (``stopping = "step"``) and ``[contact]``, the Hessian's barrier and
friction part is IPC's per-pair PSD projection until a full Newton step is below
:data:`EXACT_NEAR` times the test's size, then exact
(:meth:`fem_anim.contact.ipc.IPCContact.exact_hessian`): the projected Hessian differs from
the true one near a contact and converges linearly there (seed section 3.2.2: Newton's
quadratic convergence needs the true Hessian). If a direction from the exact Hessian fails
(no descent: its model is poor that far out), the step continues from its last iterate with
the projection and tries the exact Hessian again once the steps are :data:`EXACT_SHRINK`
times smaller, down to the test's size itself; a failure there keeps the projection for the
rest of the step (docs/contact.md, "Where a pile's Newton iterations and seconds go",
measures the factors). An exact direction that the CCD bound or the line search shortened
counts as such a failure too, its shortened step kept, until the exact Hessian is tried at
the test's size itself: Newton's local phase takes its steps whole, and a model that needs
them cut is not in it yet.

With contact, where PETSc's ``bt`` would cut a direction to a tenth (a barrier making g at
the full step enormous: a landing), the direction is first halved under Armijo's test
(:meth:`Minimiser._halve_clipped`, :data:`HALVINGS`).
"""

from __future__ import annotations

import time

import numpy as np
from petsc4py import PETSc

from fem_anim.errors import ConvergenceError, FemAnimError
from fem_anim.petsc_options import DEFAULT_PREFIX, options_in_database, unused_options
from fem_anim.solver.hessian_choice import FAILED_DIRECTION, HessianChoice
from fem_anim.solver.hessian_reuse import HessianReuse
from fem_anim.solver.solve_stats import SolveStats
from fem_anim.solver.step_bounds import bound_step, filter_inverting
from fem_anim.solver.stopping import (ROUNDOFF_REASON, StoppingTest, accept_at_budget,
                                      at_objective_roundoff, finish_at_roundoff, reason_name,
                                      resolve_stopping, scene_diagonal)

__all__ = ["EXACT_NEAR", "EXACT_SHRINK", "HALVE_CLIPPED", "HALVINGS", "Minimiser",
           "NONLINEAR_METHODS", "WHOLE_STEP_TOL"]

#: With IPC's step test: the barrier's exact Hessian once a full Newton step is below this
#: many times the test's size.
EXACT_NEAR = 100.0
#: ... and, after an exact direction failed, once the steps are this many times smaller.
EXACT_SHRINK = 10.0
#: A step counts as taken whole when it is at least 1 - this of the full Newton step.
WHOLE_STEP_TOL = 1e-6
#: With contact: backtrack by halving where PETSc's bt clips its fit (Minimiser._halve_clipped)
HALVE_CLIPPED = True
#: ... the steps tried, in order
HALVINGS = (0.5, 0.25, 0.125)

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


class Minimiser:
    """A SNES wired to an :class:`~fem_anim.problem.objective.EnergyProblem`.

    Args:
        problem: Provides ``objective``, ``residual``, ``jacobian``, ``create_matrix``
            and ``create_vector`` (and ``saddle_point``, ``filter_inversion``, ``contact``,
            ``ipc`` where they apply).
        options: Merged PETSc options (names without prefix).
        prefix: Options prefix, ending in ``_``.
        settings: The scene's ``[solver]`` keys this class reads: ``stopping``,
            ``step_tol``, ``decrement_tol``, ``max_iterations``, ``on_budget``, ``hessian``,
            ``hessian_update``, ``hessian_lag``.

    Raises:
        FemAnimError: for a ``mat_type`` other than aij or baij, options PETSc rejects, or
            ``stopping = "step"`` for a saddle point or another method than Newton.
    """

    def __init__(self, problem, options: dict[str, str], prefix: str = DEFAULT_PREFIX,
                 settings: dict | None = None):
        settings = settings or {}
        self.problem = problem
        self.prefix = prefix
        self.budget = settings.get("max_iterations")  # None: the preset's snes_max_it
        self.on_budget = settings.get("on_budget", "fail")
        self._own_linear_its = 0  # linear iterations of newton_step's solves, this step
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
        contact = getattr(problem, "ipc", None) is not None or \
            getattr(problem, "contact", None) is not None
        try:
            newton = settings.get("method", "newton") == "newton" and \
                getattr(problem, "constant_terms", None) is not None
            stopping = resolve_stopping(settings.get("stopping", "norm"), contact, self.saddle,
                                        newton)
        except ValueError as err:
            raise FemAnimError(str(err)) from None
        self.stop = StoppingTest(stopping, settings.get("decrement_tol", 0.0), self.saddle)
        #: ``"step"``: ||p||_inf <= step_tol x the bounding-box diagonal x h ends a step
        self.step_tol = float(settings.get("step_tol", 1e-3)) * scene_diagonal(
            problem.comm, problem.domain.mesh.geometry.x[:, :problem.domain.mesh.geometry.dim]
        ) if stopping == "step" else 0.0
        if stopping == "step":
            self.stop.forces = problem.force_scale
        #: ``"step"`` with IPC: the barrier's exact Hessian once a step is small (below)
        self._exact_near = stopping == "step" and getattr(problem, "ipc", None) is not None
        #: where the exact barrier Hessian first takes over, x the test's size
        self.exact_near_start = EXACT_NEAR
        self._exact_ok = False
        self._exact_on = False
        self._exact_full = None
        self._x_before = None  # the iterate a direction from the exact Hessian started at
        #: directions from the barrier's exact Hessian not taken whole (the run's count)
        self.exact_withdrawn = 0
        if not self.saddle:
            snes.setObjective(self.objective)
        snes.setFunction(problem.residual, self.b)
        self.hessian = HessianChoice(settings.get("hessian", "exact"), problem, snes,
                                     self.objective, self.b)
        self.reuse = HessianReuse(settings.get("hessian_update", "every_iteration"),
                                  settings.get("hessian_lag", 2), problem, self.hessian.jacobian)
        snes.setJacobian(self.reuse.jacobian, self.A)
        snes.setConvergenceTest(self._converged)
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
        #: ``bt`` with contact and an objective: halve where bt's fit is clipped
        #: (:meth:`_halve_clipped`); a caller may turn it off before the first solve
        self.halving = HALVE_CLIPPED and contact and not self.saddle and \
            snes.getType() == "newtonls" and \
            self.options.get("snes_linesearch_type", "bt") == "bt"
        self._armijo = float(self.options.get("snes_linesearch_alpha", 1e-4))
        self._trial = self._scaled = None
        #: directions :meth:`_halve_clipped` scaled (the run's count)
        self.halved = 0
        # a fieldsplit PC learns its fields from the problem, and reads its sub-solvers'
        # options when it is set up (the first solve): they are in the database then
        pc = snes.getKSP().getPC()
        if pc.getType() == "fieldsplit" and hasattr(problem, "configure_preconditioner"):
            problem.configure_preconditioner(pc)
        if self.hessian.mode in ("auto", "shift"):
            # the inertia controls must be in the database at every factorisation: a new
            # nonzero pattern (contact) makes PCSetUp replace the factor and its controls
            for name, value in self.hessian.enable_inertia(self.A).items():
                self.options.setdefault(name, value)

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

        A failed SNES solve may continue from its last iterate, with a fresh Hessian
        (:meth:`~fem_anim.solver.hessian_reuse.HessianReuse.retry`) or a filtered one
        (:meth:`~fem_anim.solver.hessian_choice.HessianChoice.restart`); a solve stopped at
        the round-off floor is polished (:func:`~fem_anim.solver.stopping.finish_at_roundoff`).

        Args:
            x: The initial guess.
            what: The step's name, for errors.

        Returns:
            What the solve cost and how it ended.

        Raises:
            ConvergenceError: naming ``what``, the iteration count and the SNES/KSP reasons.
        """
        start = time.perf_counter()
        assembly0 = self.problem.assembly_s
        factor0, solve0 = (e.getPerfInfo()["time"] for e in self._events)
        factorisations0 = self._events[0].getPerfInfo()["count"]
        self._clear_objective_cache()
        if self._g_seed is not None:  # a point other than x is simply never matched
            self._g_cache.append(self._g_seed)
            self._g_seed = None
        self.hessian.start_step()
        self.reuse.start_step()
        self.stop.start()
        self.stop.step_scale = self.step_tol * getattr(self.problem, "step_size", 0.0)
        self._exact_ok = self._exact_near
        self._near = self.exact_near_start  # x the test's size: the exact Hessian from here
        self._exact_on = False
        self._exact_full = None  # ||p||_inf of the last direction from the exact Hessian
        if self._exact_near:
            self.problem.ipc.exact_hessian(False)
        self._own_linear_its = 0
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
            if reason < 0 and self._exact_near and self._exact_ok and \
                    (self.budget is None or newton_its < self.budget):
                # the exact barrier Hessian gave no descent: on from x_k, projected
                if self._exact_on and self._near > 1.0:
                    self._near = max(1.0, self._near / EXACT_SHRINK)  # again, nearer
                else:
                    self._exact_ok = False
                self._exact_on = False
                self.problem.ipc.exact_hessian(False)
                self.stop.restarting = True
                continue
            stalled = reason == PETSc.SNES.ConvergedReason.DIVERGED_LINE_SEARCH and \
                not self.saddle and at_objective_roundoff(self, x, g0)
            spent = self.budget is not None and newton_its >= self.budget
            if not spent and not stalled and self.reuse.retry(reason, x):
                self.stop.restarting = True  # a kept Hessian failed: on from x_k with a fresh one
                continue
            if not spent and self.hessian.restart(reason, stalled, x):
                # the exact Hessian was indefinite where no inertia showed it: continue from
                # the last iterate filtered (trust-region choice; the same stopping test)
                self.stop.restarting = True
                continue
            break
        self.hessian.end_step()
        norm = self.snes.getFunctionNorm()
        if reason == ROUNDOFF_REASON or stalled:
            steps = 5 if self.budget is None else min(5, self.budget - newton_its)
            reason, norm = finish_at_roundoff(self, x, steps)
            newton_its += self.stop.polish_its  # the polish's full Newton steps are iterations
            self.hessian.count_polish(self.stop.polish_its)
        elif reason == PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT and \
                self.budget is not None and self.on_budget == "accept":
            reason = accept_at_budget(self, x, g0, norm, what)
        linear_its += self._own_linear_its  # the round-off check's and the polish's solves
        wall = time.perf_counter() - start
        factor1, solve1 = (e.getPerfInfo()["time"] for e in self._events)
        stats = SolveStats(
            newton_its, linear_its, reason, norm,
            wall, newton_decrement=self.stop.last_decrement,
            shift=self.shift.c if self.shift else 0.0,
            assembly_s=self.problem.assembly_s - assembly0, factor_s=factor1 - factor0,
            linear_solve_s=solve1 - solve0,
            initial_residual_norm=self.stop.initial_norm,
            hessian_its=self.hessian.counts(), residual_ratio=norm / self.stop.target(self.snes),
            hessian_assemblies=self.reuse.assemblies + self.stop.polish_assemblies,
            factorisations=self._events[0].getPerfInfo()["count"] - factorisations0,
            inertia_checks=self.hessian.inertia_checks,
            inertia_fallbacks=self.hessian.inertia_fallbacks)
        if reason <= 0:
            ksp_reason = self.snes.getKSP().getConvergedReason()
            raise ConvergenceError(
                f"{what}: the minimisation did not converge after {stats.newton_its} Newton "
                f"iterations (SNES reason {reason_name(PETSc.SNES.ConvergedReason, reason)}, "
                f"KSP reason {reason_name(PETSc.KSP.ConvergedReason, ksp_reason)}, "
                f"residual norm {stats.residual_norm:.3e})")
        x.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return stats

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
        """g(x), remembered for the last three points of this solve.

        SNES asks for g at the same iterate several times: the convergence test, the start
        of the line search, the accepted trial point (copied into the solution vector), and
        :meth:`solve` itself. A point equal entry by entry (``VecEqual``, collective) to one
        of the last three evaluated reuses its value (three: the iterate and the trial
        points of :meth:`_halve_clipped`): 3 assemblies of g per Newton iteration
        become 1 plus the rejected trials. Every other callback sets the state it needs.
        """
        for vec, value in self._g_cache:
            if vec.getSize() == x.getSize() and vec.equal(x):
                return value
        value = self.problem.objective(snes, x)
        if len(self._g_cache) < 3:
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
        """SNES's convergence test: :meth:`fem_anim.solver.stopping.StoppingTest.test` at
        the iterate, after telling the Hessian reuse where the line search ended."""
        g = np.nan if self.saddle else self.objective(snes, snes.getSolution())
        if it > 0:
            self.reuse.check_step(snes.getSolution())
        reason = self.stop.test(it, norms[2], g, snes.getTolerances(), snes.getSolution())
        withdrawn = it > 0 and self._withdraw_exact(snes.getSolution())
        if self._exact_ok and reason == 0 and not withdrawn and self.stop.steps and \
                self.stop.steps[-1] <= self._near * self.stop.step_scale:
            self._exact_on = True
            # near the minimiser the exact Hessian is positive definite: quadratic
            # convergence where IPC's per-pair projection converges linearly
            self.problem.ipc.exact_hessian(True)
        return reason

    def _withdraw_exact(self, x: PETSc.Vec) -> bool:
        """After the line search of a direction from the barrier's exact Hessian: whether
        it was shortened (by the CCD bound or the line search), and if so go back to IPC's
        projection, as after a direction that failed (the exact Hessian tried again once
        the steps are :data:`EXACT_SHRINK` times smaller). Once that is the test's size
        itself, a shortened exact step is kept on the exact Hessian, as before: the
        projection alone converges only linearly there and can reach the round-off floor
        short of the force check (the friction cubes of ``tests/test_adjoint_contact.py``).

        Newton's local phase, where the exact Hessian converges quadratically, takes its
        steps whole; a shortened step shows the exact model does not hold there yet, and
        on the pile its following directions are shortened again, for many iterations
        (docs/contact.md, "The 4-box pile against today and against the baseline").
        """
        full, self._exact_full = self._exact_full, None
        if full is None or not self._exact_on or self._near <= 1.0:
            return False
        self._x_before.axpy(-1.0, x)  # x_k - x_{k+1} = alpha y
        taken = self._x_before.norm(PETSc.NormType.INFINITY)
        if taken >= (1.0 - WHOLE_STEP_TOL) * full:
            return False
        self.exact_withdrawn += 1
        self._near = max(1.0, self._near / EXACT_SHRINK)
        self._exact_on = False
        self.problem.ipc.exact_hessian(False)
        return True

    def _precheck(self, x: PETSc.Vec, y: PETSc.Vec) -> bool:
        """Before the line search: record lambda^2/2 and bound the step.

        ``y`` is the full Newton direction (the line search tries x - alpha y) and the
        residual r at x is in ``self.b``: lambda^2 = r . y (seed definition 4). ``auto``
        with CG may first replace an ascent direction; then contact and the inversion
        filter shorten y (:mod:`fem_anim.solver.step_bounds`).

        Returns:
            Whether y was changed.
        """
        replaced = self.hessian.descent_direction(x, y, self.b)  # auto with CG
        self.stop.decrements.append(np.nan if self.saddle else 0.5 * abs(self.b.dot(y)))
        # the full step, before any bound shortens it (also read by the exact-Hessian switch)
        if self.stop.stopping == "step" or self._exact_near:
            self.stop.steps.append(y.norm(PETSc.NormType.INFINITY))
        if self._exact_on:  # for _withdraw_exact: was this direction taken whole?
            self._exact_full = self.stop.steps[-1]
            if self._x_before is None:
                self._x_before = x.duplicate()
            x.copy(self._x_before)
        scaled = bound_step(self.problem, x, y) < 1.0 or replaced
        if self.problem.filter_inversion:
            scaled = filter_inverting(self.problem, x, y) or scaled
        if self.halving:
            scaled = self._halve_clipped(x, y) or scaled
        self.hessian.record_model(x, y)
        self.reuse.record_direction(x, y)
        return scaled

    def _halve_clipped(self, x: PETSc.Vec, y: PETSc.Vec) -> bool:
        """Backtrack by halving where PETSc's ``bt`` would cut the step to a tenth.

        With an objective, ``bt`` (PETSc 3.18) takes s = r . y as its initial slope and,
        when g(x - y) fails its test, the minimiser of a quadratic fit,
        -s / (g(x - y) - g(x) - 2 s), or 0.1 where that is below 0.1: always when
        g(x - y) > g(x) + 2 s. A barrier makes g(x - y) enormous for a step whose end nears
        contact (a landing: the first direction is free fall, computed where the barrier is
        not yet active), so each iteration covers a tenth of the remaining way
        (docs/contact.md, "The 4-box pile against today and against the baseline"). There
        this tries alpha = 1/2, 1/4, 1/8 and scales y by the first whose g(x - alpha y)
        <= g(x) - c alpha s (Armijo's sufficient decrease, c = ``snes_linesearch_alpha``;
        stricter than bt's own test, which it therefore passes), or by 0.1, the step ``bt``
        would try, if none does; ``bt`` then tests the scaled step first (its g
        remembered: no second evaluation) and takes it or backtracks on from there.
        Elsewhere y is left to ``bt``.

        Returns:
            Whether y was scaled.
        """
        f = self.objective(self.snes, x)
        slope = self.b.dot(y)  # bt's initial slope: g(x - alpha y) = f - alpha slope + ...
        if not slope > 0.0 or not np.isfinite(f):
            return False
        if self._trial is None:
            self._trial, self._scaled = x.duplicate(), y.duplicate()
        trial, scaled = self._trial, self._scaled
        trial.waxpy(-1.0, y, x)
        g = self.objective(self.snes, trial)
        if np.isfinite(g) and g <= f + 2.0 * slope:
            return False  # bt takes the full step, or tries at least half of it
        for alpha in HALVINGS:
            # the trial point exactly as bt will form it from the scaled y: x - (alpha y)
            y.copy(scaled)
            scaled.scale(alpha)
            trial.waxpy(-1.0, scaled, x)
            g = self.objective(self.snes, trial)
            if g <= f - self._armijo * alpha * slope:
                break
        else:
            alpha = 0.1
        y.scale(alpha)
        self.halved += 1
        return True

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
        with options_in_database(self.prefix, self.options):  # MUMPS reads its own here
            ksp.solve(r, step)
        self._own_linear_its += ksp.getIterationNumber()
        return 0.5 * abs(r.dot(step))

    def destroy(self) -> None:
        """Free the SNES, its matrices and vectors, and the Hessian choice's and reuse's."""
        self._clear_objective_cache()
        if self._g_seed is not None:  # seeded, never solved
            self._g_seed[0].destroy()
        for vec in (self._x_before, self._trial, self._scaled):
            if vec is not None:
                vec.destroy()
        self.hessian.destroy()
        self.reuse.destroy()
        self.snes.destroy()
        self.A.destroy()
        self.b.destroy()
