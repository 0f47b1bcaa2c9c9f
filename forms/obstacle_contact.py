"""Contact with static obstacles as an energy: a smooth log barrier and lagged friction.

Following Incremental Potential Contact (Li et al. 2020), contact is a potential added to
E(x) in the step objective g(x) = 1/2 ||x - y||_M^2 + w E(x) (seed eq. 4), so each step
stays a minimisation. With d(x) the signed distance of a boundary point x = X + u to an
obstacle and d_hat the activation distance, the barrier

    b(d) = -(d - d_hat)^2 ln(d / d_hat)   for 0 < d < d_hat,   0 for d >= d_hat,

is C^2 at d_hat (b, b', b'' all vanish there) and tends to +inf as d -> 0. The contact
energy integrates it over the body's boundary,

    E_c(u) = kappa / d_hat  int_dOmega b(d(X + u)) dA,

so ``kappa`` is a pressure (Pa): the contact pressure is p = -kappa b'(d)/d_hat
= kappa [2 (1 - s) ln(1/s) + (1 - s)^2 / s] with s = d / d_hat, e.g. 12.2 kappa at
s = 0.1 and 0.03 kappa at s = 0.9. The measure decides where the barrier acts: the
vertex rule (P1) puts it on the boundary vertices with their share of the boundary
area, as IPC's vertex-obstacle constraints.

Friction (IPC section 5, lagged): with the contact pressure p_n and the obstacle normal
n_n frozen at the start of the step (x_n), the tangential displacement over the step
u_T = (I - n_n n_n^T)(u - u_n) and the smoothing length eps = eps_v h, the dissipation
potential

    D(u) = mu  int_dOmega p_n f0(|u_T|) dA,
    f0(y) = -y^3 / (3 eps^2) + y^2 / eps + eps / 3  (y < eps),   y  (y >= eps),

has gradient mu p_n f1(|u_T|) u_T/|u_T| with f1 = f0' rising from 0 to 1 at |u_T| = eps:
Coulomb friction of magnitude mu p_n once the point slides faster than eps_v, a stiff
viscous stick below. Added with the weight w of E, its stationarity term is the friction
force. Everything here is pure UFL of its arguments.
"""

from __future__ import annotations

import ufl

__all__ = ["plane_distance", "sphere_distance", "sphere_normal", "barrier",
           "barrier_derivative", "contact_energy", "friction_potential", "smoothed_slip"]


def plane_distance(x, point, normal):
    """Signed distance d = n . (x - p) to the plane bounding the half space n . (x - p) >= 0.

    Args:
        x: The deformed position X + u.
        point: A point p of the plane.
        normal: Its unit normal n, pointing into the free half space.
    """
    return ufl.dot(normal, x - point)


def sphere_distance(x, center, radius):
    """Signed distance d = |x - c| - r to a sphere (positive outside).

    Args:
        x: The deformed position X + u.
        center: The centre c.
        radius: The radius r (m).
    """
    r = x - center
    return ufl.sqrt(ufl.dot(r, r)) - radius


def sphere_normal(x, center):
    """The outward unit normal (x - c)/|x - c| of a sphere at the point nearest to x.

    Args:
        x: The deformed position X + u.
        center: The centre c.
    """
    r = x - center
    return r / ufl.sqrt(ufl.dot(r, r))


def barrier(d, dhat):
    """The barrier b(d) = -(d - d_hat)^2 ln(d / d_hat) on (0, d_hat), 0 beyond (m^2).

    Args:
        d: The signed distance (m).
        dhat: The activation distance d_hat (m).
    """
    return ufl.conditional(ufl.lt(d, dhat), -(d - dhat) ** 2 * ufl.ln(d / dhat), 0.0)


def barrier_derivative(d, dhat):
    """The barrier's slope b'(d) = -2 (d - d_hat) ln(d / d_hat) - (d - d_hat)^2 / d, 0 beyond.

    Args:
        d: The signed distance (m).
        dhat: The activation distance d_hat (m).
    """
    return ufl.conditional(ufl.lt(d, dhat),
                           -2.0 * (d - dhat) * ufl.ln(d / dhat) - (d - dhat) ** 2 / d, 0.0)


def contact_energy(d, dhat, kappa, ds: ufl.Measure):
    """The contact energy E_c = kappa / d_hat int b(d) dA (J).

    Args:
        d: The signed distance of the boundary points (m).
        dhat: The activation distance d_hat (m).
        kappa: The barrier stiffness (Pa).
        ds: The contact measure over the boundary.
    """
    return kappa / dhat * barrier(d, dhat) * ds


def smoothed_slip(y2, eps):
    """f0(y) of IPC's friction, written in y^2 = |u_T|^2 so that it is smooth at y = 0.

    The cubic term y^3 = y^2 sqrt(y^2) is taken as 0 at y = 0 (its value and first two
    derivatives vanish there), where UFL's derivative of sqrt would be 0/0.

    Args:
        y2: The squared tangential slip |u_T|^2 (m^2).
        eps: The smoothing length eps_v h (m).
    """
    y = ufl.sqrt(y2)
    cubic = ufl.conditional(ufl.gt(y2, 0.0), y2 * y, 0.0)
    return ufl.conditional(ufl.lt(y2, eps * eps), -cubic / (3.0 * eps * eps) + y2 / eps
                           + eps / 3.0, y)


def friction_potential(u, u_n, normal_n, pressure_n, mu, eps, ds: ufl.Measure):
    """The lagged friction potential D = mu int p_n f0(|(I - n_n n_n^T)(u - u_n)|) dA (J).

    Args:
        u: The displacement.
        u_n: The displacement at the step start.
        normal_n: The obstacle normal n_n at the step start.
        pressure_n: The contact pressure p_n at the step start (Pa).
        mu: The friction coefficient.
        eps: The smoothing length eps_v h (m).
        ds: The contact measure over the boundary.
    """
    du = u - u_n
    u_T = du - ufl.dot(normal_n, du) * normal_n
    return mu * pressure_n * smoothed_slip(ufl.dot(u_T, u_T), eps) * ds
