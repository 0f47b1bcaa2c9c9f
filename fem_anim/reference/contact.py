"""Contact barrier against static obstacles, in numpy (the oracle for :mod:`forms.contact`).

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
"""

from __future__ import annotations

import itertools
import math

import numpy as np
import scipy.sparse as sp

__all__ = ["boundary_facets", "vertex_areas", "barrier", "barrier_derivatives",
           "contact_energy", "contact_gradient", "contact_hessian", "signed_distance"]


def boundary_facets(cells: np.ndarray) -> np.ndarray:
    """Facets (sorted vertex tuples) that belong to exactly one simplex, ``(n, d)``."""
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
    """E_c(x) = kappa/d_hat sum_v A_v b(d(x_v)) (J)."""
    _, d, _, _, scale = _terms(points, cells, x, obstacle)
    return float(np.sum(scale * barrier(d, obstacle["dhat"])))


def contact_gradient(points, cells, x, obstacle) -> np.ndarray:
    """grad E_c, a dof vector."""
    vertices, d, grad, _, scale = _terms(points, cells, x, obstacle)
    db, _ = barrier_derivatives(d, obstacle["dhat"])
    dim = points.shape[1]
    out = np.zeros(points.shape[0] * dim)
    out.reshape(-1, dim)[vertices] = (scale * db)[:, None] * grad
    return out


def contact_hessian(points, cells, x, obstacle) -> sp.csr_matrix:
    """Hess E_c, block diagonal (one dim x dim block per boundary vertex)."""
    vertices, d, grad, hess, scale = _terms(points, cells, x, obstacle)
    db, d2b = barrier_derivatives(d, obstacle["dhat"])
    blocks = scale[:, None, None] * (d2b[:, None, None] * np.einsum("ni,nj->nij", grad, grad)
                                     + db[:, None, None] * hess)
    dim = points.shape[1]
    n = points.shape[0] * dim
    pairs = list(itertools.product(range(dim), range(dim)))
    rows = np.concatenate([vertices * dim + i for i, _ in pairs])
    cols = np.concatenate([vertices * dim + j for _, j in pairs])
    vals = np.concatenate([blocks[:, i, j] for i, j in pairs])
    return sp.csr_matrix((vals, (rows, cols)), shape=(n, n))
