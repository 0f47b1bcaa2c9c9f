r"""Linear (small-strain) elasticity, seed §4.4.1.

.. math::

    \psi(F) = \mu\, \varepsilon : \varepsilon + \frac{\lambda}{2} (\operatorname{tr} \varepsilon)^2,
    \qquad \varepsilon = \operatorname{sym}(F) - I.

Seed eq. (35), :math:`\psi = \|F - I\|_F^2`, is the unsymmetrised, single-parameter version; the
symmetric part drops the infinitesimal-rotation (skew) part of ``F - I`` so that small rotations
cost nothing. Large rotations still cost energy: ``psi(QF) != psi(F)`` (seed eq. 36). Quadratic
in ``F``, defined for every ``F`` (including inverted ones, ``J <= 0``), whose Hessian is the
rest Hessian that every other model here reproduces at ``F = I``.
"""

from __future__ import annotations

import ufl
from ufl.core.expr import Expr

from fem_anim.forms.kinematics import small_strain

__all__ = ["psi"]


def psi(F: Expr, mu: Expr | float, lmbda: Expr | float) -> Expr:
    """Strain energy density of linear elasticity (seed §4.4.1).

    Args:
        F: ``d x d`` deformation gradient, ``d`` = 2 (plane strain) or 3.
        mu: Shear modulus.
        lmbda: First Lamé parameter.

    Returns:
        ``mu eps:eps + lmbda/2 tr(eps)^2`` with ``eps = sym(F) - I``.
    """
    eps = small_strain(F)
    return mu * ufl.inner(eps, eps) + lmbda / 2 * ufl.tr(eps) ** 2
