"""Side by side, in one process: a scene stepped with corotated's quadrature data (its
batched SVD) evaluated on every cell (before) and on the corotated cells alone (now).

Run from the repository root (docs/contact.md, "Where a pile's step goes"):

    .venv/bin/python docs/contact_scenes/quadrature_cells.py demos/pile.toml 30 [--set KEY=VALUE ...]

Prints, per variant and repetition, Newton iterations a step, seconds a step (wall clock of
``Simulation.step``), the time in the quadrature data's refresh, and the largest difference of
the final displacement between the variants (0: the same result).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from fem_anim.problem import quadrature
from fem_anim.problem.energy_terms import EnergyTerms
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation

_reading = EnergyTerms._cells_reading
_update = quadrature.QuadratureData.update
spent = [0.0]


def timed_update(self):
    start = time.perf_counter()
    _update(self)
    spent[0] += time.perf_counter() - start


def run(scene, steps: int, every_cell: bool):
    EnergyTerms._cells_reading = (lambda self, key: None) if every_cell else _reading
    sim = Simulation(scene)
    state = sim.initial_state()
    h = scene["time"]["dt"]
    its, spent[0] = 0, 0.0
    start = time.perf_counter()
    for _ in range(steps):
        state, stats = sim.step(state, h)
        its += stats.newton_its
    wall = time.perf_counter() - start
    sim.minimiser.destroy()
    return its / steps, wall / steps, spent[0] / steps, state.u.copy()


def main(argv: list[str]) -> None:
    path, steps, overrides = argv[0], int(argv[1]), [a for a in argv[2:] if a != "--set"]
    scene = load_scene(path, overrides=[f"time.steps={steps}", *overrides])
    quadrature.QuadratureData.update = timed_update
    run(scene, 1, False)  # compile the forms before timing
    finals = {}
    for rep in range(2):
        for every_cell in (True, False):
            name = "every cell (before)" if every_cell else "reading cells (now)"
            its, per_step, refresh, finals[every_cell] = run(scene, steps, every_cell)
            print(f"rep {rep}: {name}: {its:.2f} Newton its/step, {per_step:.3f} s/step, "
                  f"quadrature data {refresh:.3f} s/step", flush=True)
    print(f"largest final displacement difference: "
          f"{np.max(np.abs(finals[True] - finals[False])):.3g} m")


if __name__ == "__main__":
    main(sys.argv[1:])
