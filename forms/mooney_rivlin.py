r"""Mooney-Rivlin elasticity, deviatoric part (Bonet & Wood [1] of the seed, ch. 6.6).

.. math::

    \psi_{dev}(F) = c_{10} (\bar I_1 - 3) + c_{01} (\bar I_2 - 3),
    \qquad \bar I_1 = J^{-2/3} I_1,\ \bar I_2 = J^{-4/3} I_2,

with ``I_1 = tr C`` and ``I_2 = (tr(C)^2 - tr(C^2))/2`` of the *three-dimensional* right
Cauchy-Green tensor: in plane strain (``d = 2``) ``C_3 = diag(C, 1)``, so ``I_1 = I_C + 1`` and
``I_2 = II_C + I_C``, and the 2D density is the 3D one restricted to in-plane deformations (as
in :mod:`.lame`). The modified invariants do not change under a pure dilatation, so
``psi_dev`` is isochoric; the volumetric part is the constraint ``J - 1`` of :mod:`.incompressible`
with the bulk modulus ``kappa = lmbda + 2/3 mu``. The shear modulus at rest is
``mu = 2 (c10 + c01)``; ``c01 = r mu / 2``, ``c10 = (1 - r) mu / 2`` with the Mooney ratio
``r`` in [0, 1] (``r = 0``: the isochoric neo-Hookean model). Defined for ``J > 0`` only
(``J^{-2/3}``), so the solver's ``det F > 0`` filter applies.
"""

from __future__ import annotations

from ufl.core.expr import Expr

from fem_anim.forms.kinematics import dimension, invariants

__all__ = ["psi_dev"]


def psi_dev(F: Expr, mu: Expr | float, ratio: Expr | float) -> Expr:
    """Isochoric Mooney-Rivlin density ``c10 (I1bar - 3) + c01 (I2bar - 3)``.

    Args:
        F: ``d x d`` deformation gradient, ``d`` = 2 (plane strain) or 3.
        mu: Shear modulus at rest, ``2 (c10 + c01)``.
        ratio: Mooney ratio ``r = c01 / (c10 + c01)``.
    """
    I_C, II_C, J = invariants(F)
    if dimension(F) == 2:
        I_1, I_2 = I_C + 1, II_C + I_C
    else:
        I_1, I_2 = I_C, II_C
    c10, c01 = (1 - ratio) * mu / 2, ratio * mu / 2
    return c10 * (J ** (-2.0 / 3.0) * I_1 - 3) + c01 * (J ** (-4.0 / 3.0) * I_2 - 3)
