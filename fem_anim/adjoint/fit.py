"""Fitting parameters to an objective with scipy's L-BFGS-B and the adjoint gradient.

:func:`fit` minimises J(theta) of an :class:`~fem_anim.adjoint.differentiate.AdjointModel`
within bounds. L-BFGS-B works on scaled variables z_i = theta_i / s_i (s_i the starting
value's magnitude, or 1 for a parameter starting at 0) and on J / J(theta_0), so that
Young's modulus (1e4 Pa) and Poisson's ratio (0.3) weigh alike and the tolerances are
relative; each evaluation is one forward run and one backward sweep. Every evaluation is
reported (parameters, J, |dJ/dtheta|) to a callback; the iterations L-BFGS-B accepts are
marked.

Under MPI every rank runs the same optimiser on the same (reduced) values, so the iterates
agree on all ranks.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fem_anim.adjoint.cell_gradient import owned_cell_values

__all__ = ["DEFAULT_BOUNDS", "FitResult", "default_bounds", "fit"]

#: Bounds relative to the start (factor range) or absolute, per parameter kind.
DEFAULT_BOUNDS = {"material.youngs_modulus": ("factor", 1e-3, 1e3),
                  "material.density": ("factor", 1e-3, 1e3),
                  "material.poisson_ratio": ("absolute", -0.99, 0.499),
                  "damping.alpha": ("absolute", 0.0, None),
                  "damping.beta": ("absolute", 0.0, None),
                  "friction": ("factor", 1e-3, 1e3)}


def default_bounds(name: str, start: float) -> tuple[float | None, float | None]:
    """The bounds of a parameter without ``--bounds``: E and rho within a factor 1000 of
    the start, nu in (-0.99, 0.499) (a region's or body's too), damping coefficients
    non-negative, friction coefficients within a factor 1000 of the start, initial
    velocities, spins and displacements unbounded."""
    kind = next((v for k, v in DEFAULT_BOUNDS.items() if name == k or
                 name.endswith("." + k)), None)
    if kind is None:
        return None, None
    how, low, high = kind
    return (low * start, high * start) if how == "factor" else (low, high)


@dataclass
class FitResult:
    """The outcome of :func:`fit`.

    Attributes:
        theta: The best parameters found.
        value: J there.
        gradient: dJ/dtheta there.
        iterations: L-BFGS-B's iterations.
        evaluations: Forward and backward runs made.
        message: L-BFGS-B's final message.
        history: One dict per evaluation: ``theta``, ``value``, ``gradient_norm``,
            ``accepted`` (an iterate L-BFGS-B accepted).
    """

    theta: np.ndarray
    value: float
    gradient: np.ndarray
    iterations: int
    evaluations: int
    message: str
    history: list[dict] = field(default_factory=list)
    #: The gradient per cell there (:func:`~fem_anim.adjoint.cell_gradient.owned_cell_values`)
    cell_gradient: dict = field(default_factory=dict)


def fit(model, objective, bounds: list[tuple[float | None, float | None]] | None = None,
        max_iterations: int = 30, tolerance: float = 1e-10, report=None) -> FitResult:
    """Minimise J over the model's parameters from their current values (collective).

    Args:
        model: An :class:`~fem_anim.adjoint.differentiate.AdjointModel`.
        objective: Its :class:`~fem_anim.adjoint.objectives.Objective`.
        bounds: (low, high) per parameter (None: unbounded side); default
            :func:`default_bounds`.
        max_iterations: L-BFGS-B's iteration budget.
        tolerance: L-BFGS-B's ``ftol`` and ``gtol`` on the scaled problem.
        report: Called with each evaluation's history entry (None: nothing).

    Returns:
        The :class:`FitResult`.

    Raises:
        ConvergenceError: a forward step did not converge at some trial parameters.
    """
    from scipy.optimize import minimize

    theta0 = model.parameters.values()
    scale = np.where(theta0 != 0.0, np.abs(theta0), 1.0)
    if bounds is None:
        bounds = [default_bounds(n, t) for n, t in zip(model.names, theta0)]
    scaled_bounds = [(None if lo is None else lo / s, None if hi is None else hi / s)
                     for (lo, hi), s in zip(bounds, scale)]
    history: list[dict] = []
    best: dict = {}
    reference: list[float] = []

    def evaluate(z: np.ndarray) -> tuple[float, np.ndarray]:
        theta = z * scale
        value, grad = model.evaluate(theta, objective)
        if not reference:
            reference.append(value if value > 0.0 else 1.0)
        entry = {"theta": theta.copy(), "value": value,
                 "gradient_norm": float(np.linalg.norm(grad)), "accepted": False}
        history.append(entry)
        if not best or value < best["value"]:
            best.update(theta=theta.copy(), value=value, gradient=grad.copy(),
                        cells=owned_cell_values(model))
        if report is not None:
            report(entry)
        return value / reference[0], grad * scale / reference[0]

    def accepted(z: np.ndarray) -> None:
        for entry in reversed(history):
            if np.array_equal(entry["theta"], z * scale):
                entry["accepted"] = True
                break

    result = minimize(evaluate, theta0 / scale, jac=True, method="L-BFGS-B",
                      bounds=scaled_bounds, callback=accepted,
                      options={"maxiter": max_iterations, "ftol": tolerance,
                               "gtol": tolerance})
    model.parameters.assign(best["theta"])
    return FitResult(theta=best["theta"], value=best["value"], gradient=best["gradient"],
                     cell_gradient=best["cells"],
                     iterations=int(result.nit), evaluations=len(history),
                     message=str(result.message), history=history)
