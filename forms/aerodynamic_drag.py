r"""Aerodynamic drag and wind on a shell: a normal-projected pressure drag per area.

A surface element of area ``a`` and unit normal ``n`` moving at ``v`` through air moving at
the wind velocity ``w`` feels the pressure drag of a flat plate (the normal part of the
relative velocity only: the tangential, skin-friction part is left out)

.. math::

    \mathbf f = -\tfrac12 C_d \rho_a\, |s|\, s\, \mathbf n\, a,
    \qquad s = (\mathbf v - \mathbf w) \cdot \mathbf n,

with the dimensionless drag coefficient ``C_d`` (about 1.2 for a flat plate broadside
on) and the air density ``rho_a`` (kg/m^3). It does not depend on which way ``n`` points
(``|s| s n`` is even in ``n``), so a surface's orientation does not matter. A plate of area
density ``m/A`` falling flat under gravity ``g`` reaches the terminal velocity
``v_t = sqrt(2 (m/A) g / (C_d rho_a))``; edge-on (``n`` normal to the motion) it feels none.

In the step objective (seed §3.1, eq. 4) the force is the gradient of a dissipation
potential, like the Rayleigh damping of :mod:`fem_anim.forms.damping`: the normal and the
area are lagged at the step's start (``n_0``, ``a_0``: the deformed surface at ``u_n``),
so that with the scheme's ``v_{n+1} = (u - u_d) / tau`` and ``c = w / tau``

.. math::

    \Psi(u) = w \tau \int \phi(s)\, \mathrm da_0, \qquad
    \phi(s) = \tfrac16 C_d \rho_a |s|^3, \qquad s = (\mathbf v_{n+1} - \mathbf w)
    \cdot \mathbf n_0,

is convex in ``u`` (``|s|^3`` is convex and ``C^2``) and its gradient is ``-w f``: added to
``g(x) = 1/2 ||x - y||_M^2 + w E(x)`` its stationarity is the scheme with the drag taken
implicitly in the velocity and explicitly in the geometry (semi-implicit). At a steady
state (the terminal velocity) the lag vanishes and the implicit step meets the drag law
exactly.
"""

from __future__ import annotations

import ufl
from ufl.core.expr import Expr

__all__ = ["drag_density", "lagged_normal_area", "drag_step_potential", "drag_force_potential"]


def drag_density(s: Expr, drag_coefficient, air_density) -> Expr:
    """``phi(s) = C_d rho_a |s|^3 / 6`` (W/m^2 per m/s: ``phi'(s) = C_d rho_a |s| s / 2``).

    Args:
        s: The normal relative velocity ``(v - w) . n`` (m/s).
        drag_coefficient: ``C_d`` (dimensionless).
        air_density: ``rho_a`` (kg/m^3).
    """
    return drag_coefficient * air_density * abs(s) ** 3 / 6


def lagged_normal_area(u_n: Expr, J: Expr) -> tuple[Expr, Expr]:
    """The unit normal and the area ratio ``da / dA`` of the surface deformed by ``u_n``.

    Args:
        u_n: The displacement at the step's start (3 components, P1).
        J: The rest Jacobian ``dX/dxi`` of the reference triangle (3x2, ``ufl.Jacobian``).

    Returns:
        ``(n_0, da_0 / dA)``: the unit normal ``Ds_0 x Ds_1 / |Ds_0 x Ds_1|`` of the deformed
        tangent map ``Ds = (I + grad u_n) J``, and ``|Ds_0 x Ds_1| / |J_0 x J_1|``.
    """
    Ds = J + ufl.grad(u_n) * J
    cross = ufl.cross(Ds[:, 0], Ds[:, 1])
    rest = ufl.cross(J[:, 0], J[:, 1])
    norm = ufl.sqrt(ufl.dot(cross, cross))
    return cross / norm, norm / ufl.sqrt(ufl.dot(rest, rest))


def drag_step_potential(u: Expr, u_anchor: Expr, u_n: Expr, wind: Expr, coefficient: Expr,
                        weight: Expr, drag_coefficient, air_density, J: Expr,
                        dx: ufl.Measure) -> ufl.Form:
    """``Psi(u) / w``: the drag's part of the step objective, divided by the weight ``w``.

    With ``tau = w / c``, ``Psi / w = tau int phi(((u - u_d) / tau - wind) . n_0) da_0``
    (module docstring); it goes into the part of ``g`` that the objective multiplies by
    ``w``.

    Args:
        u: The displacement (the step's unknown).
        u_anchor: The scheme's anchor ``u_d`` (``v_{n+1} = (u - u_d) / tau``).
        u_n: The displacement at the step's start (lagged normal and area).
        wind: The wind velocity ``w`` (m/s, a 3-vector).
        coefficient: ``c = w / tau`` of the scheme (staged per step).
        weight: The energy weight ``w`` (staged per step).
        drag_coefficient: ``C_d``.
        air_density: ``rho_a`` (kg/m^3).
        J: The rest Jacobian ``dX/dxi`` (3x2, ``ufl.Jacobian`` of the surface).
        dx: The cell measure of the surface.
    """
    n0, area = lagged_normal_area(u_n, J)
    rate = coefficient / weight  # 1 / tau
    s = ufl.dot(rate * (u - u_anchor) - wind, n0)
    return drag_density(s, drag_coefficient, air_density) / rate * area * dx


def drag_force_potential(v: Expr, u: Expr, wind: Expr, drag_coefficient, air_density,
                         J: Expr, dx: ufl.Measure) -> ufl.Form:
    """``int phi((v - wind) . n(u)) da(u)``: its derivative in ``v`` is ``-f``, the drag
    force at the velocity ``v`` on the surface deformed by ``u`` (for the initial
    acceleration ``M a_0 = f_0``).

    Args:
        v: The velocity (m/s).
        u: The displacement (normal and area).
        wind: The wind velocity (m/s).
        drag_coefficient: ``C_d``.
        air_density: ``rho_a`` (kg/m^3).
        J: The rest Jacobian ``dX/dxi`` (3x2, ``ufl.Jacobian`` of the surface).
        dx: The cell measure of the surface.
    """
    n, area = lagged_normal_area(u, J)
    return drag_density(ufl.dot(v - wind, n), drag_coefficient, air_density) * area * dx
