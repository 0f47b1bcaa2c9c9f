"""Time integrators written as minimisations (seed section 3.1).

Every scheme advances x_n -> x_{n+1} by

    x_{n+1} = argmin_x  g(x) = 1/2 ||x - y||_M^2 + w E(x)                  (seed eq. 4)

with a predictor y built from the history and an energy weight w; the stationarity
condition M (x - y) + w grad E(x) = 0 is the scheme. Here E = elastic + gravitational
potential. The table below gives y, w and the velocity update for each scheme
(h the time step, f = -grad E, a = M^-1 f):

::

    ================  =================================================  ======  =================
    scheme            y                                                  w       v_{n+1}
    ================  =================================================  ======  =================
    newmark           x_n + h v_n + h^2/4 a_n  (seed eqs. 1-3)            h^2/4   v_n + h/2 (a_n +
                                                                                 a_{n+1})
    implicit_euler    x_n + h v_n                                         h^2     (x - x_n)/h
    bdf2              4/3 x_n - 1/3 x_{n-1} + 8h/9 v_n - 2h/9 v_{n-1}     4h^2/9  3/(2h) (x - x^)
    symplectic_euler  x_n + h v_n, E linearised at x_n (explicit)         h^2     (x - x_n)/h
    ================  =================================================  ======  =================

with x^ = 4/3 x_n - 1/3 x_{n-1}. For Newmark a_{n+1} = (x - y)/w follows from stationarity.
Newmark (the trapezoidal rule) is second order and conserves the energy of linear systems;
implicit Euler is first order and dissipates; BDF2 is second order and mildly dissipative.
Symplectic Euler is explicit: its objective is the quadratic 1/2 ||x - y||^2_M - h^2
f(x_n).x (one linear solve with M), and it is stable only for h < 2/omega_max, omega_max the
highest natural frequency of the discrete system, i.e. the largest generalised eigenvalue of
K phi = omega^2 M phi. It grows like c_p/h_min (c_p = sqrt((lmbda + 2 mu)/rho), h_min the
smallest element size) with a large mesh-dependent factor (``tests/test_integrators.py``
computes omega_max and checks the bound). It is a comparison baseline, not a production
integrator. Rayleigh damping, when declared, is taken implicitly in every scheme
(:mod:`.damping`).
"""

from __future__ import annotations

from dataclasses import dataclass


__all__ = ["Scheme", "SCHEMES", "step_objective"]


@dataclass(frozen=True)
class Scheme:
    """Coefficients of one scheme in the common form above.

    Attributes:
        name: Scene name (``time.integrator``).
        order: Order of accuracy in h.
        weight: w / h^2.
        explicit: Whether E is linearised at x_n (symplectic Euler) instead of taken at x.
        history: Number of previous states the predictor needs beyond x_n, v_n.
    """

    name: str
    order: int
    weight: float
    explicit: bool = False
    history: int = 0


SCHEMES = {
    "newmark": Scheme("newmark", 2, 0.25),
    "implicit_euler": Scheme("implicit_euler", 1, 1.0),
    "bdf2": Scheme("bdf2", 2, 4.0 / 9.0, history=1),
    "symplectic_euler": Scheme("symplectic_euler", 1, 1.0, explicit=True),
}


def step_objective(inertia, potential, weight):
    """The step objective g(x) = 1/2 ||x - y||_M^2 + w E(x) (seed eq. 4) as one UFL form.

    Args:
        inertia: The form 1/2 ||x - y||_M^2 (:func:`fem_anim.forms.inertia.inertia`).
        potential: The form E (elastic, gravity and other potentials).
        weight: The scheme's energy weight w (h^2/4 for Newmark).
    """
    return inertia + weight * potential
