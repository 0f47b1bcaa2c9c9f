"""When Newton's contact step leaves IPC's projected barrier Hessian for the exact one and
comes back (:class:`fem_anim.solver.minimiser.Minimiser`), and when a step is at the
objective's round-off floor (:class:`fem_anim.solver.stopping.StoppingTest`): the two rules
that the 4-box pile's accepted steps and Newton iterations turn on (docs/contact.md, "The
4-box pile against today and against the baseline")."""

from __future__ import annotations

from petsc4py import PETSc

from fem_anim.solver.stopping import ROUNDOFF_REASON, StoppingTest, resolution

TOLERANCES = (1e-8, 1e-50, 0.0, 50)  # rtol, atol, stol, max_it (the step test ignores them)


def test_round_off_floor_needs_a_direction_that_promised_nothing():
    """g unchanged to its resolution and ||r|| not halved is the round-off floor only when
    the direction's predicted decrease lambda^2/2 was at most that resolution too: a line
    search that cut a promising direction to a step g cannot see goes on iterating."""
    stop = StoppingTest("step")
    stop.forces = lambda x: 1.0
    stop.step_scale = 0.0  # the step test itself is never met here
    stop.start()
    g = 1.0
    assert stop.test(0, 1.0, g, TOLERANCES) == PETSc.SNES.ConvergedReason.ITERATING
    stop.decrements.append(1e-3)  # promised far more than g's resolution (about 1e-12)
    stop.steps.append(1.0)
    assert stop.test(1, 0.9, g, TOLERANCES) == PETSc.SNES.ConvergedReason.ITERATING
    stop.decrements.append(0.5 * resolution(g))  # promised nothing g can resolve
    stop.steps.append(1.0)
    assert stop.test(2, 0.9, g, TOLERANCES) == ROUNDOFF_REASON
    # and a residual that still halves is never the floor
    stop.decrements.append(0.0)
    assert stop.test(3, 0.4, g, TOLERANCES) == PETSc.SNES.ConvergedReason.ITERATING
