"""A table of ``solver.hessian_update`` and the budget options, side by side in one process.

Usage (from the repository's top; the default scene unless a scene file is given)::

    .venv/bin/python tests/tools/hessian_update_table.py [SCENE.toml] [--steps N]
    .venv/bin/python tests/tools/hessian_update_table.py --set KEY=VALUE [--set ...]

Runs the scene once per option below, in this order, each with a fresh
:class:`~fem_anim.simulation.loop.Simulation` (forms from FFCx's disk cache after the first), and
prints a Markdown table: Newton iterations, Hessian assemblies and factorisations (PCSetUp
events) per step, retries, the solve's wall time per step, and the final displacement's
relative L2 distance to the exact-Newton run. Serial only (the distance is over the
local dofs). Not a test (no ``test_`` prefix).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from mpi4py import MPI

from fem_anim.scene import load_scene
from fem_anim.simulation.adaptive import AdaptiveStepper
from fem_anim.simulation.loop import Simulation

#: (label, solver keys); the first is the reference.
OPTIONS = [
    ("exact Newton", {}),
    ("every_step", {"hessian_update": "every_step"}),
    ("lagged, lag 2", {"hessian_update": "lagged", "hessian_lag": 2}),
    ("lagged, lag 4", {"hessian_update": "lagged", "hessian_lag": 4}),
    ("rest (Newton)", {"hessian_update": "rest"}),
    ("rest + L-BFGS", {"hessian_update": "rest", "method": "lbfgs"}),
    ("every_step + L-BFGS", {"hessian_update": "every_step", "method": "lbfgs"}),
    ("budget 2, accept", {"max_iterations": 2, "on_budget": "accept"}),
    ("budget 1, accept", {"max_iterations": 1, "on_budget": "accept"}),
]


def run(scene, steps: int) -> tuple[np.ndarray, list[dict], float]:
    sim = Simulation(scene, MPI.COMM_WORLD)
    h = scene["time"]["dt"]
    stepper = AdaptiveStepper(sim, h, scene["time"])
    state, rows = sim.initial_state(), []
    start = time.perf_counter()
    for state, row in stepper.advance(state, steps * h):
        rows.append(row)
    wall = time.perf_counter() - start
    return state.u, rows, wall


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("scene", nargs="?")
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--set", dest="overrides", action="append", default=[])
    args = parser.parse_args()
    print("| option | Newton its / step | assemblies / step | factorisations / step | "
          "retries | solve wall / step | final u vs exact |")
    print("|---|---|---|---|---|---|---|")
    reference = None
    for label, keys in OPTIONS:
        overrides = args.overrides + [f"solver.{k}={v}" for k, v in keys.items()]
        try:  # a refused combination or a failing option is a row of the table too
            u, rows, _ = run(load_scene(args.scene, overrides), args.steps)
        except Exception as err:
            print(f"| {label} | failed: {str(err)[:80]} | | | | | |")
            continue
        n = len(rows)

        def per_step(key, rows=rows, n=n):
            return sum(r[key] for r in rows) / n

        if reference is None:
            reference = u
        dist = np.linalg.norm(u - reference) / np.linalg.norm(reference)
        print(f"| {label} | {per_step('newton_its'):.2f} | {per_step('hessian_assemblies'):.2f}"
              f" | {per_step('factorisations'):.2f} | {sum(r['retries'] for r in rows)} | "
              f"{1e3 * per_step('solve_wall_s'):.1f} ms | {dist:.1e} |", flush=True)


if __name__ == "__main__":
    main()
