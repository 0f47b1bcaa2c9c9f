"""Each written step's residual, re-assembled from a finished run's files alone.

    python -m fem_anim.bench.step_residuals SCENE RUN_DIR

A step of implicit Euler is the minimiser of seed eq. (4) with w = h^2, so its first-order
condition (seed section 3.2, "Optimization Problems") is

    r = M (x - y) + h^2 (grad E(x) + kappa grad B(x)) = 0,   y = x_n + h v_n,

with M the mass matrix, E the potential (elastic, gravity, obstacles' barrier and friction)
and B the IPC barrier of the surfaces (and their lagged friction) at the barrier stiffness
kappa the step used. :func:`step_residuals` rebuilds x_n, v_n and x from the run's
trajectory (v_{n} = (x_n - x_{n-1}) / h, the scene's initial velocity for the first step),
kappa and d-hat from ``stats.csv``, and returns for each step ||r|| over its largest force
term: inertia M (x - y) and the momenta h M v_{n+1} = M (x - x_n), h M v_n = M (y - x_n) it
is the difference of, gravity, the rest of the potential's gradient, and the barrier's. The
solver's step test and force check ask at most 1e-6 (docs/contact.md, "Newton that
settles"); ``tests/test_contact_pace.py`` asserts it on the runs it writes, and the command
above prints it as a Markdown table for any run.

Contract: a serial run of implicit Euler written with every step (``output.every = 1``),
without damping; the scene given is the one the run was made from (its ``time.steps`` need
not match: the rows of ``stats.csv`` decide).
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["StepResidual", "step_residuals", "main"]


@dataclass(frozen=True)
class StepResidual:
    """One step's re-derived residual.

    Attributes:
        step: the step's number in ``stats.csv``.
        newton_its: its Newton iterations (``stats.csv``).
        snes_reason: SNES's converged reason (5: the step test met; 6: the round-off floor).
        ratio: ||r|| over the largest force term of the step.
        dhat_matches: whether ``stats.csv``'s d-hat equals the one the scene sets up.
    """

    step: int
    newton_its: int
    snes_reason: str
    ratio: float
    dhat_matches: bool


def step_residuals(scene, out: str | Path) -> list[StepResidual]:
    """Re-assemble every written step's residual of run ``out`` made from ``scene``.

    Args:
        scene: the :class:`~fem_anim.scene.loading.Scene` the run was made from.
        out: the run directory (``trajectory``, ``stats.csv``).

    Returns:
        One :class:`StepResidual` per row of ``stats.csv``, in order.

    Raises:
        ValueError: the run has not one frame more than steps (not written every step).
    """
    from dolfinx.fem import petsc as fem_petsc
    from petsc4py import PETSc

    from fem_anim.runs import open_run
    from fem_anim.simulation.loop import Simulation

    with open(Path(out) / "stats.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    sim = Simulation(scene)
    p, g = sim.problem, sim.gather
    written = open_run(str(out))

    def dofs(frame: np.ndarray) -> np.ndarray:
        u = np.zeros(p.u.x.array.size)
        u.reshape(-1, g.bs)[g.node_to_dof] = frame[g.input_index]
        return u

    frames = [dofs(written.displacement(k)) for k in range(len(written.times))]
    if len(frames) != len(rows) + 1:
        raise ValueError(f"{out}: {len(frames)} frames for {len(rows)} steps; the check "
                         "needs every step written (output.every = 1)")
    M = fem_petsc.assemble_matrix(p.mass_form)
    M.assemble()
    vec = lambda a: PETSc.Vec().createWithArray(a.copy())  # noqa: E731
    v0 = sim.initial_state().v.copy()
    result = []
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
        # w grad E but gravity: elastic, and the obstacles' barrier and lagged friction
        # (friction is no potential: the residual's form has it, grad E's does not)
        elastic = fem_petsc.assemble_vector(p.residual_form)
        elastic.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        barrier = vec(np.zeros_like(x))
        p.ipc.add_gradient(barrier, w)
        terms = [inertia, gravity, elastic, barrier]
        r = sum(t.array for t in terms)
        momenta = [M.createVecLeft() for _ in range(2)]  # h M v_{n+1}, h M v_n
        M.mult(vec(x - u_n), momenta[0])
        M.mult(vec(y - u_n), momenta[1])
        largest = max(t.norm() for t in terms + momenta)
        result.append(StepResidual(int(row["step"]), int(row["newton_its"]),
                                   row["snes_reason"], float(np.linalg.norm(r) / largest),
                                   float(row["dhat"]) == p.ipc.dhat))
        for t in terms + momenta:
            t.destroy()
    M.destroy()
    return result


def main(argv: list[str] | None = None) -> int:
    """Print each step's residual of run ``RUN_DIR`` made from ``SCENE`` (Markdown).

    Returns:
        0, or 2 after one line naming a missing file or a bad scene or run.
    """
    from fem_anim.errors import FemAnimError, describe_os_error
    from fem_anim.scene import load_scene

    parser = argparse.ArgumentParser(prog="python -m fem_anim.bench.step_residuals",
                                     description="Each written step's residual over its largest force term.")
    parser.add_argument("scene", help="the scene file the run was made from")
    parser.add_argument("out", help="the run directory")
    args = parser.parse_args(argv)
    try:
        with open(Path(args.out) / "stats.csv", newline="") as f:
            steps = sum(1 for _ in csv.DictReader(f))
        scene = load_scene(args.scene, overrides=[f"time.steps={steps}"])
        residuals = step_residuals(scene, args.out)
    except OSError as err:
        print(f"fem-anim: error: {describe_os_error(err)}", file=sys.stderr)
        return 2
    except (FemAnimError, ValueError, KeyError) as err:
        print(f"fem-anim: error: {err}", file=sys.stderr)
        return 2
    print("| step | Newton its | SNES reason | ||r|| / largest force term |")
    print("|---|---|---|---|")
    for s in residuals:
        print(f"| {s.step} | {s.newton_its} | {s.snes_reason} | {s.ratio:.2e} |")
    print(f"largest: {max(s.ratio for s in residuals):.2e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
