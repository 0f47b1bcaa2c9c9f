"""Bounds on a Newton step before its line search (seed section 3.2).

The line search tries x - alpha y, 0 < alpha <= 1, along the Newton direction y. These
functions shorten y beforehand so that no trial point is inadmissible:

* obstacles (``[[obstacle]]``): no contact point nears an obstacle by more than a fraction
  of its distance (:meth:`fem_anim.contact.obstacles.ObstacleContact.step_bound`);
* contact between surfaces (``[contact]``): no surface crosses another or itself on the
  way, by ipctk's continuous collision detection
  (:meth:`fem_anim.contact.ipc.IPCContact.step_bound`);
* the inversion filter (``solver.inversion_filter``): y is halved until no element of
  x - y has det F <= 0. The objective is +inf there
  (:meth:`fem_anim.problem.objective.EnergyProblem.objective`), so no iterate with an
  inverted element is ever accepted.
"""

from __future__ import annotations

from petsc4py import PETSc

from fem_anim.problem.events import EVENTS

__all__ = ["MAX_FILTER_HALVINGS", "bound_step", "filter_inverting", "step_limit"]

#: Halvings after which the inversion filter gives up (the line search then decides).
MAX_FILTER_HALVINGS = 40


def step_limit(problem, x: PETSc.Vec, y: PETSc.Vec) -> float:
    """The largest alpha <= 1 for which x - alpha y keeps clear of contact.

    Args:
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem` (its ``contact``
            and ``ipc``, either may be None; its state is set to x).
        x: The current iterate.
        y: The direction (the trial points are x - alpha y).

    Returns:
        1 without contact; else the smallest of the obstacles' bound (a fraction of each
        contact point's distance) and ipctk's collision-free step.
    """
    contact, ipc = getattr(problem, "contact", None), getattr(problem, "ipc", None)
    if contact is None and ipc is None:
        return 1.0
    problem.set_state(x)
    alpha = 1.0
    if getattr(problem, "mixed", False):  # the displacement block of y = (y_u, y_p)
        y = problem.fields.displacement_part(y)
    if contact is not None:
        alpha = contact.step_bound(y)
    if ipc is not None:
        alpha = min(alpha, ipc.step_bound(y.array))
    return alpha


def bound_step(problem, x: PETSc.Vec, y: PETSc.Vec) -> float:
    """Scale y in place by :func:`step_limit` when that is below 1.

    Returns:
        The factor alpha applied (1 if y is unchanged).
    """
    alpha = step_limit(problem, x, y)
    if alpha < 1.0:
        y.scale(alpha)
    return alpha


def filter_inverting(problem, x: PETSc.Vec, y: PETSc.Vec) -> bool:
    """Halve y in place until x - y has det F > 0 in every element.

    At most :data:`MAX_FILTER_HALVINGS` times; the problem's state is x again afterwards.

    Args:
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem` (``set_state``,
            ``min_det_F``).
        x: The current iterate.
        y: The Newton direction.

    Returns:
        Whether y was changed.
    """
    trial = x.duplicate()
    EVENTS["filter"].begin()
    try:
        for halvings in range(MAX_FILTER_HALVINGS):
            x.copy(trial)
            trial.axpy(-1.0, y)
            problem.set_state(trial)
            if problem.min_det_F() > 0.0:
                return halvings > 0
            y.scale(0.5)
        return True
    finally:
        trial.destroy()
        problem.set_state(x)
        EVENTS["filter"].end()
