r"""Nearly and exactly incompressible solids: the perturbed-Lagrangian (u, p) energy.

A material whose density splits as

.. math::

    \psi(F) = \psi_{dev}(F) + \frac{\kappa}{2}\, g(J)^2,
    \qquad g(1) = 0,\ g'(1) = 1,

has the same stationary points as the two-field energy density (Simo & Taylor 1991;
Bonet & Wood [1] of the seed, ch. 6.6 and 8.6)

.. math::

    W(F, p) = \psi_{dev}(F) + p\, g(J) - \frac{1}{2\kappa}\, p^2,

since the maximum over ``p`` is at ``p = kappa g(J)`` and gives back ``psi``. The pressure-like
unknown ``p`` (Pa) enters linearly in the constraint and quadratically with the compliance
``1/kappa``, which is a number (a ``Constant``) that is simply 0 for ``nu = 0.5``: nearly
(``1/kappa > 0``) and exactly incompressible (``1/kappa = 0``, ``g(J) = 0`` enforced weakly)
solids are the same code. ``W`` is convex in ``F`` only through ``psi_dev`` and concave in
``p``: a discrete step is a saddle point, not a minimum.

The split of each model is exact: for ``nu < 0.5`` eliminating ``p`` gives back the
displacement model of the same name (:mod:`.neohookean`, :mod:`.stable_neohookean`; so both
formulations converge to the same solution), and Mooney-Rivlin exists only here:

* neohookean: ``psi_dev = mu/2 (I_C - d) - mu ln J``, ``g = ln J``, ``kappa = lmbda``;
* stable_neohookean: ``psi_dev = mu'/2 (I_C - d) - mu'/2 ln((I_C + 1)/(d + 1)) - mu (J - 1)``,
  ``g = J - 1``, ``kappa = lmbda'`` (the remapped Lame parameter);
* mooney_rivlin: ``psi_dev = c10 (I1bar - 3) + c01 (I2bar - 3)`` (:mod:`.mooney_rivlin`),
  ``g = J - 1``, ``kappa = lmbda + 2/3 mu``

(stable neo-Hookean: expand ``lmbda'/2 (J - alpha)^2`` about ``J = 1`` with
``lmbda' (alpha - 1) = mu``; ``mu' = (d+1)/d mu`` as in :mod:`.stable_neohookean`.) With
``kappa = lmbda + c mu``, the compliance is computed without ever forming ``lmbda``:

.. math::

    \frac{1}{\kappa} = \frac{2 (1 + \nu)(1 - 2\nu)}{E\, (2\nu + c (1 - 2\nu))},

zero at ``nu = 1/2``. Pure UFL; the discretisation (Taylor-Hood P2/P1) is bound in
:mod:`fem_anim.problem.objective`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import ufl
from ufl.core.expr import Expr

from fem_anim.forms import mooney_rivlin
from fem_anim.forms.kinematics import dimension, invariants
from fem_anim.forms.stable_neohookean import remap_lame

__all__ = ["MIXED_MATERIALS", "MixedMaterial", "compliance", "lagrangian"]


def _neohookean_dev(F: Expr, mu, ratio) -> Expr:
    I_C, _, J = invariants(F)
    return mu / 2 * (I_C - dimension(F)) - mu * ufl.ln(J)


def _stable_neohookean_dev(F: Expr, mu, ratio) -> Expr:
    d = dimension(F)
    mu_, _ = remap_lame(mu, 0.0, d)
    I_C, _, J = invariants(F)
    return mu_ / 2 * (I_C - d) - mu_ / 2 * ufl.ln((I_C + 1) / (d + 1)) - mu * (J - 1)


@dataclass(frozen=True)
class MixedMaterial:
    """A model split as ``psi_dev(F) + kappa/2 g(J)^2``.

    Attributes:
        name: Scene-file name (``material.model``).
        psi_dev: ``psi_dev(F, mu, ratio)``, ``ratio`` the Mooney ratio (others ignore it).
        constraint: ``g(J)``.
        bulk_shift: ``c(d)`` in ``kappa = lmbda + c mu``.
    """

    name: str
    psi_dev: Callable[..., Expr]
    constraint: Callable[[Expr], Expr]
    bulk_shift: Callable[[int], float]


MIXED_MATERIALS: dict[str, MixedMaterial] = {
    m.name: m for m in (
        MixedMaterial("neohookean", _neohookean_dev, ufl.ln, lambda d: 0.0),
        MixedMaterial("stable_neohookean", _stable_neohookean_dev, lambda J: J - 1,
                      lambda d: 1.0 - 2.0 / (d * (d + 1))),
        MixedMaterial("mooney_rivlin", mooney_rivlin.psi_dev, lambda J: J - 1,
                      lambda d: 2.0 / 3.0),
    )
}


def compliance(material: MixedMaterial, E: float, nu: float, d: int) -> float:
    """The compliance ``1/kappa`` of a mixed material (formula in the module docstring).

    Args:
        material: The mixed material (its ``bulk_shift`` c in ``kappa = lmbda + c mu``).
        E: Young's modulus (Pa).
        nu: Poisson's ratio in (0, 1/2].
        d: The dimension (2 or 3).

    Returns:
        ``1/kappa`` (1/Pa); 0 at ``nu = 1/2``.

    Raises:
        ValueError: if ``E <= 0`` or ``nu`` is outside (0, 1/2].
    """
    c = material.bulk_shift(d)
    if not (0.0 < nu <= 0.5 and E > 0.0):
        raise ValueError(f"the mixed formulation needs E > 0 and nu in (0, 0.5], got {E}, {nu}")
    return 2.0 * (1.0 + nu) * (1.0 - 2.0 * nu) / (E * (2.0 * nu + c * (1.0 - 2.0 * nu)))


def lagrangian(material: MixedMaterial, F: Expr, p: Expr, mu, inv_kappa, ratio=0.0) -> Expr:
    """``W(F, p) = psi_dev(F) + p g(J) - p^2 / (2 kappa)`` (J/m^3; ``p`` in Pa).

    At the discrete saddle point ``p_h`` maximises ``int W(F(u_h), p) dX`` over the pressure
    space, so ``int W(F(u_h), p_h) dX`` is the stored energy of the discrete constrained
    system (what :mod:`fem_anim.problem.objective` reports as the elastic energy).

    Args:
        material: The mixed material (``psi_dev`` and the constraint ``g``).
        F: The deformation gradient.
        p: The pressure field (Pa).
        mu: The shear modulus (Pa).
        inv_kappa: The compliance ``1/kappa`` (1/Pa).
        ratio: The Mooney ratio r (Mooney-Rivlin only).

    Returns:
        The UFL energy density ``W(F, p)``.
    """
    J = ufl.det(F)
    return material.psi_dev(F, mu, ratio) + p * material.constraint(J) - inv_kappa / 2 * p**2
