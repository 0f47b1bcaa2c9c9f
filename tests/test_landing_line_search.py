"""The landing's line search (:meth:`fem_anim.solver.minimiser.Minimiser._halve_clipped`).

The bench's pile (``fem_anim.bench.contact_cost.pile_scene``, coarse): two boxes start
1 mm above a ground plane whose barrier reaches 0.5 mm, at rest, and land in the first
step. Its first Newton direction is free fall, computed where the barrier is not yet
active, and g at its end is enormous; PETSc's ``bt`` cut each such step to a tenth (13
Newton iterations for the step). Halving instead (1/2, 1/4, 1/8, under Armijo's test)
lands in 5: here at most 6, and fewer than with ``bt`` alone, to the same solution (within
the step test's size) and meeting the same stopping test.
"""

from __future__ import annotations

import numpy as np

import fem_anim.solver.minimiser as minimiser
from fem_anim.bench.contact_cost import pile_scene
from fem_anim.scene.loading import load_scene
from fem_anim.simulation.loop import Simulation


def _first_step(tmp_path, name: str):
    path = tmp_path / f"{name}.toml"
    path.write_text(pile_scene(0.05))
    sim = Simulation(load_scene(path, ["time.steps=1", "output.render=false"]))
    state, stats = sim.step(sim.initial_state(), 0.01)
    tol = sim.minimiser.stop.step_scale  # ||p||_inf of the step test, m
    z = sim.problem.V.tabulate_dof_coordinates()[:, 2] + state.u[2::3]
    return state.u, stats, sim.minimiser.halved, tol, z.min()


def test_the_landing_halves_instead_of_cutting_to_a_tenth(tmp_path, monkeypatch):
    u, stats, halved, tol, lowest = _first_step(tmp_path, "halving")
    monkeypatch.setattr(minimiser, "HALVE_CLIPPED", False)
    u_bt, stats_bt, halved_bt, _, _ = _first_step(tmp_path, "bt")
    assert halved > 0 and halved_bt == 0
    # both met the stopping test (IPC's step test and its force check)
    assert stats.reason > 0 and stats_bt.reason > 0
    assert stats.newton_its <= 6 < stats_bt.newton_its, (stats.newton_its, stats_bt.newton_its)
    assert tol > 0.0 and np.abs(u - u_bt).max() <= 10.0 * tol
    # the boxes did land: their lowest vertices within the ground's barrier (0.5 mm)
    assert 0.0 < lowest < 0.5e-3
