"""The Hessian's pattern widened at once for new contact entries
(:meth:`fem_anim.problem.matrices.Matrices.grow_pattern`).

On the stack of ``tests/test_contact_pace.py`` (the upper box lands on the lower one,
new pairs appear over several Newton iterations): every Hessian is assembled without a
single reallocation inside ``MatSetValues`` (PETSc's ``mallocs`` count stays put; added one
by one, each new entry of a full row copied the whole matrix), the pattern was widened
more than once, and the run ends at the same state, bit for bit, as with the entries added
one by one (the same pattern, so the same factorisations, with MUMPS's symbolic analysis
redone as often: a re-preallocated matrix whose nonzero state did not change would keep a
stale analysis), and a Cholesky factorisation
set up before a widening redoes its symbolic analysis after it (the pattern's state
changed). Serial only: under ``mpirun -n 2`` (the script at the end) the entries are added
one by one, as before, and the run ends where the serial one's logic says (to round-off:
two runs of one scene on two ranks need not agree in the last bit).
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
from conftest import run_file_under_mpirun
from mpi4py import MPI
from petsc4py import PETSc
from test_contact_pace import STACK

import fem_anim.problem.matrices as matrices
from fem_anim.scene.loading import Scene
from fem_anim.simulation.loop import Simulation

STEPS = 8


def _run(comm: MPI.Comm, grow: bool):
    """The stack's steps: final local u, the reallocations inside each Hessian's insertion,
    the pattern's widenings. ``grow=False`` adds the entries one by one."""
    saved = matrices.GROW_AT_ONCE
    matrices.GROW_AT_ONCE = saved and grow
    try:
        sim = Simulation(Scene.from_toml(STACK.format(steps=STEPS)), comm)
        p, A = sim.problem, sim.minimiser.A
        assemble = p.jacobian
        reallocations = []

        def counted(snes, x, A_, P):
            before = A_.getInfo()["mallocs"] if A_.assembled else None
            assemble(snes, x, A_, P)
            if before is not None:
                reallocations.append(A_.getInfo()["mallocs"] - before)

        p.jacobian = counted
        state = sim.initial_state()
        for _ in range(STEPS):
            state, _ = sim.step(state, 0.01)
        assert A.getType() in ("seqaij", "mpiaij") and p.ipc.num_pairs > 0
        return state.u, reallocations, p.pattern_growths
    finally:
        matrices.GROW_AT_ONCE = saved


def check(comm: MPI.Comm) -> list[str]:
    """One line per failure, the same on every rank."""
    PETSc.Log.begin()  # (the minimiser starts the log too)
    symbolic = PETSc.Log.Event("MatCholFctrSym")
    before = symbolic.getPerfInfo()["count"]
    u, reallocations, growths = _run(comm, True)
    middle = symbolic.getPerfInfo()["count"]
    u_one, reallocations_one, growths_one = _run(comm, False)
    analyses, analyses_one = middle - before, symbolic.getPerfInfo()["count"] - middle
    failures = []
    # every widening is seen as a new pattern: MUMPS analyses at the same iterations
    if not comm.allreduce(analyses == analyses_one > 1, op=MPI.LAND):
        failures.append(f"{analyses} symbolic analyses (one by one: {analyses_one})")
    serial = comm.size == 1
    if not (growths > 1 if serial else growths == 0) or growths_one != 0:
        failures.append(f"pattern widened {growths} times (one by one: {growths_one})")
    if serial and not (len(reallocations) > 8 and max(reallocations) == 0):
        failures.append("a Hessian's insertion reallocated the matrix")
    if not comm.allreduce(max(reallocations_one) > 0, op=MPI.LOR):
        failures.append("one by one, no insertion reallocated: the check cannot fail")
    # serially bit for bit; two runs under MPI may differ in round-off (the reductions'
    # message order), with the entries added either way
    same = np.array_equal(u, u_one) if comm.size == 1 else \
        np.allclose(u, u_one, rtol=0.0, atol=1e-12 * max(np.abs(u_one).max(), 1e-3))
    if not comm.allreduce(same, op=MPI.LAND):
        failures.append(f"the final states differ by {np.abs(u - u_one).max():.3e} m")
    return failures


def test_contact_entries_widen_the_pattern_at_once():
    assert check(MPI.COMM_WORLD) == []


def test_a_widened_pattern_is_analysed_again():
    """A factorisation set up on the Hessian redoes its symbolic analysis after the
    pattern is widened (else MUMPS would factorise the new entries on a stale analysis)."""
    sim = Simulation(Scene.from_toml(STACK.format(steps=STEPS)))
    p, A = sim.problem, sim.minimiser.A
    state = sim.initial_state()
    for _ in range(STEPS):
        state, _ = sim.step(state, 0.01)
    x = p.x_work.copy()
    p.jacobian(None, x, A, A)
    ksp = PETSc.KSP().create(A.getComm())
    ksp.setOperators(A)
    ksp.setType("preonly")
    ksp.getPC().setType("cholesky")
    ksp.getPC().setFactorSolverType("mumps")
    ksp.setUp()
    symbolic = PETSc.Log.Event("MatCholFctrSym")
    before = symbolic.getPerfInfo()["count"]
    n = A.getSize()[0]
    far = np.array([0, n - 1], dtype=PETSc.IntType)  # an entry no pattern holds yet
    assert A.getValue(0, n - 1) == 0.0
    assert p.grow_pattern(A, far, far[::-1])
    p.jacobian(None, x, A, A)
    ksp.getPC().setUp()
    assert symbolic.getPerfInfo()["count"] == before + 1
    ksp.destroy()
    x.destroy()


@pytest.mark.mpi
def test_contact_entries_widen_the_pattern_at_once_under_mpi(tmp_path):
    """On two ranks the entries are added one by one (the matrix's pattern state is not
    safe to re-preallocate there): no widening, the same steps."""
    run_file_under_mpirun(__file__, 2, tmp_path)


if __name__ == "__main__":
    failures = check(MPI.COMM_WORLD)
    if MPI.COMM_WORLD.rank == 0:
        print("\n".join(failures) or "pattern: widened at once")
    sys.exit(1 if failures else 0)
