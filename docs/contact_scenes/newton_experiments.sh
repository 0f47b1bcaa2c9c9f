#!/bin/bash
# Newton iterations of a contact scene under variants of the Newton loop, and where they go
# (docs/contact.md, "Where a pile's Newton iterations go: the far phase"). Run from the
# repository root:
#     bash docs/contact_scenes/newton_experiments.sh SCENE STEPS [VARIANT ...]
#     bash docs/contact_scenes/newton_experiments.sh SCENE STEPS --phases
exec .venv/bin/python - "$@" <<'PY'
"""Each variant is the current code with one change made here, in this process, stepped for
STEPS steps of the scene (one Simulation each, one after the other): Newton iterations a step
(exact and repeatable), this process's CPU seconds a step (noisy on a shared machine), and the
largest difference of the final displacement from the first variant's.

Variants: ``now``; ``expand`` (before PETSc's backtracking, the Newton step is doubled, up to
16x and within the collision-free bound of the longer step, while the step objective keeps
falling: an extrapolating line search); ``expand_stalled`` (the same, only after an iteration
that did not halve ||r||); ``exact_if_pd`` (every iteration first assembles the
barrier's and friction's exact Hessian and keeps it where MUMPS's factorisation has no
negative pivot, INFOG(12), else IPC's projection); ``set:KEY=VALUE`` (a scene override, e.g.
``set:contact.stiffness=1000``).

``--phases``: every Newton direction of the current code classified by ||r|| over the largest
force term at its iterate (``EnergyProblem.force_scale``), by ||p||_inf over the step test's
size, whether the CCD or the line search shortened it, and whether the barrier's exact
Hessian gave it.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from petsc4py import PETSc

from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation
from fem_anim.solver import hessian_choice, minimiser
from fem_anim.solver.step_bounds import step_limit

PRECHECK = minimiser.Minimiser._precheck
JACOBIAN = hessian_choice.HessianChoice.jacobian
INIT = minimiser.Minimiser.__init__


def expand_step(m, x, y, most=16.0):
    """Double y while g(x - y) keeps falling, within the CCD bound of the longest step."""
    longest = y.copy()
    longest.scale(most)
    cap = most * step_limit(m.problem, x, longest)
    longest.destroy()
    m.problem.set_state(x)
    if cap < 2.0:
        return False
    trial = x.duplicate()
    x.copy(trial)
    trial.axpy(-1.0, y)
    g, factor = m.objective(m.snes, trial), 1.0
    while 2.0 * factor <= cap:
        x.copy(trial)
        trial.axpy(-2.0 * factor, y)
        longer = m.objective(m.snes, trial)
        if not longer < g:
            break
        factor, g = 2.0 * factor, longer
    trial.destroy()
    m.problem.set_state(x)
    if factor > 1.0:
        y.scale(factor)
    return factor > 1.0


def expanding_precheck(self, x, y):
    changed = PRECHECK(self, x, y)
    history = self.stop.history  # (||r||, g) of each iterate of the step
    stalled = len(history) >= 2 and history[-1][0] >= 0.5 * history[-2][0]
    if changed or (self.expand_when == "stalled" and not stalled):
        return changed
    return expand_step(self, x, y)


def init(self, *args, **kwargs):
    INIT(self, *args, **kwargs)
    self.hessian.minimiser = self


def exact_if_pd(self, snes, x, A, P):
    m, ipc = self.minimiser, self.problem.ipc
    if not (m._exact_ok and not m._exact_on):
        return JACOBIAN(self, snes, x, A, P)
    ipc.exact_hessian(True)
    JACOBIAN(self, snes, x, A, P)
    ksp = snes.getKSP()
    ksp.setOperators(A, A)
    ksp.getPC().setUp()
    if ksp.getPC().getFactorMatrix().getMumpsInfog(12) > 0:
        ipc.exact_hessian(False)
        self.its["exact"] -= 1
        JACOBIAN(self, snes, x, A, P)


def run(path: str, steps: int, variant: str):
    minimiser.Minimiser._precheck = expanding_precheck if variant.startswith("expand") \
        else PRECHECK
    minimiser.Minimiser.expand_when = "stalled" if variant == "expand_stalled" else "always"
    minimiser.Minimiser.__init__ = init
    hessian_choice.HessianChoice.jacobian = exact_if_pd if variant == "exact_if_pd" \
        else JACOBIAN
    overrides = [f"time.steps={steps}"] + ([variant[4:]] if variant.startswith("set:") else [])
    scene = load_scene(path, overrides=overrides)
    sim = Simulation(scene)
    state = sim.initial_state()
    its, cpu = [], time.process_time()
    for _ in range(steps):
        state, stats = sim.step(state, scene["time"]["dt"])
        its.append(stats.newton_its)
    cpu = (time.process_time() - cpu) / steps
    sim.minimiser.destroy()
    return its, cpu, state.u.copy()


def phases(path: str, steps: int) -> None:
    log = []

    def traced(self, x, y):
        if log and log[-1]["alpha"] is None and log[-1]["x"] is not None:
            x0, y0 = log[-1]["x"], log[-1]["y"]
            log[-1]["alpha"] = (x0 - x).dot(y0) / y0.dot(y0)
        full = y.norm(PETSc.NormType.INFINITY)
        entry = {"rF": self.b.norm() / self.problem.force_scale(x), "exact": self._exact_on,
                 "p": None, "ccd": None, "alpha": None}
        changed = PRECHECK(self, x, y)
        entry.update(p=full / self.stop.step_scale,
                     ccd=y.norm(PETSc.NormType.INFINITY) / full, x=x.copy(), y=y.copy())
        log.append(entry)
        return changed

    minimiser.Minimiser._precheck = traced
    scene = load_scene(path, overrides=[f"time.steps={steps}"])
    sim = Simulation(scene)
    state = sim.initial_state()
    total, last = 0, []
    for _ in range(steps):
        for e in log:
            e["x"] = e["y"] = None
        state, stats = sim.step(state, scene["time"]["dt"])
        total += stats.newton_its
        last.append(log[-1]["rF"])  # where the step's last direction started
        if log and log[-1]["alpha"] is None:
            log[-1]["alpha"] = 1.0  # the last direction's line search ended the step
    n = len(log)
    count = lambda test: f"{sum(map(test, log))} ({100 * sum(map(test, log)) / n:.0f} %)"  # noqa
    print(f"{steps} steps, {total} Newton iterations ({total / steps:.2f} a step), {n} directions")
    print("||r|| / largest force >= 0.1:", count(lambda e: e["rF"] >= 0.1))
    print("  in [1e-2, 0.1):", count(lambda e: 1e-2 <= e["rF"] < 0.1))
    print("  < 1e-2:", count(lambda e: e["rF"] < 1e-2))
    print("||p||_inf > 100x the test's size:", count(lambda e: e["p"] > 100))
    print("  in (10, 100]:", count(lambda e: 10 < e["p"] <= 100))
    print("  <= 10:", count(lambda e: e["p"] <= 10))
    print("shortened by the CCD:", count(lambda e: e["ccd"] < 0.999))
    print("shortened by the line search:", count(lambda e: e["alpha"] < 0.999))
    print("the barrier's exact Hessian:", count(lambda e: e["exact"]))
    print("steps whose last direction starts at ||r|| / largest force in [1e-6, 1e-3]:",
          sum(1e-6 <= r <= 1e-3 for r in last), "of", steps)


def main(argv: list[str]) -> None:
    path, steps = argv[0], int(argv[1])
    if "--phases" in argv:
        phases(path, steps)
        return
    variants = argv[2:] or ["now", "expand", "exact_if_pd"]
    first = None
    for variant in variants:
        its, cpu, u = run(path, steps, variant)
        first = u if first is None else first
        print(f"{variant}: {np.mean(its):.2f} Newton its/step (max {max(its)}), "
              f"CPU {cpu:.3f} s/step, final displacement vs {variants[0]} "
              f"{np.max(np.abs(u - first)):.2e} m", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
PY
