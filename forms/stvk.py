r"""Saint Venant-Kirchhoff (StVK) elasticity, seed §4.4.2, eq. (37).

.. math::

    \psi(F) = \mu\, E : E + \frac{\lambda}{2} (\operatorname{tr} E)^2,
    \qquad E = \tfrac12 (F^T F - I).

Seed eq. (37), :math:`\|F^T F - I\|_F^2 = 4\, E : E`, is the case ``mu = 4, lmbda = 0``. The
density depends on ``F`` only through ``C = F^T F``, so it is rotation invariant but also
reflection invariant: ``psi(diag(1, 1, -1)) = psi(I) = 0`` (the reflection problem of §4.4.2),
and it softens and then collapses under strong compression. Defined (a polynomial) for every
``F``.
"""

from __future__ import annotations

import ufl
from ufl.core.expr import Expr

from fem_anim.forms.kinematics import green_strain

__all__ = ["psi"]


def psi(F: Expr, mu: Expr | float, lmbda: Expr | float) -> Expr:
    """Strain energy density of StVK (seed eq. 37).

    Args:
        F: ``d x d`` deformation gradient, ``d`` = 2 (plane strain) or 3.
        mu: Shear modulus.
        lmbda: First Lamé parameter.

    Returns:
        ``mu E:E + lmbda/2 tr(E)^2`` with ``E = (F^T F - I)/2``.
    """
    E = green_strain(F)
    return mu * ufl.inner(E, E) + lmbda / 2 * ufl.tr(E) ** 2
