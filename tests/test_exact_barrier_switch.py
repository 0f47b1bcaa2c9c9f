"""When Newton's contact step leaves IPC's projected barrier Hessian for the exact one and
comes back (:class:`fem_anim.solver.minimiser.Minimiser`), and when a step is at the
objective's round-off floor (:class:`fem_anim.solver.stopping.StoppingTest`): the two rules
that the 4-box pile's accepted steps and Newton iterations turn on (docs/contact.md, "The
4-box pile against today and against the baseline")."""

from __future__ import annotations

import ipctk
import pytest
from mpi4py import MPI
from petsc4py import PETSc
from test_contact_pace import STACK

from fem_anim.scene.loading import Scene
from fem_anim.solver import minimiser
from fem_anim.solver.stopping import ROUNDOFF_REASON, StoppingTest, resolution

TOLERANCES = (1e-8, 1e-50, 0.0, 50)  # rtol, atol, stol, max_it (the step test ignores them)
INF = PETSc.NormType.INFINITY


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


@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="one rank's vectors")
def test_a_shortened_exact_direction_goes_back_to_the_projection():
    """A direction from the barrier's exact Hessian taken whole keeps the exact Hessian; one
    the line search or the CCD shortened goes back to IPC's projection, the exact Hessian
    then tried again only EXACT_SHRINK times nearer; once that is the test's size itself
    the exact Hessian stays (the projection alone may reach the round-off floor short of
    the force check)."""
    from fem_anim.simulation.loop import Simulation

    sim = Simulation(Scene.from_toml(STACK.format(steps=1)))
    m, ipc = sim.minimiser, sim.problem.ipc
    x = m.b.duplicate()
    x.set(0.0)
    y = x.duplicate()
    y.set(1e-3)

    def direction_taken(alpha: float) -> bool:
        m._exact_on = True
        ipc.exact_hessian(True)
        m._exact_full = y.norm(INF)
        m._x_before = x.copy() if m._x_before is None else m._x_before
        x.copy(m._x_before)
        after = x.copy()
        after.axpy(-alpha, y)
        return m._withdraw_exact(after)

    m._exact_ok, m._near = True, minimiser.EXACT_NEAR
    assert not direction_taken(1.0)  # whole: stays exact
    assert m._exact_on and ipc.projection == ipctk.PSDProjectionMethod.NONE
    assert m._near == minimiser.EXACT_NEAR and m.exact_withdrawn == 0
    assert direction_taken(0.5)  # cut by the line search
    assert not m._exact_on and ipc.projection == ipctk.PSDProjectionMethod.CLAMP
    assert m._near == minimiser.EXACT_NEAR / minimiser.EXACT_SHRINK
    assert m._exact_ok and m.exact_withdrawn == 1
    m._near = 1.0
    assert not direction_taken(0.5)  # at the test's size itself: the exact Hessian stays
    assert m._exact_on and ipc.projection == ipctk.PSDProjectionMethod.NONE
    assert m._exact_ok and m.exact_withdrawn == 1
    m._near = minimiser.EXACT_SHRINK
    assert direction_taken(0.999)
    assert m._near == 1.0 and m.exact_withdrawn == 2
    # a direction from the projection is never withdrawn
    m._exact_on, m._exact_full = False, None
    assert not m._withdraw_exact(x) and m.exact_withdrawn == 2
