r"""Membrane energy of a thin shell: hyperelasticity on the surface's first fundamental form.

A shell's mid-surface is a triangle mesh in 3D (topological dimension 2). The seed's
deformation gradient of a linear simplex, ``F = D_s D_m^{-1}`` (seed §4.2, eq. 26), keeps its
meaning with a 3x2 ``D_s`` (the deformed edge vectors, or the tangent map
``dx/dxi`` of the reference triangle) and a 2x2 ``D_m`` (the rest edge vectors written in an
orthonormal frame of the rest tangent plane): ``F`` is 3x2 and maps the rest tangent plane
onto the deformed one. ``C = F^T F`` (2x2) is the first fundamental form of the deformed
surface in rest-orthonormal coordinates, and the membrane densities are the 2D ones of seed
§4.4 in ``C``:

.. math::

    \psi_{StVK} = \mu\, E : E + \frac{\bar\lambda}{2} (\operatorname{tr} E)^2,\quad
    E = \tfrac12 (C - I_2),

    \psi_{NH} = \frac{\mu}{2} (\operatorname{tr} C - 2) - \mu \ln J
        + \frac{\bar\lambda}{2} (\ln J)^2,\quad J = \sqrt{\det C},

with the plane-stress Lamé parameter :math:`\bar\lambda = 2 \mu \lambda / (\lambda + 2 \mu)`
(the stress through the thickness is zero), so that at small strain both give the plane-stress
law of a plate, ``sigma = E / (1 - nu^2) [(1 - nu) eps + nu tr(eps) I]``. The energy per unit
rest area is ``thickness * psi``. ``J`` is the ratio of deformed to rest area, always
positive for a non-degenerate triangle: unlike a solid, a membrane cannot invert.
"""

from __future__ import annotations

import ufl
from ufl.core.expr import Expr

__all__ = ["MEMBRANE_MODELS", "membrane_psi", "neohookean_psi", "plane_stress_lambda",
           "rest_frame", "stvk_psi", "surface_deformation_gradient", "tangent_map"]


def tangent_map(u: Expr, J: Expr) -> Expr:
    """The deformed tangent map ``D_s = dx/dxi = (I + grad u) J`` (3x2).

    Args:
        u: The displacement (3 components) on the surface.
        J: The rest Jacobian ``dX/dxi`` of the reference triangle (3x2, ``ufl.Jacobian``).
    """
    return J + ufl.grad(u) * J


def rest_frame(J: Expr) -> Expr:
    """``D_m``: the rest tangent map in an orthonormal frame of the rest tangent plane (2x2).

    The frame is ``t1 = J_0 / |J_0|``, ``t2`` the unit part of ``J_1`` orthogonal to ``t1``,
    so ``D_m`` is upper triangular with a positive diagonal (``det D_m`` is twice the rest
    area of a P1 triangle).

    Args:
        J: The rest Jacobian (3x2).
    """
    a, b = J[:, 0], J[:, 1]
    la = ufl.sqrt(ufl.dot(a, a))
    t1 = a / la
    b_t1 = ufl.dot(b, t1)
    h = ufl.sqrt(ufl.dot(b, b) - b_t1**2)
    return ufl.as_matrix([[la, b_t1], [0, h]])


def surface_deformation_gradient(u: Expr, J: Expr) -> Expr:
    """``F = D_s D_m^{-1}`` (seed eq. 26 with a 3x2 ``D_s``): the 3x2 deformation gradient.

    Args:
        u: The displacement (3 components) on the surface.
        J: The rest Jacobian (3x2).
    """
    return tangent_map(u, J) * ufl.inv(rest_frame(J))


def plane_stress_lambda(mu: Expr | float, lmbda: Expr | float) -> Expr | float:
    """The plane-stress Lamé parameter ``2 mu lmbda / (lmbda + 2 mu)`` (``E nu / (1 - nu^2)``).

    Args:
        mu: Shear modulus (Pa).
        lmbda: First Lamé parameter of the 3D material (Pa).
    """
    return 2 * mu * lmbda / (lmbda + 2 * mu)


def stvk_psi(F: Expr, mu: Expr | float, lmbda: Expr | float) -> Expr:
    """StVK membrane density ``mu E:E + lmbda_ps / 2 tr(E)^2`` (seed eq. 37 on ``C = F^T F``).

    Args:
        F: The 3x2 deformation gradient.
        mu: Shear modulus (Pa).
        lmbda: First Lamé parameter of the 3D material (Pa); the plane-stress one is used.

    Returns:
        The energy per unit rest volume (Pa); times the thickness, per unit rest area.
    """
    E = (F.T * F - ufl.Identity(2)) / 2
    return mu * ufl.inner(E, E) + plane_stress_lambda(mu, lmbda) / 2 * ufl.tr(E) ** 2


def neohookean_psi(F: Expr, mu: Expr | float, lmbda: Expr | float) -> Expr:
    """Neo-Hookean membrane density ``mu/2 (tr C - 2) - mu ln J + lmbda_ps/2 (ln J)^2``.

    Args:
        F: The 3x2 deformation gradient.
        mu: Shear modulus (Pa).
        lmbda: First Lamé parameter of the 3D material (Pa); the plane-stress one is used.

    Returns:
        The energy per unit rest volume (Pa), ``J = sqrt(det F^T F)`` the area ratio.
    """
    C = F.T * F
    lnJ = ufl.ln(ufl.det(C)) / 2
    return mu / 2 * (ufl.tr(C) - 2) - mu * lnJ + plane_stress_lambda(mu, lmbda) / 2 * lnJ**2


#: Scene ``material.model`` -> the membrane density of a shell body.
MEMBRANE_MODELS = {"stvk": stvk_psi, "neohookean": neohookean_psi}


def membrane_psi(model: str, F: Expr, mu: Expr | float, lmbda: Expr | float) -> Expr:
    """The membrane density of ``model`` (a key of :data:`MEMBRANE_MODELS`).

    Raises:
        KeyError: for a model without a membrane form.
    """
    return MEMBRANE_MODELS[model](F, mu, lmbda)
