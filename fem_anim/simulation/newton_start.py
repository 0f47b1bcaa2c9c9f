"""Where each step's minimisation starts: a state where the step objective is finite.

Newton starts at the predictor, else at u_n, else at the linearised response to the pins'
motion. A large predicted step, or pins that move far in one step, can invert elements,
where energies such as neo-Hookean's are undefined (+inf with the inversion filter). The
last resort is one Newton step from u_n with the pins still at their old positions: the
residual's lifting term carries the pins' increment into the free dofs through the Hessian
(a linear-elastic extension of the motion). With ``[contact]`` the start is instead
collision free (:func:`collision_free_guess`).
"""

from __future__ import annotations

import math

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.errors import ConvergenceError
from fem_anim.simulation.energy_report import moving_pins

__all__ = ["collision_free_guess", "initial_guess"]


def initial_guess(problem, minimiser, scene, u_pred: np.ndarray, u_last: np.ndarray,
                  what: str) -> float | None:
    """Put the step's start into ``problem.x_work`` (collective).

    Args:
        problem: The staged :class:`~fem_anim.problem.objective.EnergyProblem`.
        minimiser: The :class:`~fem_anim.solver.minimiser.Minimiser` (its Newton step).
        scene: The scene (whether pins move, for the message).
        u_pred: The predictor (m, local dofs of V).
        u_last: u_n (m, local dofs of V).
        what: The step's name in messages.

    Returns:
        g at the start, for the minimiser to reuse (None: not evaluated).

    Raises:
        ConvergenceError: if even the last resort inverts an element (or, with
            ``[contact]``, no collision-free start has a finite objective).
    """
    p = problem
    x = p.x_work
    if p.ipc is not None:
        collision_free_guess(p, u_pred, u_last, what)
        return None
    for guess in (u_pred, u_last):
        p.load_guess(guess, x)
        if math.isfinite(g := p.objective(None, x)):
            return g
    p.load_guess(u_last, x, apply_bcs=False)
    r, step = x.duplicate(), x.duplicate()
    p.residual(None, x, r)
    minimiser.newton_step(x, r, step)
    x.axpy(-1.0, step)
    r.destroy()
    step.destroy()
    if not math.isfinite(g := p.objective(None, x)):
        why = "the pins move too far in one step" if moving_pins(scene) else \
            "the motion predicted over one step inverts elements or overflows"
        raise ConvergenceError(f"{what}: no start for Newton gives a finite step "
                               f"objective ({why}): reduce time.dt")
    return g


def collision_free_guess(problem, u_pred: np.ndarray, u_last: np.ndarray, what: str) -> None:
    """With ``[contact]``: u_n + alpha (u_pred - u_n) into ``problem.x_work``, pins at their
    targets, with alpha ipctk's collision-free step size, so the start has no intersection
    (the barrier is finite on crossed surfaces: the objective cannot reject them).

    Moving pins go only as far as alpha too: Newton's pinned rows x - u_bc then bring them
    to their targets, each step capped by the CCD, so a pin never pushes one surface through
    another; if it cannot get there the step fails and is retried smaller
    (:class:`~fem_anim.simulation.adaptive.AdaptiveStepper`).

    Raises:
        ConvergenceError: neither that start nor u_n has a finite objective.
    """
    p = problem
    u = compat.petsc_vec(p.u)
    p.u.x.array[:] = u_pred
    fem_petsc.set_bc(u, p.displacement_bcs)  # the pins on V (a mixed unknown's are on W)
    u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
    target = p.u.x.array.copy()
    p.u.x.array[:] = u_last
    alpha = p.ipc.step_bound(u_last - target)
    for guess in (u_last + alpha * (target - u_last), u_last):
        p.load_guess(guess, p.x_work, apply_bcs=False)  # a mixed guess keeps its pressure
        if math.isfinite(p.objective(None, p.x_work)):
            return
    raise ConvergenceError(f"{what}: no collision-free start with every element "
                           "uninverted: reduce time.dt")
