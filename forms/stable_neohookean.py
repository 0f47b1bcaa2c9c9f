r"""Stable neo-Hookean elasticity (Smith, de Goes & Kim 2018, "Stable Neo-Hookean Flesh
Simulation", ACM TOG 37(2)); a neo-Hookean variant for seed §4.4 defined for every ``F``.

.. math::

    \psi(F) = \frac{\mu'}{2} (I_C - d) + \frac{\lambda'}{2} (J - \alpha)^2
              - \frac{\mu'}{2} \ln(I_C + 1) - c_0,
    \qquad \alpha = 1 + \frac{d}{d + 1} \frac{\mu'}{\lambda'},

with ``c0 = lmbda'/2 (1 - alpha)^2 - mu'/2 ln(d + 1)`` so that ``psi(I) = 0``; ``alpha`` makes
``F = I`` stationary. There is no ``ln J``: the density is smooth for every ``F``, including
``J <= 0`` (inverted elements are pushed back by the ``(J - alpha)^2`` term), so no step filter
is needed.

Lamé remap. ``(mu', lmbda')`` are chosen so that the Hessian at ``F = I`` equals that of linear
elasticity (seed §4.4.1) with the user's ``(mu, lmbda)``. Expanding ``psi(I + H)`` to second
order gives ``mu' d/(d+1) eps:eps + (lmbda' + 2 mu'/(d+1)^2 - mu' d/(d+1)) tr(H)^2 / 2``, hence

* 3D (the values of Smith et al.): ``mu' = 4/3 mu``, ``lmbda' = lmbda + 5/6 mu``;
* 2D (same matching): ``mu' = 3/2 mu``, ``lmbda' = lmbda + 2/3 mu``;

in general ``mu' = (d+1)/d mu`` and ``lmbda' = lmbda + mu - 2 mu / (d (d+1))``.
"""

from __future__ import annotations

import math

import ufl
from ufl.core.expr import Expr

from fem_anim.forms.kinematics import dimension, invariants

__all__ = ["psi", "remap_lame"]


def remap_lame(mu: Expr | float, lmbda: Expr | float, d: int) -> tuple[Expr | float, Expr | float]:
    """Return ``(mu', lmbda')`` that give the linear-elastic rest Hessian (see module docstring).

    Args:
        mu: Shear modulus of the linear model to match.
        lmbda: First Lamé parameter of the linear model to match.
        d: Dimension, 2 (plane strain) or 3.

    Returns:
        ``((d+1)/d mu, lmbda + mu - 2 mu/(d(d+1)))``: ``(4/3 mu, lmbda + 5/6 mu)`` in 3D and
        ``(3/2 mu, lmbda + 2/3 mu)`` in 2D.
    """
    return (d + 1) / d * mu, lmbda + (1 - 2 / (d * (d + 1))) * mu


def psi(F: Expr, mu: Expr | float, lmbda: Expr | float) -> Expr:
    """Strain energy density of stable neo-Hookean, remapped from the original Lamé parameters.

    Args:
        F: ``d x d`` deformation gradient (any sign of ``det F``), ``d`` = 2 or 3.
        mu: Shear modulus (original, not remapped).
        lmbda: First Lamé parameter (original, not remapped).

    Returns:
        ``mu'/2 (I_C - d) + lmbda'/2 (J - alpha)^2 - mu'/2 ln(I_C + 1) - c0``.
    """
    d = dimension(F)
    mu_, lmbda_ = remap_lame(mu, lmbda, d)
    alpha = 1 + d / (d + 1) * mu_ / lmbda_
    c0 = lmbda_ / 2 * (1 - alpha) ** 2 - mu_ / 2 * math.log(d + 1)
    I_C, _, J = invariants(F)
    return mu_ / 2 * (I_C - d) + lmbda_ / 2 * (J - alpha) ** 2 - mu_ / 2 * ufl.ln(I_C + 1) - c0
