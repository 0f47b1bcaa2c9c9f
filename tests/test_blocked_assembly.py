"""The Hessian form assembled through a d x d block matrix
(:meth:`fem_anim.problem.matrices.Matrices.assemble_form_matrix`).

On two boxes in contact (the stack of ``tests/test_contact_pace.py``, the Hessian's pattern
grown by the contact pairs), the Hessian assembled through the block (BAIJ) matrix equals
the direct AIJ assembly entry by entry, bit for bit, on the same pattern, and a Cholesky
factorisation set up before it keeps its symbolic analysis (the pattern's state did not
change: MUMPS redoes only the numeric factorisation); and every Hessian of the run went
through the block matrix (the saving: docs/contact.md, "Cost per Newton iteration").
"""

from __future__ import annotations

import numpy as np
from petsc4py import PETSc
from test_contact_pace import STACK

import fem_anim.problem.matrices as matrices
from fem_anim.scene.loading import Scene
from fem_anim.simulation.loop import Simulation


def _csr(A: PETSc.Mat):
    indptr, indices, values = A.getValuesCSR()
    return indptr.copy(), indices.copy(), values.copy()


def test_blocked_hessian_equals_the_direct_one_and_keeps_the_pattern(monkeypatch):
    sim = Simulation(Scene.from_toml(STACK.format(steps=8)))
    state = sim.initial_state()
    assembled = 0
    for _ in range(8):
        state, stats = sim.step(state, 0.01)
        assembled += stats.hessian_assemblies
    p, A = sim.problem, sim.minimiser.A
    assert p.ipc.num_pairs > 0  # the upper box rests on the lower one
    assert A.getType() in ("seqaij", "mpiaij")
    # every Hessian of the run went through the block matrix
    assert assembled > 8 and p.blocked_assemblies >= assembled

    x = p.x_work.copy()
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("cholesky")
    ksp.getPC().setFactorSolverType("mumps")
    p.jacobian(None, x, A, A)
    ksp.setUp()
    symbolic = PETSc.Log.Event("MatCholFctrSym")
    before = symbolic.getPerfInfo()["count"]
    p.jacobian(None, x, A, A)  # through the block matrix
    blocked = _csr(A)
    ksp.getPC().setUp()
    assert symbolic.getPerfInfo()["count"] == before, "the blocked copy changed the pattern"

    monkeypatch.setattr(matrices, "BLOCKED_ASSEMBLY", False)
    count = p.blocked_assemblies
    p.jacobian(None, x, A, A)  # directly into the AIJ matrix
    assert p.blocked_assemblies == count
    direct = _csr(A)
    assert np.array_equal(blocked[0], direct[0]) and np.array_equal(blocked[1], direct[1])
    assert np.array_equal(blocked[2], direct[2])  # bit for bit
    assert np.count_nonzero(direct[2]) > 0
    ksp.destroy()
    x.destroy()
