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
that did not halve ||r||); ``exact_if_pd`` (every iteration first assembles the barrier's and
friction's exact Hessian and keeps it where MUMPS's factorisation has no negative pivot,
INFOG(12), else IPC's projection); ``irls_friction`` (the surfaces' lagged friction with the
Hessian of iteratively reweighted least squares, mu lambda w (f1(|u|)/|u|) Gamma^T T T^T Gamma
per pair: PSD, and stiff along the slip where the exact one has f1' = 0; a Python loop over
the pairs, so slow); ``irls_friction_far`` (the same only while the barrier's Hessian is
projected, the exact one near the solution); ``set:KEY=VALUE`` (a scene override, e.g.
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

from fem_anim.contact import ipc as ipc_module

STAGE_FRICTION = ipc_module.IPCContact._stage_friction
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


class ReweightedFriction:
    """ipctk's lagged friction with the Hessian of iteratively reweighted least squares:
    per pair mu lambda w (f1(|u|)/|u|) Gamma^T T T^T Gamma (u = T^T Gamma (x - x_n) the
    tangential slip; PSD, and stiff along the slip where the exact Hessian has f1' = 0)."""

    def __init__(self, potential, far_only):
        self.potential, self.far_only = potential, far_only

    def __call__(self, *args):
        return self.potential(*args)

    def __getattr__(self, name):
        return getattr(self.potential, name)

    def hessian(self, collisions, mesh, slip, projection=None):
        import ipctk
        import scipy.sparse as sp

        if self.far_only and projection == ipctk.PSDProjectionMethod.NONE:
            return self.potential.hessian(collisions, mesh, slip, projection)  # exact near

        eps = self.potential.eps_v
        dim = slip.shape[1]
        rows, cols, vals = [], [], []
        for c in collisions:
            ids = np.asarray(c.vertex_ids(mesh.edges, mesh.faces))
            G = np.asarray(c.relative_velocity_jacobian())
            T = np.asarray(c.tangent_basis)
            v = np.asarray(c.dof(slip, mesh.edges, mesh.faces)).ravel()
            y = np.linalg.norm(T.T @ (G @ v))
            ratio = (2.0 / eps - y / eps ** 2) if y < eps else 1.0 / y
            B = T.T @ G
            H = c.mu_k * c.normal_force_magnitude * c.weight * ratio * (B.T @ B)
            dofs = np.concatenate([np.arange(k * dim, k * dim + dim) for k in ids if k >= 0])
            n = dofs.size
            rows.append(np.repeat(dofs, n))
            cols.append(np.tile(dofs, n))
            vals.append(H[:n, :n].ravel())
        size = slip.size
        if not rows:
            return sp.csc_matrix((size, size))
        return sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows),
                                                     np.concatenate(cols))), (size, size))


def reweighted_stage(self, h):
    STAGE_FRICTION(self, h)
    self.friction = ReweightedFriction(self.friction, self.irls_far_only)


def run(path: str, steps: int, variant: str):
    ipc_module.IPCContact._stage_friction = reweighted_stage \
        if variant.startswith("irls_friction") else STAGE_FRICTION
    ipc_module.IPCContact.irls_far_only = variant == "irls_friction_far"
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
