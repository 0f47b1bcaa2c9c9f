"""When a step's Newton iteration stops, and what it reports (seed section 3.2, definition 4).

``solver.stopping`` picks the test of :class:`StoppingTest`, which SNES calls once per
iteration (``SNESSetConvergenceTest``):

* ``"norm"``: PETSc's residual-norm tests ||r|| <= ``snes_atol`` or
  ||r|| <= ``snes_rtol`` r0 (r0 the norm at the initial guess);
* ``"decrement"``: the Newton decrement lambda^2/2 = r^T H^-1 r / 2 <= ``decrement_tol``
  (seed definition 4; affine invariant, in the units of g), read from the Newton direction
  before its line search;
* ``"step"``: IPC's test (Li et al. 2020, section 4.1): the full Newton step p (before its
  line search and contact bound) is small against the scene, ||p||_inf / h <= ``step_tol``
  l with l the bounding-box diagonal of the rest mesh (:func:`scene_diagonal`), so a scene
  at rest stops as soon as Newton moves it less than a fraction of its size per second.
  A small step alone does not make the step's equations hold, so the test also asks that
  the residual be small against the step's own forces: ||r|| <= :data:`FORCE_TOL` x the
  largest of the 2-norms of the terms of grad g (inertia and the momenta it is the difference
  of, damping, w grad E's elastic and obstacle part, w times gravity, w times the IPC barrier
  and friction; over the free dofs:
  :meth:`fem_anim.problem.objective.EnergyProblem.force_scale`), evaluated only once the
  step is small. ``"auto"`` (the default) is ``"step"`` for a scene with contact
  (obstacles or ``[contact]``) and ``"norm"`` for any other (:func:`resolve_stopping`).

Each test also stops at the *round-off floor*: an iteration that neither halves ||r||
nor changes g by more than its floating-point resolution (:func:`resolution`) has nothing
left to gain and stops with :data:`ROUNDOFF_REASON` (under ``"step"`` only after a Newton
direction that promised no more than that, its lambda^2/2:
:meth:`StoppingTest.promised_nothing`), as does a line search that fails
because the predicted decrease is below that resolution (:func:`at_objective_roundoff`).
:func:`finish_at_roundoff` then takes full Newton steps judged by the residual alone
(:func:`polish`) and reports whether the test was met. ``solver.max_iterations`` with
``on_budget = "accept"`` keeps an iterate that lowered g at the budget
(:func:`accept_at_budget`, :data:`BUDGET_REASON`).

A saddle point (``element.formulation = "mixed"``) has no g to judge by: the round-off test
becomes ||r|| no longer halving below :data:`SADDLE_FLOOR` r0, and its decrement is NaN.

The functions taking ``m`` act on a :class:`fem_anim.solver.minimiser.Minimiser`: its
``snes``, ``problem``, residual vector ``b``, ``objective``, ``newton_step``, ``hessian``,
``budget`` and ``stop`` (its :class:`StoppingTest`).
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim.errors import ConvergenceError
from fem_anim.solver.step_bounds import step_limit

__all__ = ["BUDGET_REASON", "CONVERGED_REASONS", "DECREMENT_REASON", "FORCE_TOL",
           "POLISH_FAILED_REASON", "ROUNDOFF_REASON", "ROUNDOFF_ULPS", "SADDLE_FLOOR",
           "STEP_REASON", "StoppingTest", "accept_at_budget", "at_objective_roundoff",
           "finish_at_roundoff", "polish", "reason_name", "resolution", "resolve_stopping",
           "scene_diagonal"]

#: Reason the convergence test gives when Newton stopped at the round-off floor of the
#: objective: PETSc's CONVERGED_SNORM_RELATIVE, which PETSc itself never reports here
#: (``snes_stol`` is 0). :func:`finish_at_roundoff` then decides the reason reported.
ROUNDOFF_REASON = 4
#: The resolution of g, in units in the last place of max |g| (:func:`resolution`).
ROUNDOFF_ULPS = 4096.0
#: Reason recorded when the Newton-decrement test stopped the iteration: PETSc's
#: CONVERGED_ITS ("converged by a user test"; a plain iteration cap is DIVERGED_MAX_IT).
DECREMENT_REASON = 5
#: Reason recorded when IPC's step test (with its force check) stopped the iteration: the
#: same "converged by a user test" as the decrement's (the scene's ``solver.stopping`` says
#: which test it was).
STEP_REASON = DECREMENT_REASON
#: ``"step"``: the residual norm at most this fraction of the largest force term's norm.
FORCE_TOL = 1e-6
#: A saddle point's Newton is at its round-off floor when an iteration no longer halves
#: ||r|| although ||r|| is already this far below its first value.
SADDLE_FLOOR = 1e-6
#: Reason recorded when Newton stopped at the round-off floor and the polish's full Newton
#: steps did not reach the requested test either (no PETSc reason is 6): the step is kept,
#: as converged as double precision allows, but it is *not* converged to the test.
POLISH_FAILED_REASON = 6
#: Reason recorded when ``solver.on_budget = "accept"`` kept the iterate reached after
#: ``solver.max_iterations`` Newton iterations because it decreased the step objective
#: (no PETSc reason is 7): accepted, *not* converged to the test.
BUDGET_REASON = 7
#: Reasons of a step that met its stopping test.
CONVERGED_REASONS = (2, 3, DECREMENT_REASON)


def resolution(*values: float) -> float:
    """The smallest change of the objective distinguishable from round-off near ``values``:
    :data:`ROUNDOFF_ULPS` x machine epsilon x max |value|."""
    return ROUNDOFF_ULPS * np.finfo(float).eps * max(abs(v) for v in values)


def resolve_stopping(stopping: str, contact: bool, saddle: bool, newton: bool = True) -> str:
    """The test ``solver.stopping`` names: ``"auto"`` is ``"step"`` with contact (a barrier's
    residual spans too many orders for a test relative to r0), ``"norm"`` otherwise, for a
    saddle point (its decrement and force check bound nothing) and for a method other than
    Newton with line search (no full Newton step to measure).

    Args:
        stopping: ``solver.stopping``.
        contact: Whether the scene has contact (obstacles or ``[contact]``).
        saddle: Whether the step is a saddle point.
        newton: Whether ``solver.method`` is ``"newton"`` with its split constant terms
            (an implicit displacement step: the force check's terms exist).

    Raises:
        ValueError: ``"step"`` named for a saddle point or another method.
    """
    if stopping == "auto":
        return "step" if contact and not saddle and newton else "norm"
    if stopping == "step" and (saddle or not newton):
        raise ValueError("solver.stopping = \"step\" needs solver.method = \"newton\" on an "
                         "implicit displacement step (not element.formulation = \"mixed\" "
                         "nor an explicit integrator): use \"norm\"")
    return stopping


def scene_diagonal(comm, points: np.ndarray) -> float:
    """The length of the diagonal of the bounding box of ``points`` over all ranks (m).

    Args:
        comm: The mesh's communicator.
        points: This rank's (n, gdim) rest coordinates (n may be 0).
    """
    n = points.shape[1]
    local = np.concatenate([points.min(axis=0), -points.max(axis=0)]) if points.size \
        else np.full(2 * n, np.inf)
    bounds = np.empty_like(local)
    comm.Allreduce(np.ascontiguousarray(local, dtype=float), bounds, op=MPI.MIN)
    return float(np.linalg.norm(-bounds[n:] - bounds[:n]))


def reason_name(enum, value: int) -> str:
    """``"NAME (value)"`` of a PETSc reason enumeration's member, or the bare value."""
    for name in dir(enum):
        if not name.startswith("_") and getattr(enum, name) == value:
            return f"{name} ({value})"
    return str(value)


class StoppingTest:
    """The convergence test of one minimiser, with the step's residual and decrement history.

    Args:
        stopping: ``solver.stopping`` resolved (:func:`resolve_stopping`): ``"norm"``,
            ``"decrement"`` or ``"step"``.
        decrement_tol: ``solver.decrement_tol`` (J), for ``"decrement"``.
        saddle: Whether the problem is a saddle point (no objective to judge by).

    Attributes:
        history: ``(||r||, g)`` at each iteration of the step (``history[0][0]`` is r0; an
            ``auto`` or Hessian-reuse restart continues it).
        decrements: lambda^2/2 of each Newton direction of the step.
        restarting: Set by the minimiser before an SNES solve that continues the step.
        polish_its: Full Newton steps of the last polish.
        polish_assemblies: ... of those, the ones that assembled a Hessian.
        step_scale: ``"step"``: the largest ||p||_inf (m) of a converged step, step_tol x
            diagonal x h, set by the minimiser for each step.
        steps: ||p||_inf of each full Newton direction of the step.
        forces: ``"step"``: a callable giving the largest force term's norm at an iterate
            x (the minimiser's), called once a step is small.
        force_checks: How often the step called ``forces``.
    """

    def __init__(self, stopping: str = "norm", decrement_tol: float = 0.0,
                 saddle: bool = False):
        self.stopping = stopping
        self.decrement_tol = decrement_tol
        self.saddle = saddle
        self.history: list[tuple[float, float]] = []
        self.decrements: list[float] = []
        self.restarting = False
        self.polish_its = 0
        self.polish_assemblies = 0
        self.step_scale = 0.0
        self.steps: list[float] = []
        self.forces = None
        self.force_checks = 0

    def start(self) -> None:
        """A new step: no decrements, no step norms, no polish, not restarting."""
        self.decrements = []
        self.steps = []
        self.force_checks = 0
        self.polish_its = self.polish_assemblies = 0
        self.restarting = False

    @property
    def initial_norm(self) -> float:
        """r0 of the step (NaN before its first test)."""
        return self.history[0][0] if self.history else float("nan")

    @property
    def last_decrement(self) -> float:
        """lambda^2/2 of the step's last Newton direction (NaN without one)."""
        return self.decrements[-1] if self.decrements else float("nan")

    def forces_balanced(self, fnorm: float, x: PETSc.Vec) -> bool:
        """``"step"``'s force check at the iterate x with residual norm ``fnorm``:
        ||r|| <= :data:`FORCE_TOL` x the largest force term's norm (collective)."""
        self.force_checks += 1
        return fnorm <= FORCE_TOL * self.forces(x)

    def promised_nothing(self, floor: float) -> bool:
        """Whether the last Newton direction's predicted decrease lambda^2/2 (before any
        bound or line search) is at most ``floor``, the objective's resolution: then a
        change of g below the resolution is the round-off floor. A direction that
        promised more and was cut by the line search to a step g cannot resolve is not:
        the iteration goes on (on the 4-box pile such steps ended 4 to 7 of 10 steps
        with ||r|| at 1 to 10 % of the largest force term, docs/contact.md, "The 4-box
        pile against today and against the baseline"). True without a recorded direction.
        Asked under ``"step"`` only, whose force check such an ending skips (the norm and
        decrement tests keep the plain rule: not measured here).
        """
        return not self.decrements or not self.decrements[-1] > floor

    def target(self, snes: PETSc.SNES) -> float:
        """The residual norm the norm test asks for: max(snes_atol, snes_rtol r0)."""
        rtol, atol, _, _ = snes.getTolerances()
        return max(atol, rtol * self.history[0][0]) if self.history else atol

    def test(self, it: int, fnorm: float, g: float,
             tolerances: tuple[float, float, float, int], x: PETSc.Vec | None = None) -> int:
        """The SNES reason after iteration ``it``: the chosen test, or the round-off floor.

        Args:
            it: The iteration number (0: the initial guess).
            fnorm: ||r|| at the iterate.
            g: The objective there (NaN for a saddle point).
            tolerances: ``snes.getTolerances()``: (rtol, atol, stol, max_it).
            x: The iterate (``"step"``'s force check reads it).

        Returns:
            A ``PETSc.SNES.ConvergedReason``, :data:`DECREMENT_REASON` or
            :data:`ROUNDOFF_REASON` (0, ITERATING, to go on).
        """
        rtol, atol, _, max_it = tolerances
        if it == 0 and not self.restarting:
            self.history = []  # an auto restart keeps the step's first norm (snes_rtol)
        if it == 0 and self.restarting:
            self.restarting = False
            self.history.append((fnorm, g))
            return PETSc.SNES.ConvergedReason.ITERATING
        self.history.append((fnorm, g))
        R = PETSc.SNES.ConvergedReason
        if not np.isfinite(fnorm):
            return R.DIVERGED_FNORM_NAN
        if self.stopping == "decrement":
            # lambda^2/2 of the previous Newton direction (the step from it is taken)
            if it > 0 and self.decrements and self.decrements[-1] <= self.decrement_tol:
                return DECREMENT_REASON
        elif self.stopping == "step":
            # the previous full Newton step was small, and the residual is small against
            # the step's forces at the iterate it led to
            if it > 0 and self.steps and self.steps[-1] <= self.step_scale and \
                    self.forces_balanced(fnorm, x):
                return STEP_REASON
        elif fnorm <= atol:
            return R.CONVERGED_FNORM_ABS
        elif fnorm <= rtol * self.history[0][0]:
            return R.CONVERGED_FNORM_RELATIVE
        if it > 0 and not self.saddle:
            f_prev, g_prev = self.history[-2]
            if fnorm > 0.5 * f_prev and abs(g_prev - g) <= resolution(g, g_prev) and \
                    (self.stopping != "step" or self.promised_nothing(resolution(g, g_prev))):
                return ROUNDOFF_REASON
        elif it > 0:  # a saddle point: judged by ||r|| alone (no g to see round-off in)
            f_prev = self.history[-2][0]
            if fnorm > 0.5 * f_prev and fnorm <= SADDLE_FLOOR * self.history[0][0]:
                return ROUNDOFF_REASON
        if it >= max_it:
            return R.DIVERGED_MAX_IT
        return R.ITERATING


def at_objective_roundoff(m, x: PETSc.Vec, g0: float) -> bool:
    """Whether Newton cannot decrease g any further in floating point.

    The predicted decrease of a Newton step is lambda^2/2 = r^T H^-1 r / 2 (seed
    definition 4). When it is below :func:`resolution` of max(|g(x)|, |g(x_0)|) the
    backtracking line search must fail, and x is as converged as double precision allows.
    Uses the factorisation of the last Jacobian.

    Args:
        m: The minimiser.
        x: The iterate where the line search failed.
        g0: g at the step's initial guess.
    """
    g = m.objective(m.snes, x)
    m.hessian.leave_trust_region()  # the full Newton step's decrement
    r, step = m.b.duplicate(), m.b.duplicate()
    m.problem.residual(m.snes, x, r)
    decrement = m.newton_step(x, r, step, assemble_hessian=False)
    r.destroy()
    step.destroy()
    return decrement <= resolution(g, g0)


def polish(m, x: PETSc.Vec, max_steps: int = 5, assemble: bool = True) -> tuple[int, float]:
    """Full Newton steps judged by the residual, where g can no longer judge them.

    Below the objective's round-off the line search cannot tell a good step from a bad one,
    but the residual still can: take full steps (x updated in place) while each at least
    halves ||r|| and keeps clear of contact (:func:`fem_anim.solver.step_bounds.step_limit`),
    then apply the chosen test (norms: ``snes_atol``, ``snes_rtol``; the decrement of
    the next Newton direction; or that direction's size with the force check). The steps
    are counted in ``m.stop.polish_its`` (and ``polish_assemblies``).

    Args:
        m: The minimiser.
        x: The iterate, overwritten with the last accepted full step.
        max_steps: At most this many full steps.
        assemble: False solves with the kept Hessian and its factorisation instead
            (``hessian_update = "rest"``, whose constant factorisation would otherwise be
            lost).

    Returns:
        The SNES reason to report (CONVERGED_FNORM_ABS / _RELATIVE, :data:`DECREMENT_REASON`,
        :data:`STEP_REASON`, or :data:`POLISH_FAILED_REASON` if the test is still not met:
        x is kept, as converged as double precision allows) and the final residual norm.
    """
    stop = m.stop
    _, atol, _, _ = m.snes.getTolerances()
    target = stop.target(m.snes)
    R = PETSc.SNES.ConvergedReason
    stop.polish_its = stop.polish_assemblies = 0
    r, step, trial, r_trial = (m.b.duplicate() for _ in range(4))
    try:
        m.problem.residual(m.snes, x, r)
        norm = r.norm()
        for _ in range(max_steps):
            if norm <= target and stop.stopping == "norm":
                break
            decrement = m.newton_step(x, r, step, assemble_hessian=assemble)
            stop.polish_its += 1
            stop.polish_assemblies += assemble
            stop.decrements.append(np.nan if stop.saddle else decrement)
            if stop.stopping == "decrement" and decrement <= stop.decrement_tol:
                return DECREMENT_REASON, norm
            if stop.stopping == "step" and \
                    step.norm(PETSc.NormType.INFINITY) <= stop.step_scale:
                if stop.forces_balanced(norm, x):
                    return STEP_REASON, norm
            if step_limit(m.problem, x, step) < 1.0:
                break  # a full step must keep clear of obstacles and other surfaces
            x.copy(trial)
            trial.axpy(-1.0, step)
            m.problem.residual(m.snes, trial, r_trial)
            trial_norm = r_trial.norm()
            if not trial_norm <= 0.5 * norm:
                break
            trial.copy(x)
            r_trial.copy(r)
            norm = trial_norm
        m.problem.set_state(x)
        if norm <= target and stop.stopping == "norm":
            return (R.CONVERGED_FNORM_ABS if norm <= atol else R.CONVERGED_FNORM_RELATIVE,
                    norm)
        return POLISH_FAILED_REASON, norm
    finally:
        for v in (r, step, trial, r_trial):
            v.destroy()


def finish_at_roundoff(m, x: PETSc.Vec, steps: int) -> tuple[int, float]:
    """The polish of a step stopped at the round-off floor: its reason and residual norm.

    With ``hessian_update = "rest"`` the kept factorisation is tried first, then, if the
    test is still not met, the exact Hessian for the steps left. ``m.stop.polish_its``
    counts all the full steps taken.

    Args:
        m: The minimiser.
        x: The iterate, overwritten as by :func:`polish`.
        steps: At most this many full Newton steps in all.
    """
    stop = m.stop
    if m.reuse.mode == "rest":  # first with the kept factorisation
        reason, norm = polish(m, x, max_steps=steps, assemble=False)
        kept_its = stop.polish_its
        if reason == POLISH_FAILED_REASON and steps - kept_its > 0:
            reason, norm = polish(m, x, max_steps=steps - kept_its)  # exact
            stop.polish_its += kept_its
        return reason, norm
    return polish(m, x, max_steps=steps)


def accept_at_budget(m, x: PETSc.Vec, g0: float, norm: float, what: str) -> int:
    """``on_budget = "accept"``: keep x, the iterate after the budget, if it improved.

    A minimisation keeps x when g(x) < g(x_0) (the initial guess), a saddle point when
    ||r(x)|| < ||r(x_0)||.

    Args:
        m: The minimiser.
        x: The iterate after ``solver.max_iterations`` Newton iterations.
        g0: g at the initial guess.
        norm: ||r(x)||.
        what: The step's name, for the error.

    Returns:
        :data:`BUDGET_REASON`.

    Raises:
        ConvergenceError: if it did not improve (the step fails as without a budget).
    """
    if m.stop.saddle:
        r0 = m.stop.history[0][0] if m.stop.history else np.inf
        better, shown = norm < r0, f"residual norm {norm:.6e}, initially {r0:.6e}"
    else:
        g = m.objective(m.snes, x)
        better, shown = g < g0, f"g = {g:.10e}, at the initial guess {g0:.10e}"
    if not better:
        raise ConvergenceError(
            f"{what}: after its budget of {m.budget} Newton iterations "
            f"(solver.max_iterations) the step did not improve on its initial guess "
            f"({shown}), so it cannot be accepted")
    m.problem.set_state(x)
    return BUDGET_REASON
