"""``solver.mode = "preview"`` on contact scenes: each step solved to the stopping test.

One Newton step per time step does not keep an impact's energy bounded (measured on the pile:
docs/contact.md, "The preview on contact scenes"), so a scene with contact gets none of the
preview's keys (:mod:`fem_anim.scene.modes`) and its run says so in its first line. Checked:
the keys, the line, and the pile's first steps under ``--preview``: none fails (the one-step
preview's CG-ICC met the pile's indefinite Hessian at step 1 and retried it at half dt), and
the energy never rises above its start.
"""

from __future__ import annotations

from pathlib import Path


from fem_anim.scene import default_scene_text, load_scene
from fem_anim.scene.contact_integrator import integrator_note
from fem_anim.simulation.loop import Simulation

PILE = Path(__file__).resolve().parents[1] / "demos" / "pile.toml"
OBSTACLE = ('\n[[obstacle]]\nname = "floor"\ntype = "plane"\nnormal = [0.0, 0.0, 1.0]\n'
            'point = [0.0, 0.0, -0.5]\n')


def _solver_keys(scene) -> dict:
    return {k: scene["solver"][k] for k in ("max_iterations", "on_budget", "preset", "hessian")}


def test_a_contact_scene_keeps_the_exact_keys_under_preview(tmp_path):
    pile_preview = load_scene(PILE, ['solver.mode="preview"'])
    assert pile_preview["solver"]["mode"] == "preview"
    assert _solver_keys(pile_preview) == _solver_keys(load_scene(PILE, []))
    assert pile_preview["solver"]["max_iterations"] is None
    path = tmp_path / "obstacle.toml"
    path.write_text(default_scene_text().replace('integrator = "newmark"', 'integrator = "bdf2"')
                    + OBSTACLE)
    obstacle = load_scene(path, ['solver.mode="preview"'])
    assert _solver_keys(obstacle) == _solver_keys(load_scene(path, []))
    assert "preview" in integrator_note(obstacle.data)
    assert "preview" not in integrator_note(load_scene(path, []).data)
    # a scene without contact still gets the one-step preview
    assert load_scene(None, ['solver.mode="preview"'])["solver"]["max_iterations"] == 1


def test_preview_on_the_pile_does_not_fail_or_gain_energy():
    """Four steps of 10 ms of the pile under --preview: every step is solved (none raises,
    so none would be retried) and the total energy never exceeds its start."""
    sim = Simulation(load_scene(PILE, ['solver.mode="preview"', "time.steps=4"]))
    p = sim.problem
    state = sim.initial_state()
    p.u.x.array[:], p.v.x.array[:] = state.u, state.v
    start = p.energies()["total_energy"]
    for _ in range(4):
        state, stats = sim.step(state, 0.01)
        assert stats.reason > 0
        p.u.x.array[:], p.v.x.array[:] = state.u, state.v
        assert p.energies()["total_energy"] <= start + 1e-9 * abs(start)
