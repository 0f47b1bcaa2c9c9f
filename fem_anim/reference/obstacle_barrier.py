"""Contact barrier against static obstacles, in numpy.

The oracle for :mod:`fem_anim.forms.obstacle_contact` and
:class:`fem_anim.contact.obstacles.ObstacleContact`.

For P1 the contact energy is integrated with the vertex rule on the boundary facets, so

    E_c(x) = kappa / d_hat  sum_v A_v b(d(x_v)),    A_v = sum_{facets f containing v} |f| / d,

(d the dimension: a facet has d vertices), with the barrier of Li et al. (2020)
b(d) = -(d - d_hat)^2 ln(d / d_hat) on (0, d_hat) and 0 beyond. Its gradient and Hessian
are per vertex: kappa/d_hat A_v b'(d) grad d and kappa/d_hat A_v (b''(d) grad d grad d^T
+ b'(d) Hess d), with grad d = n, Hess d = 0 for a plane n . (x - p) and
grad d = r/|r|, Hess d = (I - r r^T/|r|^2)/|r| for a sphere |r| - R, r = x - c.

An obstacle is a dict as in the scene's ``[[obstacle]]`` table: ``type`` ``"plane"``
(``point``, ``normal``) or ``"sphere"`` (``center``, ``radius``), with ``dhat`` and
``stiffness``. Positions ``x`` are dof vectors, vertex-major (:mod:`.geometry`).

Lagged friction (IPC section 5; :mod:`fem_anim.forms.obstacle_contact`) with the same vertex
rule: with x_n the positions at the start of the step, p_v = -kappa/d_hat b'(d(x_{n,v})) the
frozen pressure, n_v the obstacle's unit normal at x_{n,v} (plane: n; sphere:
(x_{n,v} - c)/|x_{n,v} - c|), u_v = (I - n_v n_v^T)(x_v - x_{n,v}) and y_v = |u_v|,

    D(x) = mu sum_v A_v p_v f0(y_v),    grad_v D = mu A_v p_v f1(y_v) u_v / y_v,

f0(y) = -y^3/(3 eps^2) + y^2/eps + eps/3 and f1(y) = f0'(y) = 2y/eps - y^2/eps^2 below
eps, f0 = y and f1 = 1 above (so f1(y)/y = 2/eps - y/eps^2 stays finite at y = 0).
The sphere's Hessian with the curvature term b' Hess d dropped (IPC's projection of the
negative tangential eigenvalues,
:meth:`fem_anim.contact.obstacles.ObstacleContact.curvature_correction`) is
:func:`contact_hessian` with ``projected=True``.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import scipy.sparse as sp

__all__ = ["boundary_facets", "vertex_areas", "barrier", "barrier_derivatives",
           "contact_energy", "contact_gradient", "contact_hessian", "signed_distance",
           "smoothed_slip", "friction_energy", "friction_gradient"]


def boundary_facets(cells: np.ndarray) -> np.ndarray:
    """Facets that belong to exactly one simplex.

    Args:
        cells: Simplices, ``(n_cells, d + 1)``.

    Returns:
        The boundary facets as sorted vertex tuples, ``(n, d)``.
    """
    k = cells.shape[1]
    faces = np.concatenate([np.delete(cells, i, axis=1) for i in range(k)])
    faces = np.sort(faces, axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    return unique[counts == 1]


def vertex_areas(points: np.ndarray, facets: np.ndarray) -> np.ndarray:
    """A_v: each boundary facet's measure shared equally by its d vertices."""
    d = points.shape[1]
    P = points[facets]
    edges = P[:, 1:] - P[:, :1]  # (n, d - 1, d)
    gram = np.einsum("nik,njk->nij", edges, edges)
    measure = np.sqrt(np.linalg.det(gram)) / math.factorial(d - 1)
    areas = np.zeros(points.shape[0])
    np.add.at(areas, facets.ravel(), np.repeat(measure / d, d))
    return areas


def barrier(d: np.ndarray, dhat: float) -> np.ndarray:
    """b(d) = -(d - d_hat)^2 ln(d / d_hat) for d < d_hat, else 0 (d > 0)."""
    active = d < dhat
    out = np.zeros_like(d)
    out[active] = -(d[active] - dhat) ** 2 * np.log(d[active] / dhat)
    return out


def barrier_derivatives(d: np.ndarray, dhat: float) -> tuple[np.ndarray, np.ndarray]:
    """b'(d) and b''(d) (zero for d >= d_hat)."""
    active = d < dhat
    a, t = d[active], d[active] - dhat
    db, d2b = np.zeros_like(d), np.zeros_like(d)
    db[active] = -2.0 * t * np.log(a / dhat) - t ** 2 / a
    d2b[active] = -2.0 * np.log(a / dhat) - 4.0 * t / a + t ** 2 / a ** 2
    return db, d2b


def signed_distance(y: np.ndarray, obstacle: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """d, grad d (n, dim) and Hess d (n, dim, dim) at the points ``y`` (n, dim)."""
    dim = y.shape[1]
    if obstacle["type"] == "plane":
        n = np.asarray(obstacle["normal"], float)
        n = n / np.linalg.norm(n)
        point = np.asarray(obstacle.get("point") or np.zeros(dim), float)
        d = (y - point) @ n
        return d, np.tile(n, (len(y), 1)), np.zeros((len(y), dim, dim))
    r = y - np.asarray(obstacle["center"], float)
    norm = np.linalg.norm(r, axis=1)
    unit = r / norm[:, None]
    hess = (np.eye(dim) - np.einsum("ni,nj->nij", unit, unit)) / norm[:, None, None]
    return norm - obstacle["radius"], unit, hess


def _terms(points, cells, x, obstacle):
    facets = boundary_facets(cells)
    vertices = np.unique(facets)
    dim = points.shape[1]
    y = np.asarray(x, float).reshape(-1, dim)[vertices]
    d, grad, hess = signed_distance(y, obstacle)
    if np.any(d <= 0.0):
        raise ValueError("a boundary vertex lies on or inside the obstacle")
    scale = obstacle["stiffness"] / obstacle["dhat"] * vertex_areas(points, facets)[vertices]
    return vertices, d, grad, hess, scale


def contact_energy(points, cells, x, obstacle) -> float:
    """The contact energy E_c(x) = kappa/d_hat sum_v A_v b(d(x_v)) (J).

    Args:
        points: Rest positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.
        x: Deformed positions, a dof vector (vertex-major).
        obstacle: An ``[[obstacle]]`` table (``type``, its geometry, ``dhat``, ``stiffness``).
    """
    _, d, _, _, scale = _terms(points, cells, x, obstacle)
    return float(np.sum(scale * barrier(d, obstacle["dhat"])))


def contact_gradient(points, cells, x, obstacle) -> np.ndarray:
    """grad E_c as a dof vector (arguments as in :func:`contact_energy`)."""
    vertices, d, grad, _, scale = _terms(points, cells, x, obstacle)
    db, _ = barrier_derivatives(d, obstacle["dhat"])
    dim = points.shape[1]
    out = np.zeros(points.shape[0] * dim)
    out.reshape(-1, dim)[vertices] = (scale * db)[:, None] * grad
    return out


def contact_hessian(points, cells, x, obstacle, projected: bool = False) -> sp.csr_matrix:
    """Hess E_c, block diagonal (one dim x dim block per boundary vertex).

    ``projected``: without the curvature term b' Hess d (zero for a plane; for a sphere the
    negative tangential eigenvalues that IPC's per-contact projection removes).
    """
    vertices, d, grad, hess, scale = _terms(points, cells, x, obstacle)
    db, d2b = barrier_derivatives(d, obstacle["dhat"])
    if projected:
        hess = np.zeros_like(hess)
    blocks = scale[:, None, None] * (d2b[:, None, None] * np.einsum("ni,nj->nij", grad, grad)
                                     + db[:, None, None] * hess)
    dim = points.shape[1]
    n = points.shape[0] * dim
    pairs = list(itertools.product(range(dim), range(dim)))
    rows = np.concatenate([vertices * dim + i for i, _ in pairs])
    cols = np.concatenate([vertices * dim + j for _, j in pairs])
    vals = np.concatenate([blocks[:, i, j] for i, j in pairs])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))


def smoothed_slip(y: np.ndarray, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """f0(y) and f1(y)/y of the lagged friction (y >= 0)."""
    below = y < eps
    f0, f1_over_y = y.copy(), np.zeros_like(y)
    f0[below] = _f0_below(y[below], eps)
    f1_over_y[below] = 2.0 / eps - y[below] / eps ** 2
    f1_over_y[~below] = 1.0 / y[~below]
    return f0, f1_over_y


def _f0_below(y: np.ndarray, eps: float) -> np.ndarray:
    return -y ** 3 / (3.0 * eps ** 2) + y ** 2 / eps + eps / 3.0


def _friction_terms(points, cells, x, x_prev, obstacle, eps):
    vertices, d_prev, normal, _, scale = _terms(points, cells, x_prev, obstacle)
    db, _ = barrier_derivatives(d_prev, obstacle["dhat"])
    pressure = -obstacle["stiffness"] / obstacle["dhat"] * db
    dim = points.shape[1]
    du = (np.asarray(x, float) - np.asarray(x_prev, float)).reshape(-1, dim)[vertices]
    tangential = du - np.einsum("ni,ni->n", normal, du)[:, None] * normal
    y = np.linalg.norm(tangential, axis=1)
    f0, f1_over_y = smoothed_slip(y, eps)
    weight = obstacle["friction"] * scale * obstacle["dhat"] / obstacle["stiffness"] * pressure
    return vertices, weight, tangential, f0, f1_over_y


def friction_energy(points, cells, x, x_prev, obstacle, eps: float) -> float:
    """The lagged friction potential D(x) = mu sum_v A_v p_v f0(|u_v|) (J).

    Args:
        points: Rest positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.
        x: Deformed positions, a dof vector (vertex-major).
        x_prev: Positions at the start of the step (the lagged state).
        obstacle: An ``[[obstacle]]`` table with ``friction`` (mu).
        eps: The smoothing length eps_v h (m).
    """
    _, weight, _, f0, _ = _friction_terms(points, cells, x, x_prev, obstacle, eps)
    return float(np.sum(weight * f0))


def friction_gradient(points, cells, x, x_prev, obstacle, eps: float) -> np.ndarray:
    """grad D = mu A_v p_v f1(|u_v|) u_v / |u_v| per boundary vertex, a dof vector.

    Arguments as in :func:`friction_energy`.
    """
    vertices, weight, tangential, _, f1_over_y = _friction_terms(points, cells, x, x_prev,
                                                                 obstacle, eps)
    dim = points.shape[1]
    out = np.zeros(points.shape[0] * dim)
    out.reshape(-1, dim)[vertices] = (weight * f1_over_y)[:, None] * tangential
    return out
