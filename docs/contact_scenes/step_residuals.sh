#!/bin/bash
# Each written step's residual over its largest force term, re-assembled from a run's files
# (docs/contact.md, "The 4-box pile against today and against the baseline"). Run from the
# repository root: bash docs/contact_scenes/step_residuals.sh SCENE RUN_DIR
exec .venv/bin/python - "$@" <<'PY'
"""Re-assemble implicit Euler's residual M (x - y) + h^2 (grad E + kappa grad B) of every
step of a finished ``fem-anim run`` from its trajectory and stats.csv's barrier stiffness
alone (as ``tests/test_contact_pace.py::test_each_step_satisfies_its_equations_from_the_
written_outputs`` does), and print per step: Newton iterations, the SNES reason (5: the
step test met; 6: stopped at the round-off floor without meeting it) and ||r|| over the
largest force term (inertia, the momenta h M v_{n+1} and h M v_n, gravity, elastic and
obstacle, IPC barrier); the step test asks at most 1e-6. Serial; implicit Euler without
friction or damping (the bench's pile).

    bash docs/contact_scenes/step_residuals.sh SCENE RUN_DIR
"""

from __future__ import annotations

import csv
import sys

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim.runs import open_run
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation


def main(scene_path: str, out: str) -> None:
    rows = list(csv.DictReader(open(f"{out}/stats.csv", newline="")))
    scene = load_scene(scene_path, overrides=[f"time.steps={len(rows)}"])
    sim = Simulation(scene)
    p, g = sim.problem, sim.gather
    written = open_run(out)

    def dofs(frame):
        u = np.zeros(p.u.x.array.size)
        u.reshape(-1, g.bs)[g.node_to_dof] = frame[g.input_index]
        return u

    M = fem_petsc.assemble_matrix(p.mass_form)
    M.assemble()
    vec = lambda a: PETSc.Vec().createWithArray(a.copy())  # noqa: E731
    frames = [dofs(written.displacement(k)) for k in range(len(written.times))]
    v0 = sim.initial_state().v.copy()
    worst = 0.0
    print("| step | Newton its | SNES reason | ||r|| / largest force term |")
    print("|---|---|---|---|")
    for n, row in enumerate(rows):
        h = float(row["dt"])
        u_n, x = frames[n], frames[n + 1]
        v_n = (frames[n] - frames[n - 1]) / h if n else v0
        y = u_n + h * v_n
        w = h * h
        p.stage(u_n, y, w, float(row["time"]), h)
        p.u.x.array[:] = u_n
        p.ipc.restage(float(row["barrier_stiffness"]), h)
        p.u.x.array[:] = x
        p.update_quadrature_data()
        inertia = vec(x - y)
        M.mult(vec(x - y), inertia)
        gravity = p.constant_terms.gradient.copy()
        gravity.scale(w)
        potential = fem_petsc.assemble_vector(p.potential_gradient_form)
        potential.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        potential.scale(w)
        elastic = potential.copy()
        elastic.axpy(-1.0, gravity)
        barrier = vec(np.zeros_like(x))
        p.ipc.add_gradient(barrier, w)
        terms = [inertia, gravity, elastic, barrier]
        r = sum(t.array for t in terms)
        momenta = [M.createVecLeft() for _ in range(2)]
        M.mult(vec(x - u_n), momenta[0])
        M.mult(vec(y - u_n), momenta[1])
        ratio = np.linalg.norm(r) / max(t.norm() for t in terms + momenta)
        worst = max(worst, ratio)
        print(f"| {row['step']} | {row['newton_its']} | {row['snes_reason']} | {ratio:.2e} |")
    print(f"largest: {worst:.2e}")


if __name__ == "__main__":
    main(*sys.argv[1:3])
PY
