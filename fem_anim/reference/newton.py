"""Newton's method with a backtracking (Armijo) line search (seed sections 3.2.1-3.3.1).

Minimises ``g(x)`` over the free dofs, the pinned ones keeping their value in ``x0``. The
Newton direction ``p = -(hess g)^{-1} grad g`` (seed eq. (10)) comes from a sparse LU
factorisation; where it is not a descent direction the Hessian is shifted by ``tau I``
(seed note 4) with growing ``tau``.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fem_anim.errors import ConvergenceError

__all__ = ["ConvergenceError", "minimize_newton"]


def _descent_direction(H: sp.spmatrix, grad: np.ndarray, max_shifts: int = 20) -> np.ndarray:
    """Newton direction, shifted if needed to descend (seed eq. (10) and note 4).

    Solves ``(H + tau I) p = -grad`` for the first ``tau`` in ``0, t0, 10 t0, ...`` (``t0`` =
    1e-8 max|diag H|) that gives ``grad . p < 0``; steepest descent if none does.
    """
    identity = sp.identity(H.shape[0], format="csc")
    H = H.tocsc()
    tau0 = 1e-8 * max(np.abs(H.diagonal()).max(initial=0.0), 1e-300)
    for attempt in range(max_shifts + 1):
        tau = 0.0 if attempt == 0 else tau0 * 10.0 ** (attempt - 1)
        try:
            p = spla.splu(H + tau * identity).solve(-grad)
        except RuntimeError:  # exactly singular
            continue
        if np.all(np.isfinite(p)) and grad @ p < 0.0:
            return p
    return -grad


def minimize_newton(
    objective: Callable[[np.ndarray], float],
    gradient: Callable[[np.ndarray], np.ndarray],
    hessian: Callable[[np.ndarray], sp.spmatrix],
    x0: np.ndarray,
    free: np.ndarray,
    *,
    atol: float = 1e-10,
    rtol: float = 1e-10,
    max_iterations: int = 50,
    armijo: float = 1e-4,
    max_backtracks: int = 40,
) -> tuple[np.ndarray, int]:
    """Minimise ``objective`` over ``x[free]`` by damped Newton.

    Stops when ``||grad g(x)_free|| <= atol + rtol ||grad g(x0)_free||``. Each step
    ``x += alpha p`` halves ``alpha`` from 1 until the Armijo condition
    ``g(x + alpha p) <= g(x) + armijo alpha grad g . p + 1e-12 |g(x)|`` holds (the last term
    absorbs round-off in ``g`` near convergence); an infinite or NaN ``g`` is rejected.

    Args:
        objective: ``g(x)``.
        gradient: ``grad g(x)``, full-length dense vector.
        hessian: ``hess g(x)``, full sparse matrix.
        x0: Initial guess; its pinned entries are kept.
        free: Boolean mask of the unknowns.
        atol: Absolute gradient-norm tolerance.
        rtol: Tolerance relative to the initial gradient norm.
        max_iterations: Newton iteration limit.
        armijo: Sufficient-decrease constant ``c1``.
        max_backtracks: Line-search halving limit.

    Returns:
        ``(x, iterations)``.

    Raises:
        ConvergenceError: If the line search or the iteration limit is exhausted.
    """
    x = np.array(x0, dtype=float)
    free = np.asarray(free, dtype=bool)
    g_x = objective(x)
    grad = gradient(x)[free]
    tolerance = atol + rtol * np.linalg.norm(grad)
    for iteration in range(max_iterations + 1):
        if np.linalg.norm(grad) <= tolerance:
            return x, iteration
        if iteration == max_iterations:
            break
        p = _descent_direction(hessian(x)[free][:, free], grad)
        slope = grad @ p
        alpha = 1.0
        for _ in range(max_backtracks):
            trial = x.copy()
            trial[free] += alpha * p
            g_trial = objective(trial)
            if g_trial <= g_x + armijo * alpha * slope + 1e-12 * abs(g_x):  # False for NaN
                break
            alpha *= 0.5
        else:
            raise ConvergenceError(
                f"line search failed at Newton iteration {iteration}: no sufficient decrease "
                f"after {max_backtracks} halvings (|grad| = {np.linalg.norm(grad):.3e})"
            )
        x, g_x = trial, g_trial
        grad = gradient(x)[free]
    raise ConvergenceError(
        f"Newton did not converge in {max_iterations} iterations: |grad| = "
        f"{np.linalg.norm(grad):.3e} > tolerance {tolerance:.3e}"
    )
