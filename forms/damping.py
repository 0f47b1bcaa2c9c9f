"""Rayleigh damping as a dissipation potential inside the step objective.

The damping force is -C v with C = alpha M + beta K_0 (mass- and stiffness-proportional,
K_0 the stiffness at rest). Written as a potential it keeps each step a minimisation
(seed section 3.1): for a scheme whose velocity is v_{n+1} = (x - x_d)/tau, with anchor
x_d and time scale tau from the history, adding

    D(x) = c/2 (x - x_d)^T C (x - x_d),        c = w/tau,

to g(x) = 1/2 ||x - y||_M^2 + w E(x) makes its stationarity M(x - y) + w (grad E + C v_{n+1}) = 0,
the damped scheme. :mod:`fem_anim.simulation.integrators` gives (c, x_d) per scheme.

1/2 d^T K_0 d is the linear-elastic energy of the displacement d (every material of
``forms/`` has the linear-elastic Hessian at rest, with the same mu and lambda), so

    D = c [ alpha/2 int rho |d|^2 + beta int psi_lin(I + grad d) ],   d = u - u_d.
"""

from __future__ import annotations

import ufl

from fem_anim.forms import linear
from fem_anim.forms.kinematics import deformation_gradient

__all__ = ["dissipation_potential"]


def dissipation_potential(u, u_anchor, coefficient, alpha, beta, rho, mu, lmbda,
                          dx_mass: ufl.Measure, dx_elastic: ufl.Measure):
    """c/2 (u - u_anchor)^T (alpha M + beta K_0) (u - u_anchor) as a UFL form.

    Terms with a zero coefficient (``alpha`` or ``beta`` given as the float 0) are omitted.

    Args:
        u: The displacement.
        u_anchor: The scheme's anchor u_d (x_d = X + u_d).
        coefficient: c = w/tau of the scheme.
        alpha: The mass-proportional coefficient (1/s).
        beta: The stiffness-proportional coefficient (s).
        rho: The density (kg/m^3).
        mu: The shear modulus (Pa) of K_0.
        lmbda: The first Lame parameter (Pa) of K_0.
        dx_mass: The mass measure.
        dx_elastic: The elastic energy's measure.

    Returns:
        The UFL form D, or None if both coefficients are 0.
    """
    d = u - u_anchor
    form = None
    if not (isinstance(alpha, (int, float)) and alpha == 0):
        form = coefficient * alpha * 0.5 * rho * ufl.inner(d, d) * dx_mass
    if not (isinstance(beta, (int, float)) and beta == 0):
        term = coefficient * beta * linear.psi(deformation_gradient(d), mu, lmbda) * dx_elastic
        form = term if form is None else form + term
    return form
