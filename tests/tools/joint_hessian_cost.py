"""What the joint Hessian of a shell beside a solid costs, part by part (docs/cloth.md).

Runs ``demos/drape_soft.toml`` for 40 frames (the cloth lies on the block with contact
pairs) and prints where their time went (the parts' assemblies, the joint problem's own
work: copies and the barrier's evaluations with ipctk's detection, factorisations, ipctk's
whole time), then at the last state times, best of five, each part's own Hessian assembly
(:meth:`EnergyProblem.jacobian`), the copy of both into the joint matrix (CSR renumbered to
the joint layout), the barrier's Hessian and the whole joint assembly
(:meth:`fem_anim.problem.joint_objective.JointProblem.jacobian`)::

    .venv/bin/python tests/tools/joint_hessian_cost.py
"""

from __future__ import annotations

import time
import tomllib
from pathlib import Path

import numpy as np
from petsc4py import PETSc

from fem_anim.petsc_options import init_petsc

init_petsc([])

from fem_anim.scene import Scene  # noqa: E402
from fem_anim.simulation.adaptive import AdaptiveStepper  # noqa: E402
from fem_anim.simulation.joint_loop import JointSimulation, JointState  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def best(f, n: int = 5) -> float:
    """The fastest of ``n`` calls of ``f`` (s)."""
    times = []
    for _ in range(n):
        start = time.perf_counter()
        f()
        times.append(time.perf_counter() - start)
    return min(times)


def main() -> None:
    scene = Scene.from_dict(tomllib.loads((ROOT / "demos" / "drape_soft.toml").read_text()))
    sim = JointSimulation.from_scene(scene)
    state = JointState(sim.initial_state())
    stepper = AdaptiveStepper(sim, scene["time"]["dt"], scene["time"])
    rows = []
    start = time.perf_counter()
    for frame in range(1, 41):
        for state, row in stepper.advance(state, frame * scene["time"]["dt"]):
            rows.append(row)
    wall = time.perf_counter() - start
    p = sim.problem
    print(f"40 frames: {len(rows)} steps, {sum(r['newton_its'] for r in rows)} Newton "
          f"iterations, {wall:.1f} s; assembly of the solid {p.parts[0].assembly_s:.1f} s and "
          f"the shell {p.parts[1].assembly_s:.1f} s, the joint problem's own "
          f"{p._own_assembly_s:.1f} s, factorisations {sum(r['factor_s'] for r in rows):.1f} "
          f"s, ipctk {sum(r['contact_s'] for r in rows):.1f} s")
    x = p.create_vector()
    p.load_guess([s.u for s in state.parts], x)
    A = p.create_matrix()
    p.jacobian(None, x, A, A)
    p.split(x, p._x_parts)
    parts = [best(lambda k=k: p.parts[k].jacobian(None, p._x_parts[k], p._A_parts[k],
                                                  p._A_parts[k])) for k in range(2)]

    def copy() -> None:
        for k in range(2):
            rows, cols, vals = p._part_triplets(k, p._A_parts[k])
            unique, first = np.unique(rows, return_index=True)
            A.setValuesIJV(np.r_[first, rows.size].astype(PETSc.IntType),
                           cols.astype(PETSc.IntType), vals, addv=PETSc.InsertMode.ADD_VALUES,
                           rowmap=unique.astype(PETSc.IntType))
        A.assemble()

    copied = best(copy)
    barrier = best(lambda: (p.ipc.add_hessian(A, float(p.weight.value)), A.assemble()))
    joint = best(lambda: p.jacobian(None, x, A, A))
    print(f"Hessian assembly (s): solid {parts[0]:.4f}, shell {parts[1]:.4f}, copy of both "
          f"into the joint matrix {copied:.4f} ({copied / sum(parts):.2f} x the parts'), "
          f"barrier {barrier:.4f}, whole joint {joint:.4f}; {int(A.getInfo()['nz_used'])} "
          f"nonzeros, {p.ipc.num_pairs} contact pairs")


if __name__ == "__main__":
    main()
