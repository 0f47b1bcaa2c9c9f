"""The trust region's state belongs to one time step (:mod:`fem_anim.solver.trust_region`).

The contract (:meth:`fem_anim.solver.hessian_choice.HessianChoice.start_step`): each time
step starts afresh: no trust radius, no memory of CG's indefiniteness, no longest direction,
plain CG. So a step taken by a minimiser that has just solved steps through a trust region
is the step a new minimiser takes from the same state: the same iterations of each kind,
the same CG iterations and the same displacements (one process, one machine: the same
arithmetic). The case is the coarse crushed StVK cube with ``cg-icc`` and ``auto``
(tests/test_hessian_modes.py), whose first steps meet an indefinite Hessian and step in a
trust region.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from test_solver_menu import squash

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                reason="serial: compares two minimisers of one process")

DT = 0.05
STEPS = 3


def test_a_step_after_a_trust_region_is_a_fresh_minimisers_step(tmp_path):
    continued = squash(tmp_path, hessian="auto", element_size=0.1, solver='preset = "cg-icc"')
    states, stats = [continued.initial_state()], []
    regions = []
    for _ in range(STEPS):
        before = continued.minimiser.hessian.trust_region_its
        state, s = continued.step(states[-1], DT)
        assert s.reason > 0
        states.append(state)
        stats.append(s)
        regions.append(continued.minimiser.hessian.trust_region_its - before)
    assert regions[0] > 0, "the case no longer steps in a trust region at step 1"
    for k in range(1, STEPS):
        (tmp_path / f"fresh{k}").mkdir()
        fresh = squash(tmp_path / f"fresh{k}", hessian="auto", element_size=0.1,
                       solver='preset = "cg-icc"')
        state, s = fresh.step(states[k], DT)
        assert s.reason > 0
        assert (s.newton_its, s.linear_its, dict(s.hessian_its)) == \
            (stats[k].newton_its, stats[k].linear_its, dict(stats[k].hessian_its)), k + 1
        np.testing.assert_allclose(state.u, states[k + 1].u, rtol=0,
                                   atol=1e-13 * np.abs(states[k + 1].u).max())
        fresh.minimiser.destroy()
    continued.minimiser.destroy()
