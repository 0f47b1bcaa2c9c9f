"""Hessian modification for indefinite Newton systems (seed section 3.2.2, note 4).

Remedies for a Hessian H of the step objective that is not positive definite (large
compression, buckling, inverting elements), selected by ``solver.hessian``:

``shift``
    A = H + c I (seed note 4), with c adapted: raised (doubled, from a floor relative to
    the diagonal of H) until the factorisation shows no negative pivot (MUMPS/PETSc
    Cholesky inertia), lowered (quartered) after each success so that Newton returns to
    the exact Hessian, and to quadratic convergence, as soon as H is positive definite.
``project`` (clamp)
    Projected Newton (Teran et al. 2005; Kim and Eberle, "Dynamic Deformables"): the
    material tangent d^2 psi/dF^2 (a d^2 x d^2 matrix per quadrature point) is evaluated by
    a compiled UFL expression, its negative eigenvalues are clamped to zero in one
    batched numpy ``eigh``, and the elastic Hessian is assembled from the projection by a
    UFL form. Each element's Hessian w G^T A G (seed eqs. 31-34) is then positive
    semi-definite, the inertia term adds M > 0, and every Newton direction is a descent
    direction. For P1 elements (one quadrature point) this is exactly the per-element
    projection of the F-space Hessian.
``abs``
    Absolute eigenvalue filtering (Chen, Liu, Levin, Zheng, Jacobson, SIGGRAPH 2024): the
    negative eigenvalues of the tangent are replaced by their absolute values,
    V |L| V^T. Where clamping throws the negative curvature away (a direction in which the
    model is flat, so Newton steps far along it), abs keeps its size; on large
    compressions it needs fewer iterations.
``trust_region_filter``
    Chen et al., "Trust-Region Eigenvalue Filtering for Projected Newton" (SIGGRAPH Asia
    2024): each Newton iteration chooses clamp or abs from the ratio rho of the actual
    decrease of the step objective g to the decrease predicted by the *unprojected*
    quadratic model along the previous step (:func:`model_ratio`): |rho - 1| < 0.01 (the
    exact model is accurate: close to the minimiser) -> clamp, else abs
    (:func:`trust_region_choice`). The first iteration of a step, without a previous
    step, uses abs.
``auto``
    Exact Newton while the step Hessian is positive definite; filtered only when and
    where it is not (Longva et al. 2023, "Pitfalls of Projection"). With a Cholesky
    factorisation each iteration assembles the exact Hessian and reads the inertia of its
    factorisation (MUMPS, no extra cost when it is positive definite); a negative pivot
    makes that iteration use the trust-region filter's choice instead. Krylov presets
    have no inertia: CG's negative curvature (DIVERGED_INDEFINITE_MAT) or a failed line
    search continue the step from its last iterate with abs, and with the exact Hessian
    again where the trust-region filter would clamp (|rho - 1| < 0.01).
    Filtering changes only the quadrature points whose tangent is not positive definite
    (:func:`filter_tangent`).

The mass and damping terms of the objective are convex and kept exact in all of them;
only the elastic tangent is filtered.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["FILTERS", "MODES", "ShiftStrategy", "abs_psd", "filter_tangent", "model_ratio",
           "positive_definite", "project_psd", "trust_radius", "trust_region_choice",
           "RHO_TOLERANCE"]

#: ``solver.hessian`` values.
MODES = ("exact", "shift", "project", "abs", "trust_region_filter", "auto")
#: |rho - 1| below which the trust-region filter clamps (Chen et al. 2024).
RHO_TOLERANCE = 0.01


def _blas_thread_setter():
    """OpenBLAS's ``openblas_set_num_threads`` / ``get`` as loaded by numpy (None if absent).

    numpy's batched ``eigh`` calls LAPACK once per small matrix, and a threaded OpenBLAS
    wakes its threads for each call, which costs far more than the call itself: the filters
    run it on one thread (:func:`_eigh_single_threaded`).
    """
    import ctypes

    try:
        with open("/proc/self/maps") as maps:
            paths = sorted({line.split()[-1] for line in maps if "blas" in line.split()[-1]})
    except OSError:
        return None
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        if hasattr(lib, "openblas_set_num_threads") and hasattr(lib, "openblas_get_num_threads"):
            return lib.openblas_set_num_threads, lib.openblas_get_num_threads
    return None


_BLAS = []  # the setter, found on first use


def _eigh_single_threaded(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.linalg.eigh`` of a stack of small matrices with BLAS on one thread."""
    if not _BLAS:
        _BLAS.append(_blas_thread_setter())
    if _BLAS[0] is None:
        return np.linalg.eigh(a)
    set_threads, get_threads = _BLAS[0]
    threads = get_threads()
    set_threads(1)
    try:
        return np.linalg.eigh(a)
    finally:
        set_threads(threads)


def positive_definite(a: np.ndarray) -> np.ndarray:
    """Which matrices of a symmetric stack ``(n, m, m)`` are positive definite.

    Gaussian elimination without pivoting, vectorised over the stack: a symmetric matrix
    is positive definite iff every pivot is > 0 (Sylvester's criterion). m numpy steps
    instead of n eigendecompositions.
    """
    work = np.array(a, dtype=float, copy=True)
    ok = np.ones(work.shape[0], dtype=bool)
    with np.errstate(all="ignore"):  # a tiny pivot: inf or NaN below it, flagged not PD
        for k in range(work.shape[1]):
            pivot = work[:, k, k]
            ok &= pivot > 0.0
            safe = np.where(pivot > 0.0, pivot, 1.0)
            work[:, k + 1:, k + 1:] -= work[:, k + 1:, k, None] * work[:, None, k, k + 1:] / \
                safe[:, None, None]
    return ok


def filter_tangent(tangent: np.ndarray, how: str) -> np.ndarray:
    """Filter the negative eigenvalues of a stack of symmetric matrices.

    Matrices that are positive definite (:func:`positive_definite`) are returned as given
    (symmetrised); the others as V f(L) V^T with f(l) = max(l, 0) (``"clamp"``) or |l|
    (``"abs"``), the eigenvectors kept (one batched ``eigh`` of those only).

    Args:
        tangent: ``(n, m, m)`` matrices, e.g. d^2 psi/dF^2 per quadrature point
            (symmetrised here against round-off).
        how: ``"clamp"`` or ``"abs"``.

    Returns:
        ``(n, m, m)`` positive semi-definite matrices.
    """
    sym = 0.5 * (tangent + np.swapaxes(tangent, 1, 2))
    candidates = np.flatnonzero(~positive_definite(sym))
    if candidates.size == 0:
        return sym
    eigenvalues, vectors = _eigh_single_threaded(sym[candidates])
    negative = eigenvalues[:, 0] < 0.0
    if not negative.any():
        return sym
    filtered = np.maximum(eigenvalues[negative], 0.0) if how == "clamp" else \
        np.abs(eigenvalues[negative])
    v = vectors[negative]
    rebuilt = np.einsum("nij,nj,nkj->nik", v, filtered, v)
    sym[candidates[negative]] = 0.5 * (rebuilt + np.swapaxes(rebuilt, 1, 2))  # symmetric
    return sym


def project_psd(tangent: np.ndarray) -> np.ndarray:
    """Clamp the negative eigenvalues of a stack of symmetric matrices to zero."""
    return filter_tangent(tangent, "clamp")


def abs_psd(tangent: np.ndarray) -> np.ndarray:
    """Replace the negative eigenvalues of a stack of symmetric matrices by |lambda|."""
    return filter_tangent(tangent, "abs")


#: Filter name -> the per-point map
#: (:class:`fem_anim.problem.quadrature.QuadratureData` calls it).
FILTERS = {"clamp": project_psd, "abs": abs_psd}


def model_ratio(actual: float, slope: float, curvature: float, alpha: float) -> float:
    """rho = actual decrease / decrease predicted by the exact quadratic model.

    The step x_{k+1} = x_k - alpha y from x_k along y; the model of g at x_k is
    m(-alpha y) = g_k - alpha r.y + alpha^2/2 y^T H y (r = grad g(x_k), H the unprojected
    Hessian), so the predicted decrease is alpha s - alpha^2 c / 2 with s = r.y and
    c = y^T H y.

    Args:
        actual: g(x_k) - g(x_{k+1}).
        slope: s = r . y.
        curvature: c = y^T H y (may be negative: H is the exact Hessian).
        alpha: The line-search step length.

    Returns:
        rho (NaN when the predicted decrease is zero).
    """
    predicted = alpha * slope - 0.5 * alpha * alpha * curvature
    return actual / predicted if predicted != 0.0 else float("nan")


def trust_region_choice(rho: float | None) -> str:
    """The filter of the next iteration: ``"clamp"`` if |rho - 1| < 0.01, else ``"abs"``.

    ``None`` (no previous step) or NaN choose ``"abs"``.
    """
    if rho is not None and abs(rho - 1.0) < RHO_TOLERANCE:
        return "clamp"
    return "abs"


def trust_radius(radius: float, rho: float, alpha: float, length: float) -> float:
    """The trust radius after a step alpha y (``length`` = ||y||) whose actual decrease of g
    was rho times the exact quadratic model's (Nocedal & Wright, Algorithm 4.1, with the
    line search of a line-search Newton inside: the step may be shorter than the direction).

    * rho < 1/4: the model was poor: a quarter of the step taken;
    * the line search shortened a direction whose model then held (rho > 3/4): half the
      direction (its full length failed the sufficient-decrease test; PETSc's backtracking
      cuts lambda to 0.1 at once, which would under-rate the model's reach tenfold);
      otherwise the step taken;
    * a full step to the boundary (||y|| >= 0.99 radius) with rho > 3/4: twice the radius,
      four times when the model was exact to 10 % (|rho - 1| < 0.1);
    * else unchanged. A NaN rho (no predicted decrease) leaves the radius unchanged.
    """
    taken = abs(alpha) * length
    if not np.isfinite(rho):
        return radius
    if rho < 0.25:
        return 0.25 * taken
    if alpha < 1.0 - 1e-12:
        return 0.5 * length if rho > 0.75 else taken
    if rho > 0.75 and length >= 0.99 * radius:
        return radius * (4.0 if abs(rho - 1.0) < 0.1 else 2.0)
    return radius


@dataclass
class ShiftStrategy:
    """The adaptive shift c of A = H + c I (seed note 4).

    Attributes:
        floor: Smallest positive shift relative to max |diag H|.
        c: Current shift (absolute), kept between Newton iterations and steps.
        raises: Number of times c was raised (reported per step).
    """

    floor: float = 1e-8
    c: float = 0.0
    raises: int = 0

    def first(self, diagonal_scale: float) -> float:
        """The shift to try first: the remembered one (zero after enough successes)."""
        if self.c < self.floor * diagonal_scale:
            self.c = 0.0
        return self.c

    def raise_shift(self, diagonal_scale: float) -> float:
        """A failed factorisation: double c (at least the floor)."""
        self.raises += 1
        self.c = max(2.0 * self.c, self.floor * diagonal_scale)
        return self.c

    def succeeded(self) -> None:
        """A successful factorisation: lower c for the next attempt."""
        self.c *= 0.25
