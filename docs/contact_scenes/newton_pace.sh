#!/bin/bash
# Side-by-side Newton iterations and seconds of a contact scene (docs/contact.md, "Where a
# pile's Newton iterations and seconds go); the Python below says how. Run from the
# repository root: bash docs/contact_scenes/newton_pace.sh SCENE STEPS [REPS] [--set KEY=VALUE]
exec .venv/bin/python - "$@" <<'PY'
"""Side by side, in one process, a scene stepped three ways: as before this page's changes
(corotated's quadrature data, a batched SVD, on every cell; the barrier's exact Hessian only
once a Newton step meets the stopping test's size), with the quadrature data on the cells
that read it alone, and as now (also the exact Hessian from 100x the test's size).

Run from the repository root (docs/contact.md, "Where a pile's Newton iterations and
seconds go"):

    bash docs/contact_scenes/newton_pace.sh SCENE STEPS [REPS] [--set KEY=VALUE]

With ``--profile`` instead, the current code's cProfile of steps 6 to the last (top 25 by
own time); with ``--trace 3,19,44`` each listed step's Newton iterations: the full step's
infinity norm, the CCD's bound on it, ||r|| over the largest force term at the iterate, and
the line search's alpha (the accepted step over the bounded direction). ``--before`` profiles or
traces the variant "before".

Otherwise prints, per variant and repetition, Newton iterations a step, seconds a step
(wall clock of ``Simulation.step``, and this process's CPU time, steadier on a shared
machine), the time in the quadrature data's refresh, and the largest difference of the
final displacement from the first variant's (0 for the quadrature change alone: the same
result; the Hessian change takes other iterates within the stopping test).
"""

from __future__ import annotations

import sys
import time

import numpy as np

from fem_anim.problem import quadrature
from fem_anim.solver import minimiser
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


EXACT_NEAR = minimiser.EXACT_NEAR
#: name -> (quadrature data on every cell, EXACT_NEAR)
VARIANTS = {"before": (True, 1.0), "quadrature cells": (False, 1.0),
            "now": (False, EXACT_NEAR)}


def run(scene, steps: int, every_cell: bool, near: float):
    EnergyTerms._cells_reading = (lambda self, key: None) if every_cell else _reading
    minimiser.EXACT_NEAR = near
    sim = Simulation(scene)
    state = sim.initial_state()
    h = scene["time"]["dt"]
    its, spent[0] = 0, 0.0
    start, cpu = time.perf_counter(), time.process_time()
    for _ in range(steps):
        state, stats = sim.step(state, h)
        its += stats.newton_its
    wall, cpu = time.perf_counter() - start, time.process_time() - cpu
    sim.minimiser.destroy()
    return its / steps, (wall / steps, cpu / steps), spent[0] / steps, state.u.copy()


def profile(scene, steps: int) -> None:
    import cProfile
    import pstats

    sim = Simulation(scene)
    state = sim.initial_state()
    for _ in range(5):
        state, _ = sim.step(state, scene["time"]["dt"])
    prof = cProfile.Profile()
    prof.enable()
    for _ in range(5, steps):
        state, _ = sim.step(state, scene["time"]["dt"])
    prof.disable()
    pstats.Stats(prof).sort_stats("tottime").print_stats(25)


def trace(scene, steps: int, shown: set[int]) -> None:
    from petsc4py import PETSc

    log, previous = [], []
    precheck = minimiser.Minimiser._precheck

    def traced(self, x, y):
        if previous:  # the last direction's alpha: x_{k+1} = x_k - alpha y_k
            x0, y0 = previous.pop()
            log[-1][3] = (x0 - x).dot(y0) / y0.dot(y0)
        full = y.norm(PETSc.NormType.INFINITY)
        force = self.b.norm() / self.problem.force_scale(x)
        changed = precheck(self, x, y)
        log.append([full, y.norm(PETSc.NormType.INFINITY) / full, force, None])
        previous.append((x.copy(), y.copy()))
        return changed

    minimiser.Minimiser._precheck = traced
    sim = Simulation(scene)
    state = sim.initial_state()
    for n in range(1, steps + 1):
        log.clear()
        previous.clear()
        state, stats = sim.step(state, scene["time"]["dt"])
        if n in shown:
            print(f"step {n}: {stats.newton_its} Newton iterations")
            for full, bound, force, alpha in log:
                print(f"  |p|_inf {full:.3e} m, CCD bound {bound:.3g}, |r|/force {force:.3e}, "
                      f"alpha {'-' if alpha is None else f'{alpha:.3g}'}")


def main(argv: list[str]) -> None:
    if "--profile" in argv or "--trace" in argv:
        path, steps = argv[0], int(argv[1])
        scene = load_scene(path, overrides=[f"time.steps={steps}"])
        if "--before" in argv:  # the variant "before"
            EnergyTerms._cells_reading = lambda self, key: None
            minimiser.EXACT_NEAR = 1.0
        if "--profile" in argv:
            profile(scene, steps)
        else:
            trace(scene, steps, {int(n) for n in argv[argv.index("--trace") + 1].split(",")})
        return
    path, steps = argv[0], int(argv[1])
    reps = int(argv[2]) if len(argv) > 2 and argv[2].isdigit() else 1
    overrides = [a for a in argv[2 + (len(argv) > 2 and argv[2].isdigit()):] if a != "--set"]
    scene = load_scene(path, overrides=[f"time.steps={steps}", *overrides])
    quadrature.QuadratureData.update = timed_update
    run(scene, 1, False, EXACT_NEAR)  # compile the forms before timing
    finals = {}
    for rep in range(reps):
        for name, (every_cell, near) in VARIANTS.items():
            its, per_step, refresh, finals[name] = run(scene, steps, every_cell, near)
            print(f"rep {rep}: {name}: {its:.2f} Newton its/step, {per_step[0]:.3f} s/step "
                  f"(CPU {per_step[1]:.3f} s/step), "
                  f"quadrature data {refresh:.3f} s/step, final displacement differs from "
                  f"before's by {np.max(np.abs(finals[name] - finals['before'])):.3g} m",
                  flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
PY
