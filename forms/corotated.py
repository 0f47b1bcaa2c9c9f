r"""Corotated elasticity, seed §4.4.3 (fixing the reflection problem of §4.4.2).

.. math::

    \psi(F) = \mu \|F - R\|_F^2 + \frac{\lambda}{2} (J - 1)^2,

with ``R`` the rotation of the signed polar decomposition ``F = R S`` (``det R = +1``, ``S``
symmetric, indefinite when ``J < 0``). ``R`` maximises ``tr(R^T F)`` over rotations, and with
the signed singular values ``sigma_i`` of ``F`` (the smallest one negated when ``J < 0``)

.. math::

    \|F - R\|_F^2 = I_C - 2 s + d, \qquad s = \operatorname{tr} S = \textstyle\sum_i \sigma_i .

UFL has no SVD, so ``s`` is written without one:

* 2D: ``s^2 = I_C + 2 J`` exactly, so ``s = sqrt(I_C + 2 J)``. Smooth wherever
  ``s = sigma_1 + sigma_2 > 0``; at ``s = 0`` (``J <= 0`` with ``|sigma_1| = |sigma_2|``, e.g.
  the reflection ``diag(1, -1)``) the value is right but the sqrt has infinite slope and the
  stress and Hessian are inf/NaN.
* 3D: ``s`` is the largest real root of the quartic

  .. math:: f(s) = s^4 - 2 I_C s^2 - 8 J s + I_C^2 - 4 II_C,

  whose roots are ``±sigma_1 ± sigma_2 ± sigma_3`` with an even number of minus signs. The root
  ``s0`` is computed outside UFL (:func:`stretch_trace`, per quadrature point) and passed in as a
  terminal; ``psi`` uses the Chebyshev-corrected value

  .. math:: \tilde s = s_0 - \frac{f}{f'} - \frac{f'' f^2}{2 f'^3},
            \qquad f, f', f'' \text{ at } (s_0, F).

  As ``f(s0, F) = 0`` at the current ``F``, ``s~ = s0`` and its first and second derivatives
  with respect to ``F`` equal the implicit-function derivatives of the exact root, so the
  residual and the Newton Hessian are exact. ``f'(s0) = 8 (sigma_1 + sigma_2)(sigma_1 + sigma_3)
  (sigma_2 + sigma_3) > 0`` for ``J > 0``; it vanishes only where ``R`` is not unique and
  ``psi`` has a kink: ``J < 0`` with the two smallest singular values equal (e.g. the seed's
  reflection ``diag(1, 1, -1)``), or rank-one ``F``. There the kernel divides 0 by 0 (NaN).

:func:`psi_lagged` is a different, quasi-Newton method: ``R`` is a given (lagged) rotation
terminal, so the energy gradient is exact when ``R = polar_rotation(F)`` but the Hessian lacks
the ``-2 mu dR/dF`` term.
"""

from __future__ import annotations

import numpy as np
import ufl
from ufl.core.expr import Expr

from fem_anim.forms.kinematics import dimension, invariants

__all__ = [
    "polar_rotation",
    "psi",
    "psi_lagged",
    "stretch_quartic",
    "stretch_trace",
    "stretch_trace_expr",
]


def stretch_quartic(s: Expr, F: Expr) -> tuple[Expr, Expr, Expr]:
    """The 3D quartic ``f(s) = s^4 - 2 I_C s^2 - 8 J s + I_C^2 - 4 II_C`` and its s-derivatives.

    Args:
        s: Trial value of the stretch trace.
        F: ``3 x 3`` deformation gradient.

    Returns:
        ``(f, f', f'')`` at ``(s, F)``.
    """
    I_C, II_C, J = invariants(F)
    f = s**4 - 2 * I_C * s**2 - 8 * J * s + I_C**2 - 4 * II_C
    df = 4 * s**3 - 4 * I_C * s - 8 * J
    d2f = 12 * s**2 - 4 * I_C
    return f, df, d2f


def stretch_trace_expr(F: Expr, s0: Expr | None = None) -> Expr:
    """UFL expression for ``s = tr S``, the sum of the signed singular values of ``F``.

    Args:
        F: ``d x d`` deformation gradient.
        s0: 3D only: scalar terminal holding the exact root (:func:`stretch_trace`) at the
            current ``F``; ignored in 2D.

    Returns:
        ``sqrt(I_C + 2 J)`` in 2D; the Chebyshev-corrected root ``s~`` in 3D.
    """
    if dimension(F) == 2:
        I_C, _, J = invariants(F)
        return ufl.sqrt(I_C + 2 * J)
    if s0 is None:
        raise ValueError("corotated psi in 3D needs s0, the stretch trace at the current F")
    f, df, d2f = stretch_quartic(s0, F)
    return s0 - f / df - d2f * f**2 / (2 * df**3)


def psi(F: Expr, mu: Expr | float, lmbda: Expr | float, s0: Expr | None = None) -> Expr:
    """Strain energy density of corotated elasticity (seed §4.4.3).

    Args:
        F: ``d x d`` deformation gradient, ``d`` = 2 (plane strain) or 3.
        mu: Shear modulus.
        lmbda: First Lamé parameter.
        s0: Required in 3D: scalar terminal set to :func:`stretch_trace` of the current ``F``.

    Returns:
        ``mu (I_C - 2 s + d) + lmbda/2 (J - 1)^2``.
    """
    I_C, _, J = invariants(F)
    s = stretch_trace_expr(F, s0)
    return mu * (I_C - 2 * s + dimension(F)) + lmbda / 2 * (J - 1) ** 2


def psi_lagged(F: Expr, mu: Expr | float, lmbda: Expr | float, R: Expr) -> Expr:
    """Corotated density with a lagged rotation (quasi-Newton; not the exact Hessian).

    Args:
        F: ``d x d`` deformation gradient.
        mu: Shear modulus.
        lmbda: First Lamé parameter.
        R: ``d x d`` terminal holding a rotation, usually :func:`polar_rotation` of the last
            iterate; treated as constant by ``ufl.diff`` / ``ufl.derivative``.

    Returns:
        ``mu ||F - R||^2 + lmbda/2 (J - 1)^2``.
    """
    D = F - R
    return mu * ufl.inner(D, D) + lmbda / 2 * (ufl.det(F) - 1) ** 2


def _signed_svd(F_values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Batched SVD ``F = U diag(sigma) V^T`` with ``det U = det V = +1``, sigma signed."""
    F_values = np.asarray(F_values, dtype=np.float64)
    U, sigma, Vt = np.linalg.svd(F_values)
    flip = np.linalg.det(U) * np.linalg.det(Vt) < 0
    U[flip, :, -1] *= -1
    sigma[flip, -1] *= -1
    return U, sigma, Vt


def stretch_trace(F_values: np.ndarray) -> np.ndarray:
    """Sum of the signed singular values of each ``F`` (smallest negated where ``J < 0``).

    Args:
        F_values: Array of shape ``(n, d, d)``, ``d`` = 2 or 3.

    Returns:
        Array of shape ``(n,)``: ``s = tr(R^T F)``, the largest root of the quartic in 3D.
    """
    F_values = np.asarray(F_values, dtype=np.float64)
    # singular values only (no U, V: 1.5x faster); the smallest takes the sign of det F,
    # as in _signed_svd (det U det V = sign det F)
    sigma = np.linalg.svd(F_values, compute_uv=False)
    sigma[:, -1] *= np.where(np.linalg.det(F_values) < 0.0, -1.0, 1.0)
    return sigma.sum(axis=-1)


def polar_rotation(F_values: np.ndarray) -> np.ndarray:
    """Rotation ``R`` (``det R = +1``) of the signed polar decomposition ``F = R S``.

    Args:
        F_values: Array of shape ``(n, d, d)``, ``d`` = 2 or 3.

    Returns:
        Array of shape ``(n, d, d)``.
    """
    U, _, Vt = _signed_svd(F_values)
    return U @ Vt
