"""Kinematics: deformation gradient, strain measures and invariants (seed §4.2, §4.4).

The deformation of the body maps material points to world points; its gradient
``F = I + grad(u)`` (seed §4.2, eq. 26 for a linear tetrahedron) is the only argument the energy
densities ``psi(F)`` of §4.4 take. All functions here are pure UFL and work for ``d = 2``
(plane strain) and ``d = 3``.
"""

from __future__ import annotations

import ufl
from ufl.core.expr import Expr

__all__ = [
    "deformation_gradient",
    "dimension",
    "green_strain",
    "invariants",
    "right_cauchy_green",
    "small_strain",
]


def dimension(F: Expr) -> int:
    """The dimension of a deformation gradient.

    Args:
        F: A ``d x d`` UFL tensor.

    Returns:
        ``d``.

    Raises:
        ValueError: if ``F`` is not 2x2 or 3x3.
    """
    d, e = F.ufl_shape
    if d != e or d not in (2, 3):
        raise ValueError(f"F must be 2x2 or 3x3, got shape {F.ufl_shape}")
    return d


def deformation_gradient(u: Expr) -> Expr:
    """Deformation gradient ``F = I + grad(u)`` (seed §4.2, eq. 26).

    Args:
        u: The displacement.
    """
    return ufl.Identity(len(u)) + ufl.grad(u)


def right_cauchy_green(F: Expr) -> Expr:
    """Right Cauchy-Green tensor ``C = F^T F``.

    Args:
        F: The deformation gradient.
    """
    return F.T * F


def green_strain(F: Expr) -> Expr:
    """Green-Lagrange strain ``E = (F^T F - I) / 2``, the StVK strain of seed eq. (37).

    Args:
        F: The deformation gradient.
    """
    return (F.T * F - ufl.Identity(dimension(F))) / 2


def small_strain(F: Expr) -> Expr:
    """Infinitesimal strain ``eps = sym(F) - I = sym(grad u)`` (seed §4.4.1).

    Args:
        F: The deformation gradient.
    """
    return ufl.sym(F) - ufl.Identity(dimension(F))


def invariants(F: Expr) -> tuple[Expr, Expr, Expr]:
    """Invariants ``(I_C, II_C, J)`` of ``C = F^T F``.

    ``I_C = tr C = sum sigma_i^2``, ``II_C = (tr(C)^2 - tr(C C)) / 2 = sum_{i<j} sigma_i^2
    sigma_j^2`` and ``J = det F`` (signed product of the singular values ``sigma_i`` of ``F``).

    Args:
        F: The deformation gradient.

    Returns:
        ``(I_C, II_C, J)``.
    """
    C = right_cauchy_green(F)
    I_C = ufl.tr(C)
    II_C = (I_C**2 - ufl.inner(C, C)) / 2
    return I_C, II_C, ufl.det(F)
