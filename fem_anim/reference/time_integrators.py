"""Time integrators written as minimisations (seed section 3.1).

Each implicit step minimises the step objective (seed eq. (4))

    g(x) = 1/2 ||x - y||_M^2 + c E(x),      grad g = M (x - y) + c grad E,

whose stationarity ``M (x - y) = c f(x)`` is the integrator's update; ``y`` (the inertial
predictor) and ``c`` depend on the scheme:

::

    ==================  ===============================================  ==========
    scheme              y                                                c
    ==================  ===============================================  ==========
    Newmark (trap.)     x_n + h v_n + h^2/4 a_n           (eqs. (1)-(3))  h^2/4
    implicit Euler      x_n + h v_n                                       h^2
    BDF2                4/3 x_n - 1/3 x_{n-1} + 8h/9 v_n - 2h/9 v_{n-1}   4h^2/9
    ==================  ===============================================  ==========

followed by the velocity (and acceleration) updates in the step functions. Symplectic Euler
is the explicit baseline. Pinned dofs keep their position, with zero velocity and
acceleration; accelerations ``M^{-1} f`` solve ``M_ff a_f = f_f`` on the free dofs.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fem_anim.reference.newton import minimize_newton
from fem_anim.reference.potential import EnergyProblem, build_problem

__all__ = [
    "INTEGRATORS",
    "State",
    "Trajectory",
    "bdf2_step",
    "implicit_euler_step",
    "initial_state",
    "newmark_step",
    "simulate",
    "symplectic_euler_step",
]


@dataclass(frozen=True)
class State:
    """Positions and velocities at ``t_n``, plus what a scheme carries between steps.

    Attributes:
        x: Positions ``x_n``, ``(n_dofs,)``.
        v: Velocities ``v_n``, ``(n_dofs,)``.
        a: Newmark acceleration ``a_n`` (computed as ``M^{-1} f(x_n)`` when ``None``).
        x_prev: ``x_{n-1}`` for BDF2 (``None`` on the first step).
        v_prev: ``v_{n-1}`` for BDF2.
    """

    x: np.ndarray
    v: np.ndarray
    a: np.ndarray | None = None
    x_prev: np.ndarray | None = None
    v_prev: np.ndarray | None = None


def initial_state(problem: EnergyProblem, x0: np.ndarray, v0: np.ndarray | None = None) -> State:
    """State at ``t = 0`` with the velocity of pinned dofs set to zero.

    Args:
        problem: The potential energy, mass matrix and pins.
        x0: Initial positions, a dof vector.
        v0: Initial velocities (default zero).
    """
    x0 = np.array(x0, dtype=float)
    v0 = np.zeros_like(x0) if v0 is None else np.array(v0, dtype=float)
    return State(x=x0, v=np.where(problem.pinned, 0.0, v0))


def _minimize_step(problem: EnergyProblem, state: State, y: np.ndarray, c: float, **newton):
    """Minimise ``1/2 ||x - y||_M^2 + c E(x)`` over the free dofs from ``x_n``."""
    M = problem.mass

    def objective(x):
        r = x - y
        return 0.5 * r @ (M @ r) + c * problem.energy(x)

    def gradient(x):
        return M @ (x - y) + c * problem.gradient(x)

    def hessian(x):
        return M + c * problem.hessian(x)

    return minimize_newton(objective, gradient, hessian, state.x, problem.free, **newton)


def _advance(problem: EnergyProblem, state: State, x, v, a=None) -> State:
    """Next state; velocities (and accelerations) vanish on pinned dofs."""
    pinned = problem.pinned
    a = None if a is None else np.where(pinned, 0.0, a)
    return State(x=x, v=np.where(pinned, 0.0, v), a=a, x_prev=state.x, v_prev=state.v)


def newmark_step(problem: EnergyProblem, state: State, dt: float, **newton) -> tuple[State, int]:
    """Implicit Newmark (trapezoidal rule) step, seed eqs. (1)-(4).

    ``y = x_n + h v_n + h^2/4 a_n``, ``c = h^2/4``; then ``a_{n+1} = 4/h^2 (x - y)`` and
    ``v_{n+1} = v_n + h/2 (a_n + a_{n+1})``.

    Args:
        problem: Energy, mass matrix and pins.
        state: Current state.
        dt: Time step ``h``.
        **newton: Keyword arguments of :func:`~fem_anim.reference.newton.minimize_newton`
            (``atol``, ``rtol``, ``max_iterations``, ...).

    Returns:
        ``(next state, Newton iterations)``.
    """
    h = dt
    a = problem.accelerate(problem.force(state.x)) if state.a is None else state.a
    y = state.x + h * state.v + h**2 / 4 * a
    x, iterations = _minimize_step(problem, state, y, h**2 / 4, **newton)
    a_next = 4.0 / h**2 * (x - y)
    return _advance(problem, state, x, state.v + h / 2 * (a + a_next), a_next), iterations


def implicit_euler_step(
    problem: EnergyProblem, state: State, dt: float, **newton
) -> tuple[State, int]:
    """Implicit (backward) Euler step: ``y = x_n + h v_n``, ``c = h^2``, ``v_{n+1} = (x - x_n)/h``.

    Arguments and return as in :func:`newmark_step`.
    """
    h = dt
    x, iterations = _minimize_step(problem, state, state.x + h * state.v, h**2, **newton)
    return _advance(problem, state, x, (x - state.x) / h), iterations


def bdf2_step(problem: EnergyProblem, state: State, dt: float, **newton) -> tuple[State, int]:
    """Second-order backward differentiation step (implicit Euler when no history yet).

    ``y = 4/3 x_n - 1/3 x_{n-1} + 8h/9 v_n - 2h/9 v_{n-1}``, ``c = 4h^2/9``,
    ``v_{n+1} = 3/(2h) (x - 4/3 x_n + 1/3 x_{n-1})``.

    Arguments and return as in :func:`newmark_step`.
    """
    if state.x_prev is None:
        return implicit_euler_step(problem, state, dt, **newton)
    h = dt
    y = 4 / 3 * state.x - 1 / 3 * state.x_prev + 8 * h / 9 * state.v - 2 * h / 9 * state.v_prev
    x, iterations = _minimize_step(problem, state, y, 4 * h**2 / 9, **newton)
    v = 3 / (2 * h) * (x - 4 / 3 * state.x + 1 / 3 * state.x_prev)
    return _advance(problem, state, x, v), iterations


def symplectic_euler_step(
    problem: EnergyProblem, state: State, dt: float, **newton
) -> tuple[State, int]:
    """Explicit symplectic Euler step (the explicit baseline; no solve but ``M^{-1}``).

    ``v_{n+1} = v_n + h M^{-1} f(x_n)``, ``x_{n+1} = x_n + h v_{n+1}``. Newton options are
    accepted and ignored; the iteration count is 0.
    """
    v = state.v + dt * problem.accelerate(problem.force(state.x))
    v = np.where(problem.pinned, 0.0, v)
    return _advance(problem, state, state.x + dt * v, v), 0


INTEGRATORS: dict[str, Callable[..., tuple[State, int]]] = {
    "newmark": newmark_step,
    "implicit_euler": implicit_euler_step,
    "bdf2": bdf2_step,
    "symplectic_euler": symplectic_euler_step,
}
"""Step functions by name."""


@dataclass(frozen=True)
class Trajectory:
    """Result of :func:`simulate`: times ``(steps+1,)``, positions and velocities
    ``(steps+1, n_dofs)`` and Newton iterations per step ``(steps,)``."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    iterations: np.ndarray


def simulate(
    points: np.ndarray,
    cells: np.ndarray,
    material: str,
    E: float,
    nu: float,
    rho,
    gravity,
    pinned_mask: np.ndarray | None,
    integrator: str,
    dt: float,
    steps: int,
    *,
    x0: np.ndarray | None = None,
    v0: np.ndarray | None = None,
    lumped: bool = False,
    **newton,
) -> Trajectory:
    """Integrate an elastic body from ``x0`` (default: rest positions) for ``steps`` steps.

    Args:
        points: Reference vertex positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d+1)``.
        material: Material model name.
        E: Young's modulus.
        nu: Poisson's ratio.
        rho: Density, scalar or ``(n_cells,)``.
        gravity: Gravitational acceleration ``(d,)`` or ``None``.
        pinned_mask: Boolean mask of the dofs held fixed, or ``None``.
        integrator: One of :data:`INTEGRATORS`.
        dt: Time step.
        steps: Number of steps.
        x0: Initial positions (default ``points.ravel()``).
        v0: Initial velocities (default zero).
        lumped: Use the lumped mass matrix.
        **newton: Options of :func:`~fem_anim.reference.newton.minimize_newton`.

    Raises:
        ValueError: On an unknown integrator, ``dt <= 0`` or ``steps < 0``.
    """
    if integrator not in INTEGRATORS:
        raise ValueError(f"integrator must be one of {tuple(INTEGRATORS)}, got {integrator!r}")
    if not dt > 0.0:
        raise ValueError(f"dt must be positive, got {dt}")
    if steps < 0:
        raise ValueError(f"steps must be non-negative, got {steps}")
    problem = build_problem(points, cells, material, E, nu, rho, gravity, pinned_mask, lumped)
    state = initial_state(problem, problem.points.ravel() if x0 is None else x0, v0)
    step = INTEGRATORS[integrator]
    xs, vs, iterations = [state.x], [state.v], []
    for _ in range(steps):
        state, its = step(problem, state, dt, **newton)
        xs.append(state.x)
        vs.append(state.v)
        iterations.append(its)
    return Trajectory(
        t=dt * np.arange(steps + 1),
        x=np.array(xs),
        v=np.array(vs),
        iterations=np.array(iterations, dtype=int),
    )
