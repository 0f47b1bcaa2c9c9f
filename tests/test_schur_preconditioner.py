"""The mixed formulation's Schur preconditioner is close to the Schur complement.

The contract (:class:`fem_anim.problem.mixed_space.SchurPreconditioner`): the matrix handed
to the ``schur`` preset's fieldsplit, P = -w mu (1 + mu/kappa) M_p, stands in for the Schur
complement S = C - B A^-1 B^T of the step's Hessian [[A, B^T], [B, C]]; the true S is
smaller than P under time stepping (the inertia in A), so the generalised eigenvalues
lambda of S v = lambda P v are real and in (0, 1]: P^-1 S is positive definite and GMRES
on the Schur system needs few iterations. A preconditioner of the wrong sign, scale or of a
stale step still lets FGMRES converge, only slower; it fails here. S is computed densely
from the assembled Hessian the step last solved with (a coarse 2D beam), not from the
preconditioner's own formula.

Measured (Debian 12, 2 steps of 1/30 s, nu = 0.4999): lambda in [0.137, 0.732] (ratio 5.4);
at dt = 1/120 s [0.014, 0.11], at 1/480 s [0.0011, 0.0082]: the pressure mass is the
quasi-static preconditioner, good when w K dominates M (module docstring).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
from mpi4py import MPI
from test_mixed import _mixed_scene

from fem_anim.simulation.loop import Simulation

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                reason="serial: dense blocks of the global Hessian")

#: Bounds on lambda(P^-1 S) at dt = 1/30 s, with a margin of 25 % on the measured
#: [0.137, 0.732]; the upper bound 1 is the theory's (inertia only makes S smaller).
LOWEST, HIGHEST, SPREAD = 0.1, 1.0, 7.0


def dense(matrix) -> np.ndarray:
    aij = matrix if matrix.getType() in ("aij", "seqaij", "mpiaij") else matrix.convert("aij")
    indptr, indices, values = aij.getValuesCSR()
    return sp.csr_matrix((values, indices, indptr), shape=aij.getSize()).toarray()


@pytest.mark.parametrize("nu", [0.5, 0.4999])
def test_schur_complement_against_its_preconditioner(tmp_path, nu):
    sim = Simulation(_mixed_scene(tmp_path, material={"poisson_ratio": nu},
                                  solver={"preset": "schur"}))
    state = sim.initial_state()
    for _ in range(2):  # the preconditioner of a later step, after several updates
        state, stats = sim.step(state, 1.0 / 30.0)
        assert stats.reason > 0
    H = dense(sim.minimiser.snes.getJacobian()[0])
    schur = sim.problem.schur
    iu, ip = schur.is_u.getIndices(), schur.is_p.getIndices()
    A, Bt = H[np.ix_(iu, iu)], H[np.ix_(iu, ip)]
    B, C = H[np.ix_(ip, iu)], H[np.ix_(ip, ip)]
    S = C - B @ np.linalg.solve(A, Bt)
    P = dense(schur.matrix)
    lam = scipy.linalg.eigvals(S, P)
    assert np.abs(lam.imag).max() <= 1e-10 * np.abs(lam.real).max()
    lam = lam.real
    assert LOWEST < lam.min() and lam.max() <= HIGHEST * (1.0 + 1e-10), (lam.min(), lam.max())
    assert lam.max() / lam.min() < SPREAD
    sim.minimiser.destroy()
