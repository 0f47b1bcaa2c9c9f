"""The Hessian form assembled through a d x d block matrix
(:meth:`fem_anim.problem.matrices.Matrices.assemble_form_matrix`).

The block (BAIJ) assembly added into the AIJ Hessian must give the direct AIJ assembly's
entries bit for bit, on the same pattern:

* on a bar with a moving pin (the pinned rows and columns are the identity's), serially and
  under ``mpirun -n 3`` (the script at the end; rows owned by one rank, ghost cells
  assembled by another; there a few entries differ in the last bit: the other ranks'
  contributions are summed in another order);
* on two boxes in contact (the stack of ``tests/test_contact_pace.py``: the Hessian's
  pattern grown by the contact pairs), where a Cholesky factorisation set up before it keeps
  its symbolic analysis (the pattern's state did not change: MUMPS redoes only the numeric
  factorisation), and every Hessian of the run went through the block matrix (the saving: docs/contact.md, "Cost per Newton iteration").
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
from conftest import run_file_under_mpirun
from mpi4py import MPI
from petsc4py import PETSc
from test_constant_terms import PIN_VELOCITY, SCENE
from test_contact_pace import STACK

import fem_anim.problem.matrices as matrices
from fem_anim import compat
from fem_anim.scene import load_scene
from fem_anim.scene.loading import Scene
from fem_anim.simulation.loop import Simulation


def _csr(A: PETSc.Mat):
    indptr, indices, values = A.getValuesCSR()
    return indptr.copy(), indices.copy(), values.copy()


def _same(a, b) -> bool:
    return all(np.array_equal(u, v) for u, v in zip(a, b))


def check_pinned(comm: MPI.Comm) -> list[str]:
    """The pinned bar's Hessian at a perturbed state: blocked against direct (this rank's
    rows); one line per failure, the same on every rank."""
    sim = Simulation(load_scene(None, SCENE), comm)
    p = sim.problem
    rng = np.random.default_rng(comm.rank)
    n = p.u.x.array.size
    p.set_pinned_displacement(0.25)
    p.weight.value = 1.0 / 240.0
    p.u.x.array[:] = np.tile(0.25 * PIN_VELOCITY, n // 3) + 0.002 * rng.standard_normal(n)
    p.u.x.scatter_forward()
    x = compat.petsc_vec(p.u).copy()
    A = p.create_matrix()
    count = p.blocked_assemblies
    p.jacobian(None, x, A, A)  # through the block matrix
    blocked = _csr(A)
    saved = matrices.BLOCKED_ASSEMBLY
    matrices.BLOCKED_ASSEMBLY = False
    try:
        p.jacobian(None, x, A, A)  # directly into the AIJ matrix
    finally:
        matrices.BLOCKED_ASSEMBLY = saved
    direct = _csr(A)
    failures = []
    if not comm.allreduce(p.blocked_assemblies == count + 1, op=MPI.LAND):
        failures.append("the Hessian did not go through the block matrix")
    # serially bit for bit; under MPI other ranks' contributions are summed in another order
    same = _same(blocked, direct) if comm.size == 1 else \
        _same(blocked[:2], direct[:2]) and np.allclose(blocked[2], direct[2], rtol=1e-14,
                                                       atol=1e-14 * np.abs(direct[2]).max())
    if not comm.allreduce(same, op=MPI.LAND):
        failures.append("the blocked Hessian differs from the direct one")
    if not comm.allreduce(np.count_nonzero(direct[2]) > 0, op=MPI.LOR):
        failures.append("the Hessian is zero")
    A.destroy()
    x.destroy()
    return failures


def test_blocked_hessian_equals_the_direct_one_with_pins():
    assert check_pinned(MPI.COMM_WORLD) == []


@pytest.mark.mpi
def test_blocked_hessian_under_mpi(tmp_path):
    """The same on three ranks."""
    run_file_under_mpirun(__file__, 3, tmp_path)


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
    assert _same(blocked, direct)  # bit for bit, same pattern
    assert np.count_nonzero(direct[2]) > 0
    ksp.destroy()
    x.destroy()


if __name__ == "__main__":
    failures = check_pinned(MPI.COMM_WORLD)
    if MPI.COMM_WORLD.rank == 0:
        print("\n".join(failures) or "blocked assembly: equal")
    sys.exit(1 if failures else 0)
