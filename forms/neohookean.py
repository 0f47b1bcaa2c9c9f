r"""Compressible neo-Hookean elasticity (seed §4.4; Bonet & Wood [1] of the seed, ch. 6).

.. math::

    \psi(F) = \frac{\mu}{2} (I_C - d) - \mu \ln J + \frac{\lambda}{2} (\ln J)^2,
    \qquad I_C = \operatorname{tr}(F^T F),\ J = \det F.

Domain: ``J > 0``; ``psi -> +inf`` as ``J -> 0+``, which resists inversion, unlike StVK and
linear elasticity. Outside the domain the compiled kernel evaluates ``log`` of zero or of a
negative number, giving ``-inf`` or NaN in the energy, its gradient and its Hessian; nothing here
guards against it. The solver's ``J > 0`` step filter (``requires_positive_J`` in
:mod:`.material`) is what keeps iterates inside the domain.
"""

from __future__ import annotations

import ufl
from ufl.core.expr import Expr

from fem_anim.forms.kinematics import dimension, invariants

__all__ = ["psi"]


def psi(F: Expr, mu: Expr | float, lmbda: Expr | float) -> Expr:
    """Strain energy density of the compressible neo-Hookean model.

    Args:
        F: ``d x d`` deformation gradient with ``det F > 0``, ``d`` = 2 (plane strain) or 3.
        mu: Shear modulus.
        lmbda: First Lamé parameter.

    Returns:
        ``mu/2 (I_C - d) - mu ln J + lmbda/2 (ln J)^2``.
    """
    I_C, _, J = invariants(F)
    lnJ = ufl.ln(J)
    return mu / 2 * (I_C - dimension(F)) - mu * lnJ + lmbda / 2 * lnJ**2
