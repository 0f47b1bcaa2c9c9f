"""KSPSTCG's trust region through :mod:`fem_anim.solver.trust_region` (ctypes), and the radius
rule :func:`fem_anim.solver.hessian_modification.trust_radius`, against closed-form answers."""

from __future__ import annotations

import numpy as np
import pytest
from petsc4py import PETSc

from fem_anim import compat

from fem_anim.solver import trust_region as ksp_trust_region
from fem_anim.solver.hessian_modification import trust_radius


def _diagonal(values) -> PETSc.Mat:
    n = len(values)
    A = PETSc.Mat().createAIJ([n, n], nnz=1, comm=PETSc.COMM_SELF)
    for i, v in enumerate(values):
        A[i, i] = v
    A.assemble()
    return A


def _stcg(diagonal, rhs, radius):
    """KSPSTCG on diag(diagonal) d = rhs, preconditioned by diag(|diagonal|) (positive
    definite, as auto's abs-filtered Hessian); the direction, the KSP's reason, norm and
    model value."""
    A, P = _diagonal(diagonal), _diagonal(np.abs(diagonal))
    ksp = PETSc.KSP().create(PETSc.COMM_SELF)
    ksp.setOperators(A, P)
    ksp.setType("stcg")
    ksp.getPC().setType("jacobi")
    ksp.setTolerances(rtol=1e-12, max_it=100)
    ksp_trust_region.set_radius(ksp, radius)
    b, d = A.createVecs()
    b.setArray(rhs)
    ksp.solve(b, d)
    out = (d.getArray().copy(), ksp.getConvergedReason(),
           ksp_trust_region.direction_norm(ksp), ksp_trust_region.model_value(ksp))
    for obj in (ksp, A, P, b, d):
        obj.destroy()
    return out


def test_positive_definite_inside_the_region_gives_the_newton_step():
    diagonal, rhs = np.array([4.0, 3.0, 2.0, 1.0]), np.ones(4)
    d, reason, norm, model = _stcg(diagonal, rhs, 100.0)
    assert reason > 0
    assert d == pytest.approx(rhs / diagonal, rel=1e-10)
    assert norm == pytest.approx(np.linalg.norm(d), rel=1e-12)
    assert model == pytest.approx(0.5 * d @ (diagonal * d) - rhs @ d, rel=1e-12)


@pytest.mark.parametrize("radius", [0.05, 0.5, 3.0])
def test_negative_curvature_goes_to_the_boundary_downhill(radius):
    """An indefinite matrix: the direction ends on ||d|| = radius (Euclidean, the norm PETSc
    3.18 and 3.22 use), the model 1/2 d^T A d - b^T d is the one reported and decreases."""
    diagonal, rhs = np.array([4.0, 3.0, 2.0, 1.0, -1.0, -2.0]), np.ones(6)
    d, reason, norm, model = _stcg(diagonal, rhs, radius)
    assert reason in compat.trust_region_boundary_reasons()
    assert np.linalg.norm(d) == pytest.approx(radius, rel=1e-10)
    assert norm == pytest.approx(radius, rel=1e-10)
    assert model == pytest.approx(0.5 * d @ (diagonal * d) - rhs @ d, rel=1e-10)
    assert model < 0.0 and rhs @ d > 0.0  # x - d is downhill for g


def test_negative_curvature_at_the_first_direction():
    """Where plain CG returns an ascent direction (p^T A p < 0 at once), STCG steps along
    the preconditioned gradient to the boundary, downhill."""
    diagonal, rhs = np.array([-1.0, -2.0, 3.0]), np.array([1.0, 1.0, 0.0])
    d, reason, norm, model = _stcg(diagonal, rhs, 0.3)
    assert reason == compat.trust_region_boundary_reasons()[0]
    assert np.linalg.norm(d) == pytest.approx(0.3, rel=1e-10)
    assert rhs @ d > 0.0 and model < 0.0


def test_trust_radius_rule():
    r = 1.0
    # model poor: a quarter of the step taken (full or shortened)
    assert trust_radius(r, 0.1, 1.0, 1.0) == pytest.approx(0.25)
    assert trust_radius(r, -3.0, 0.5, 0.8) == pytest.approx(0.25 * 0.4)
    # the line search shortened the direction: half of it if the model then held, else the step
    assert trust_radius(r, 0.9, 0.1, 0.8) == pytest.approx(0.4)
    assert trust_radius(r, 0.5, 0.1, 0.8) == pytest.approx(0.08)
    # a full step to the boundary: x2, x4 when the model was within 10 %
    assert trust_radius(r, 0.8, 1.0, 1.0) == pytest.approx(2.0)
    assert trust_radius(r, 1.05, 1.0, 0.995) == pytest.approx(4.0)
    # a full step inside the region, or a middling rho: unchanged
    assert trust_radius(r, 1.0, 1.0, 0.5) == r
    assert trust_radius(r, 0.5, 1.0, 1.0) == r
    assert trust_radius(r, float("nan"), 1.0, 1.0) == r
