"""The inertia term of a step objective and the kinetic energy (seed section 4.1).

The kinetic energy k = 1/2 v^T M v (seed eqs. 14-19) with the consistent mass matrix
M = sum_t rho_t S_t (eqs. 17-20: tetrahedron vol/10 on the diagonal and vol/20 off it,
triangle area/6 and area/12) is the integral of rho |v|^2 / 2 computed exactly
(quadrature degree 2k for P_k). The lumped mass (seed footnote 4: row sums on the
diagonal) is the same integral evaluated with the vertex quadrature rule, which for P1
puts each cell's mass rho vol/(d+1) on its vertices: exactly the row sums of M.
"""

from __future__ import annotations

import ufl

__all__ = ["mass_measure", "inertia", "kinetic_energy"]


def mass_measure(dx: ufl.Measure, degree: int, lumped: bool) -> ufl.Measure:
    """Measure that makes ``rho u.v dx`` the consistent or the (P1) lumped mass matrix.

    Args:
        dx: The cell measure.
        degree: The displacement's Lagrange degree k (consistent: quadrature degree 2k).
        lumped: Use the vertex rule (row-sum lumping, seed footnote 4).
    """
    if lumped:
        return dx(metadata={"quadrature_rule": "vertex", "quadrature_degree": 1})
    return dx(metadata={"quadrature_degree": 2 * degree})


def inertia(u, u_pred, rho, dx_mass: ufl.Measure):
    """The inertia term 1/2 ||x - y||_M^2 = 1/2 int rho |u - u_pred|^2 of seed eq. 4.

    Args:
        u: The displacement (x = X + u).
        u_pred: The predictor's displacement (y = X + u_pred).
        rho: The density (kg/m^3).
        dx_mass: The mass measure (:func:`mass_measure`).
    """
    w = u - u_pred
    return 0.5 * rho * ufl.inner(w, w) * dx_mass


def kinetic_energy(v, rho, dx_mass: ufl.Measure):
    """The kinetic energy k = 1/2 v^T M v (seed eq. 19).

    Args:
        v: The velocity.
        rho: The density (kg/m^3).
        dx_mass: The mass measure (:func:`mass_measure`).
    """
    return 0.5 * rho * ufl.inner(v, v) * dx_mass
