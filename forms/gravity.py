"""Gravitational potential of a body in a uniform field.

E_g(x) = - int rho g . x dV. Relative to the rest configuration X (x = X + u) this is
- int rho g . u dV, whose gradient is the constant nodal gravity force M g: a scene
without ``[gravity]`` builds no such term (the form then contains no ``g``).
"""

from __future__ import annotations

import ufl

__all__ = ["gravity_potential"]


def gravity_potential(u, rho, g, dx: ufl.Measure):
    """The gravitational potential - int rho g . u dV relative to the rest configuration.

    Args:
        u: The displacement.
        rho: The density (kg/m^3).
        g: The acceleration of gravity (m/s^2).
        dx: The cell measure.
    """
    return -rho * ufl.inner(g, u) * dx
