r"""Kirchhoff-Love bending of a P2 shell: a C0 interior-penalty (symmetric Nitsche) energy.

The mid-surface carries a continuous P2 displacement ``u`` on a triangle mesh in 3D (P1
geometry: each rest triangle is flat). Inside a triangle the change of curvature is the
second fundamental form of the deformed surface, ``b_ab = n . x_{,ab}``, in orthonormal
coordinates of the rest plane; the rest cell is flat and affine, so ``x_{,ab} = u_{,ab}`` and
as a 3x3 tangent tensor

.. math::

    B = \sum_i n_i\, \nabla_s \nabla_s u_i ,\qquad
    \psi_b(B) = \frac D2 \left[(1 - \nu) B : B + \nu (\operatorname{tr} B)^2\right],

Koiter's bending density (Kirchhoff-Love's ``D/2 [(1-nu) |kappa|^2 + nu tr(kappa)^2]`` at
large rotation), ``n`` the deformed unit normal and ``D`` the flexural rigidity
(:func:`fem_anim.forms.shell_bending.flexural_rigidity`). A C0 field has a kink across each
edge: the signed angle ``Theta = theta - theta_rest`` between the two sides' deformed
normals (the hinge's angle, :func:`fem_anim.forms.shell_bending.hinge_angle`, measured at
every quadrature point of the edge; ``theta_rest`` is the rest mesh's dihedral angle, where a
curved rest surface keeps its curvature). The C0 interior-penalty energy (Engel et al. 2002;
Brenner and Sung 2005, for the plate) is

.. math::

    E_b = \sum_T \int_T \psi_b\,\mathrm dA
        + \sum_e \int_e \Big[-\{M_{\nu\nu}\}\,\Theta
        + \frac{\alpha D}{2 h_e} \Theta^2\Big]\,\mathrm ds ,\qquad
    M_{\nu\nu} = \nu_e \cdot \frac{\partial \psi_b}{\partial B}\, \nu_e ,

``{.}`` the mean of the two sides, ``nu_e`` each side's outward rest conormal, ``h_e`` the mean
height of the two triangles over the edge and ``alpha`` the penalty
(:data:`KL_PENALTY`). The consistency term makes the energy's Euler-Lagrange equations those of
the smooth plate (the moment's jump integrated by parts), so the discrete solution converges
to Kirchhoff-Love's, not to a mesh-dependent limit (the hinge's). ``Theta`` linearises to the
jump of the normal slope ``w+_{nu+} + w-_{nu-}`` with the edge direction ``N+ x nu+`` (both
flip with the '+' cell's orientation, as ``M`` does: their product does not depend on how
the mesh orients its triangles). A clamped boundary edge is the same term against the clamp's
normal (the rest normal), with the one side's moment and height. The seed's deformation
gradient (seed §4.2, eq. 26) is the 3x2 ``F`` of :mod:`fem_anim.forms.shell_membrane`; the
deformed normal is that of its tangent map.
"""

from __future__ import annotations

import ufl
from ufl.core.expr import Expr

from fem_anim.forms.shell_bending import hinge_angle, unit_normal
from fem_anim.forms.shell_membrane import tangent_map

__all__ = ["KL_PENALTY", "clamp_density", "curvature_change", "edge_density", "kl_psi",
           "normal_moment"]

#: The interior-penalty factor ``alpha`` of ``alpha D / h_e``: large enough for the energy
#: to be coercive on P2 (docs/cloth.md, "Kirchhoff-Love bending").
KL_PENALTY = 10.0


def curvature_change(hessian: Expr, n: Expr) -> Expr:
    """``B = sum_i n_i grad_s grad_s u_i``: the deformed second fundamental form (3x3 tangent
    tensor of the flat rest triangle; zero at rest).

    Args:
        hessian: ``grad(grad(u))`` of the displacement (3x3x3; P2), possibly restricted.
        n: The deformed unit normal.
    """
    i, j, k = ufl.indices(3)
    return ufl.as_tensor(n[i] * hessian[i, j, k], (j, k))


def kl_psi(B: Expr, D: Expr | float, nu: Expr | float) -> Expr:
    """Koiter's bending density ``D/2 [(1 - nu) B:B + nu tr(B)^2]`` (J/m^2).

    Args:
        B: The curvature change (3x3 tangent tensor).
        D: The flexural rigidity (J).
        nu: Poisson's ratio.
    """
    return D / 2 * ((1 - nu) * ufl.inner(B, B) + nu * ufl.tr(B) ** 2)


def normal_moment(B: Expr, conormal: Expr, D: Expr | float, nu: Expr | float) -> Expr:
    """``M_nn = nu_e . dpsi/dB nu_e = D [(1 - nu) nu_e.B.nu_e + nu tr B]`` (N m / m).

    Args:
        B: The curvature change.
        conormal: A unit vector of the rest tangent plane (an edge's outward conormal).
        D: The flexural rigidity (J).
        nu: Poisson's ratio.
    """
    return D * ((1 - nu) * ufl.dot(conormal, ufl.dot(B, conormal)) + nu * ufl.tr(B))


def _side(u: Expr, J: Expr, side: str | None):
    """``(n, N, grad u)`` on one side of an edge (or in the cell: ``side`` None)."""
    n, N, G = unit_normal(tangent_map(u, J)), unit_normal(J), ufl.grad(u)
    if side is None:
        return n, N, G
    return n(side), N(side), G(side)


def edge_density(u: Expr, J: Expr, conormal: Expr, D: Expr | float, nu: Expr | float,
                 height: Expr, alpha: Expr | float = KL_PENALTY) -> Expr:
    """``-{M_nn} Theta + alpha D / (2 h_e) Theta^2`` on an interior edge (J/m).

    Args:
        u: The displacement (P2).
        J: The rest Jacobian (``ufl.Jacobian``).
        conormal: The outward rest conormal of each side (``ufl.FacetNormal``).
        D: The flexural rigidity (J).
        nu: Poisson's ratio.
        height: ``h_e``, the mean height of the two rest triangles over the edge (m).
        alpha: The penalty factor.
    """
    n_p, N_p, G_p = _side(u, J, "+")
    n_m, N_m, _ = _side(u, J, "-")
    sign = ufl.sign(ufl.dot(N_p, N_m))  # the '-' side oriented as the '+' side
    edge = ufl.cross(N_p, conormal("+"))
    theta = hinge_angle(n_p, sign * n_m, edge + ufl.dot(G_p, edge))
    Theta = theta - hinge_angle(N_p, sign * N_m, edge)
    H = ufl.grad(ufl.grad(u))
    B_p = curvature_change(H("+"), n_p)
    B_m = sign * curvature_change(H("-"), n_m)
    M_p = normal_moment(B_p, conormal("+"), D, nu)
    M = (M_p + normal_moment(B_m, conormal("-"), D, nu)) / 2
    return -M * Theta + alpha * D / (2 * height) * Theta**2


def clamp_density(u: Expr, J: Expr, conormal: Expr, D: Expr | float, nu: Expr | float,
                  height: Expr, alpha: Expr | float = KL_PENALTY) -> Expr:
    """The clamped boundary edge's ``-M_nn Theta + alpha D / (2 h) Theta^2`` (J/m): ``Theta``
    the angle between the deformed normal and the rest one (the clamp's), ``h`` the height of
    the triangle over the edge.

    Args:
        u: The displacement (P2).
        J: The rest Jacobian.
        conormal: The outward rest conormal (``ufl.FacetNormal``).
        D: The flexural rigidity (J).
        nu: Poisson's ratio.
        height: The rest triangle's height over the edge (m).
        alpha: The penalty factor.
    """
    n, N, G = _side(u, J, None)
    edge = ufl.cross(N, conormal)
    Theta = hinge_angle(n, N, edge + ufl.dot(G, edge))
    M = normal_moment(curvature_change(ufl.grad(ufl.grad(u)), n), conormal, D, nu)
    return -M * Theta + alpha * D / (2 * height) * Theta**2
