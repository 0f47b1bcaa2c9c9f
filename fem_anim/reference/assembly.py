"""Global elastic energy, gradient and Hessian of a P1 mesh (seed eqs. (27) and (34)).

With ``vec(F_e) = G_e x_e`` (:func:`~fem_anim.reference.geometry.gradient_operator`) the
discrete energy is ``E(x) = sum_e w_e psi(F_e)`` (eq. (27b)), so by the chain rule

    grad E = sum_e  w_e G_e^T vec(P(F_e)),
    hess E = sum_e  w_e G_e^T (dP/dF)(F_e) G_e,

scattered to the global dofs of each element. ``mu`` and ``lmbda`` are scalars or per-cell
arrays of shape ``(n_cells,)``; ``material`` is a model name or a per-cell array of names
(a body of several materials: each model is evaluated on its own cells).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_anim.reference.geometry import cell_dofs, cell_volumes, check_mesh, gradient_operator
from fem_anim.reference.materials import first_piola, first_piola_derivative, psi
from fem_anim.reference.tensor import unvec, vec

__all__ = ["elastic_energy", "elastic_gradient", "elastic_hessian"]


def _element_kinematics(points, cells, x):
    """``(dofs, w, G, F)`` of every element for the dof vector ``x``."""
    points, cells = check_mesh(points, cells)
    d = points.shape[1]
    x = np.asarray(x, dtype=float)
    if x.shape != (points.size,):
        raise ValueError(f"x must have shape ({points.size},), got {x.shape}")
    dofs = cell_dofs(cells, d)
    G = gradient_operator(points, cells)
    F = unvec(np.einsum("nij,nj->ni", G, x[dofs]), d)
    return dofs, cell_volumes(points, cells), G, F


def _per_cell(function, material, F: np.ndarray, mu, lmbda) -> np.ndarray:
    """``function(material, F, mu, lmbda)`` with a model name per cell, one call per model."""
    if isinstance(material, str):
        return function(material, F, mu, lmbda)
    names = np.asarray(material)
    if names.shape != (F.shape[0],):
        raise ValueError(f"material must be a name or {F.shape[0]} names, got {names.shape}")
    n = F.shape[0]
    mu, lmbda = np.broadcast_to(mu, (n,)), np.broadcast_to(lmbda, (n,))
    out = None
    for name in np.unique(names):
        cells = names == name
        values = function(str(name), F[cells], mu[cells], lmbda[cells])
        if out is None:
            out = np.empty((n,) + values.shape[1:])
        out[cells] = values
    return out


def elastic_energy(points, cells, material: str, mu, lmbda, x: np.ndarray) -> float:
    """Total elastic energy ``E(x) = sum_e w_e psi(F_e)`` (seed eq. (27b)).

    Args:
        points: Reference vertex positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d+1)``.
        material: Name of a material model (see :data:`~fem_anim.reference.materials.MATERIALS`),
            or one name per cell, ``(n_cells,)``.
        mu: First Lame parameter, scalar or ``(n_cells,)``.
        lmbda: Second Lame parameter, scalar or ``(n_cells,)``.
        x: Deformed positions, vertex-major interleaved, ``(n_vertices * d,)``.

    Returns:
        The energy; ``+inf`` if a neo-Hookean element is inverted.
    """
    _, w, _, F = _element_kinematics(points, cells, x)
    return float(np.sum(w * _per_cell(psi, material, F, mu, lmbda)))


def elastic_gradient(points, cells, material: str, mu, lmbda, x: np.ndarray) -> np.ndarray:
    """Gradient ``sum_e w_e G_e^T vec(P_e)`` as a dense ``(n_vertices * d,)`` vector.

    Arguments as in :func:`elastic_energy`.
    """
    dofs, w, G, F = _element_kinematics(points, cells, x)
    local = np.einsum("n,nij,ni->nj", w, G, vec(_per_cell(first_piola, material, F, mu, lmbda)))
    return np.bincount(dofs.ravel(), weights=local.ravel(), minlength=np.size(x))


def elastic_hessian(points, cells, material: str, mu, lmbda, x: np.ndarray) -> sp.csr_matrix:
    """Hessian ``sum_e w_e G_e^T (dP/dF)_e G_e`` as a sparse CSR matrix.

    Arguments as in :func:`elastic_energy`.

    Returns:
        Symmetric ``(n_vertices * d, n_vertices * d)`` CSR matrix (duplicates summed).
    """
    dofs, w, G, F = _element_kinematics(points, cells, x)
    A = _per_cell(first_piola_derivative, material, F, mu, lmbda)
    local = np.einsum("n,npi,npq,nqj->nij", w, G, A, G, optimize=True)
    m = dofs.shape[1]
    rows = np.repeat(dofs, m, axis=1).ravel()
    cols = np.tile(dofs, (1, m)).ravel()
    n = np.size(x)
    return sp.coo_matrix((local.ravel(), (rows, cols)), shape=(n, n)).tocsr()
