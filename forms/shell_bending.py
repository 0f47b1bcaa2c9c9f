r"""Bending energy of a thin shell: the discrete-shell hinge energy over interior edges.

The bending energy of a P1 triangle surface lives on its edges: across each interior edge
``e`` the two triangles' unit normals ``n+`` and ``n-`` make a dihedral angle ``theta``, and
(Grinspun, Hirani, Desbrun, Schroeder 2003, "Discrete Shells"; the hinge of
Kirchhoff-Love's energy ``D/2 int (2H)^2 dA`` for a P1 surface)

.. math::

    E_b = \sum_e k \frac{3 |e|^2}{A_+ + A_-} (\theta_e - \bar\theta_e)^2
        = \int_{\mathcal E} k \frac{3 |e|}{A_+ + A_-} (\theta - \bar\theta)^2 \,\mathrm dS,

a facet integral over the interior edges (``dS``) of quantities restricted to the two sides.
``bar theta`` is the rest angle, so a shell curved at rest is stress free. The angle is
signed and smooth: with ``s = (n+ x n-) . e / |e|`` and ``c = n+ . n-``,
``theta = 2 atan(s / (1 + c))`` (the half-angle formula, exact for ``|theta| < pi``), so the
energy's gradient and Hessian exist at the flat state. ``k`` is the hinge stiffness; for a
plate of Young's modulus ``E``, Poisson ratio ``nu`` and thickness ``t`` the scene derives it
from the flexural rigidity ``D = E t^3 / (12 (1 - nu^2))`` (:func:`hinge_stiffness`). The
normals of two triangles sharing an edge may be oriented either way by the mesh; ``n-`` is
taken with the sign of ``N+ . N-`` of the rest normals (rest dihedral angles below 90
degrees), a constant of the deformation.
"""

from __future__ import annotations

import ufl
from ufl.core.expr import Expr

__all__ = ["HINGE_FACTOR", "flexural_rigidity", "hinge_angle", "hinge_density",
           "hinge_stiffness", "unit_normal"]

#: ``k = HINGE_FACTOR * D``: the hinge stiffness whose energy on a cylinder of curvature
#: ``kappa`` meshed by right triangles (edges along and across the axis, and diagonals)
#: is Kirchhoff-Love's ``D/2 kappa^2`` per area (docs/cloth.md, "Bending").
HINGE_FACTOR = 1.0 / 6.0


def unit_normal(Ds: Expr) -> Expr:
    """The unit normal ``Ds_0 x Ds_1 / |Ds_0 x Ds_1|`` of a triangle's tangent map (3x2).

    Args:
        Ds: The (deformed or rest) tangent map ``dx/dxi``.
    """
    n = ufl.cross(Ds[:, 0], Ds[:, 1])
    return n / ufl.sqrt(ufl.dot(n, n))


def hinge_angle(n_plus: Expr, n_minus: Expr, edge: Expr) -> Expr:
    """The signed dihedral angle ``2 atan(s / (1 + c))`` between two unit normals.

    Args:
        n_plus: The unit normal of one triangle.
        n_minus: The unit normal of the other, consistently oriented.
        edge: The shared edge's vector (any length, the same orientation at rest and
            deformed).

    Returns:
        ``theta`` in ``(-pi, pi)``; zero for coplanar triangles.
    """
    s = ufl.dot(ufl.cross(n_plus, n_minus), edge) / ufl.sqrt(ufl.dot(edge, edge))
    c = ufl.dot(n_plus, n_minus)
    return 2 * ufl.atan(s / (1 + c))


def hinge_density(theta: Expr, theta_rest: Expr, k: Expr | float, edge_length: Expr,
                  area_sum: Expr) -> Expr:
    """The hinge energy per unit edge length ``3 k |e| / (A+ + A-) (theta - theta_rest)^2``.

    Integrated over an edge (length ``|e|``) it is the edge's term
    ``k 3 |e|^2 / (A+ + A-) (theta - theta_rest)^2`` of the discrete-shell energy.

    Args:
        theta: The deformed dihedral angle.
        theta_rest: The rest dihedral angle.
        k: The hinge stiffness (J).
        edge_length: The rest edge length (m).
        area_sum: The rest areas of the two triangles, summed (m^2).
    """
    return 3 * k * edge_length / area_sum * (theta - theta_rest) ** 2


def flexural_rigidity(E, nu, thickness):
    """Kirchhoff-Love's plate rigidity ``D = E t^3 / (12 (1 - nu^2))`` (J).

    Args:
        E: Young's modulus (Pa).
        nu: Poisson's ratio.
        thickness: The shell thickness ``t`` (m).
    """
    return E * thickness**3 / (12 * (1 - nu**2))


def hinge_stiffness(E, nu, thickness):
    """The hinge stiffness ``k = HINGE_FACTOR * D`` of a plate of the given material (J).

    Args:
        E: Young's modulus (Pa).
        nu: Poisson's ratio.
        thickness: The shell thickness ``t`` (m).
    """
    return HINGE_FACTOR * flexural_rigidity(E, nu, thickness)
