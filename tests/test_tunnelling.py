"""A body thrown so fast that its predictor lies wholly inside another stays outside.

The collision-free start of each step (u_n + alpha (y - u_n), alpha the CCD's step bound:
:func:`fem_anim.simulation.newton_start.collision_free_guess` for one mesh,
``JointSimulation._collision_free_start`` for a shell beside a solid) is what keeps a body
from tunnelling: if the predictor y (seed Section 3.1, the y of eq. 3; x_n + h v_n for
implicit Euler without gravity) lies wholly inside another body, more than d_hat from
its faces, the step objective there is finite (a rigid translation, no pair within d_hat)
and Newton would start, and stay, inside. No surface crosses another then, so only the
independent check's enclosure test (:func:`fem_anim.contact.intersection.enclosed_vertices`)
can see it. Each test asserts that the first predictor is such a state (so the CCD bound
is what is exercised) and that no frame has an intersection.
"""

from __future__ import annotations

import numpy as np

from fem_anim import compat
from fem_anim.contact.intersection import boundary_triangles, crossed_frames, intersecting
from fem_anim.scene import Scene, load_scene
from fem_anim.simulation.joint_loop import JointSimulation
from fem_anim.simulation.loop import Simulation

H, DHAT = 0.01, 1.0e-3

#: A 4 cm box thrown at 10 m/s down onto a 20 cm box 3 mm below it: its first predictor
#: lies 6 to 10 cm below the big box's top face, 8 cm from its sides.
BOX_INTO_BOX = f"""
name = "tunnel"
[time]
dt = {H}
steps = 3
integrator = "implicit_euler"
[contact]
dhat = {DHAT}
[[body]]
name = "big"
material = {{ youngs_modulus = 1e5, density = 1000 }}
[body.mesh]
shape = "box"
size = [0.2, 0.2, 0.2]
origin = [-0.1, -0.1, 0.0]
element_size = 0.1
[[body]]
name = "small"
material = {{ youngs_modulus = 1e5, density = 1000 }}
initial = {{ velocity = [0, 0, -10.0] }}
[body.mesh]
shape = "box"
size = [0.04, 0.04, 0.04]
origin = [-0.02, -0.02, 0.203]
element_size = 0.04
"""


def _inside_box_by(x: np.ndarray, lo, hi) -> float:
    """The smallest distance of the points x to the faces of the box [lo, hi] (m), negative
    if one is outside it."""
    return float(np.minimum(x - np.asarray(lo), np.asarray(hi) - x).min())


def test_a_small_box_thrown_into_a_big_one_stays_outside(tmp_path):
    """Two solid bodies in one mesh: the small box's first predictor lies inside the big
    box, more than d_hat from its faces; every frame of 3 steps is intersection free."""
    path = tmp_path / "tunnel.toml"
    path.write_text(BOX_INTO_BOX)
    sim = Simulation(load_scene(path))
    points, cells = sim.domain.points, sim.domain.cells
    state = sim.initial_state()
    small = points[:, 2] > 0.2 + 1e-9
    assert small.sum() > 0
    y = points + sim.gather.gather(sim.integrator.predictor(H, state)).reshape(-1, 3)
    assert _inside_box_by(y[small], [-0.1, -0.1, 0.0], [0.1, 0.1, 0.2]) > 10 * DHAT
    frames = [sim.gather.gather(state.u).reshape(-1, 3)]
    for _ in range(3):
        state, _ = sim.step(state, H)
        frames.append(sim.gather.gather(state.u).reshape(-1, 3))
    assert crossed_frames(points, cells, frames) == []
    assert (points + frames[-1])[small, 2].min() > (points + frames[-1])[~small, 2].max()


def test_a_small_cloth_thrown_into_a_cube_stays_outside():
    """A 4 cm sheet thrown at 5 m/s down onto a 10 cm cube pinned at its base, 3 mm above
    its top: the first predictor lies 4.7 cm deep in the cube, 3 cm from its sides; every
    step's union of the cube's boundary and the sheet is intersection free."""
    top = 0.1
    solid = {"name": "cube",
             "mesh": {"shape": "box", "size": [0.1, 0.1, top], "origin": [-0.05, -0.05, 0.0],
                      "element_size": 0.05},
             "material": {"model": "neohookean", "youngs_modulus": 2.0e4,
                          "poisson_ratio": 0.3, "density": 500.0},
             "time": {"dt": H, "steps": 3, "integrator": "implicit_euler"},
             "pin": [{"min": [-1.0, -1.0, -1e-6], "max": [1.0, 1.0, 1e-6]}]}
    shell = {"name": "cloth",
             "mesh": {"shape": "sheet", "size": [0.04, 0.04],
                      "origin": [-0.02, -0.02, top + 0.003], "element_size": 0.02},
             "shell": {"thickness": 1.0e-3},
             "material": {"model": "stvk", "youngs_modulus": 1.0e5, "poisson_ratio": 0.3,
                          "density": 300.0},
             "time": {"dt": H, "steps": 3, "integrator": "implicit_euler"},
             "initial": {"velocity": [0.0, 0.0, -5.0]},
             "contact": {"dhat": DHAT}}
    sim = JointSimulation(Scene.from_dict(solid), Scene.from_dict(shell))
    points, triangles, first = [], [], 0
    for part in sim.parts:  # the union surface from the cells alone (serial: P1 dofs)
        cells = compat.cell_dofs(part.V)
        points.append(part.V.tabulate_dof_coordinates())
        triangles.append((boundary_triangles(cells) if cells.shape[1] == 4 else cells) + first)
        first += len(points[-1])
    states = sim.initial_state()
    y = points[1] + sim.integrator.predictor(H, states[1]).reshape(-1, 3)
    assert _inside_box_by(y, [-0.05, -0.05, 0.0], [0.05, 0.05, top]) > 10 * DHAT
    points, triangles = np.concatenate(points), np.concatenate(triangles)
    for _ in range(3):
        states, _ = sim.step(states, H)
        x = points + np.concatenate([s.u.reshape(-1, 3) for s in states])
        assert not intersecting(x, triangles)
