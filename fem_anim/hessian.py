"""Hessian modification for indefinite Newton systems (seed section 3.2.2, note 4).

Two remedies for a Hessian H of the step objective that is not positive definite (large
compression, buckling, inverting elements), selected by ``solver.hessian``:

``shift``
    A = H + c I (seed note 4), with c adapted: raised (doubled, from a floor relative to
    the diagonal of H) until the factorisation shows no negative pivot (MUMPS/PETSc
    Cholesky inertia), lowered (quartered) after each success so that Newton returns to
    the exact Hessian, and to quadratic convergence, as soon as H is positive definite.
``project``
    Projected Newton (Teran et al. 2005; Kim and Eberle, "Dynamic Deformables"): the
    material tangent d^2 psi/dF^2 (a d^2 x d^2 matrix per quadrature point) is evaluated by
    a compiled UFL expression, its negative eigenvalues are clamped to zero in one
    batched numpy ``eigh``, and the elastic Hessian is assembled from the projection by a
    UFL form. Each element's Hessian w G^T A G (seed eqs. 31-34) is then positive
    semi-definite, the inertia term adds M > 0, and every Newton direction is a descent
    direction. For P1 elements (one quadrature point) this is exactly the per-element
    projection of the F-space Hessian.

The mass and damping terms of the objective are convex and kept exact in both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["project_psd", "ShiftStrategy"]


def project_psd(tangent: np.ndarray) -> np.ndarray:
    """Clamp the negative eigenvalues of a stack of symmetric matrices to zero.

    Args:
        tangent: ``(n, m, m)`` matrices (symmetrised here against round-off).

    Returns:
        ``(n, m, m)`` positive semi-definite matrices V max(L, 0) V^T.
    """
    sym = 0.5 * (tangent + np.swapaxes(tangent, 1, 2))
    eigenvalues, vectors = np.linalg.eigh(sym)
    return np.einsum("nij,nj,nkj->nik", vectors, np.maximum(eigenvalues, 0.0), vectors)


@dataclass
class ShiftStrategy:
    """The adaptive shift c of A = H + c I (seed note 4).

    Attributes:
        floor: Smallest positive shift relative to max |diag H|.
        c: Current shift (absolute), kept between Newton iterations and steps.
        raises: Number of times c was raised (reported per step).
    """

    floor: float = 1e-8
    c: float = 0.0
    raises: int = 0

    def first(self, diagonal_scale: float) -> float:
        """The shift to try first: the remembered one (zero after enough successes)."""
        if self.c < self.floor * diagonal_scale:
            self.c = 0.0
        return self.c

    def raise_shift(self, diagonal_scale: float) -> float:
        """A failed factorisation: double c (at least the floor)."""
        self.raises += 1
        self.c = max(2.0 * self.c, self.floor * diagonal_scale)
        return self.c

    def succeeded(self) -> None:
        """A successful factorisation: lower c for the next attempt."""
        self.c *= 0.25
