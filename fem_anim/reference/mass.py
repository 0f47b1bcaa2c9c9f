"""Mass matrices and the gravity potential of a P1 mesh (seed section 4.1).

The kinetic energy ``k = 1/2 v^T M v`` (eq. (19)) with ``M = sum_t rho_t S_t`` uses the exact
P1 integrals ``s^t_ij = int_t s_i s_j = |t| (1 + delta_ij) / ((d+1)(d+2))`` (eq. (17)): area/6
and area/12 on triangles, volume/10 and volume/20 on tetrahedra, expanded ``x I_d`` (eq. (20)).
The lumped matrix takes the row sums (footnote 4), ``m_i = sum_t rho_t |t| / (d+1)``.
``rho`` is a scalar or a per-cell array ``(n_cells,)``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_anim.reference.geometry import cell_dofs, cell_volumes, check_mesh

__all__ = ["gravity_energy", "gravity_gradient", "mass_matrix", "vertex_masses"]


def _cell_masses(points, cells, rho) -> np.ndarray:
    """``rho_t |t|`` per cell."""
    rho = np.broadcast_to(np.asarray(rho, dtype=float), (len(cells),))
    return rho * cell_volumes(points, cells)


def vertex_masses(points, cells, rho) -> np.ndarray:
    """Lumped vertex masses ``m_i = int rho s_i = sum_t rho_t |t| / (d+1)``, ``(n_vertices,)``.

    These are the row sums of the scalar consistent mass matrix.

    Args:
        points: Rest positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.
        rho: Density (kg/m^3), a scalar or ``(n_cells,)``.
    """
    points, cells = check_mesh(points, cells)
    d = points.shape[1]
    share = np.repeat(_cell_masses(points, cells, rho) / (d + 1), d + 1)
    return np.bincount(cells.ravel(), weights=share, minlength=len(points))


def mass_matrix(points, cells, rho, lumped: bool = False) -> sp.csr_matrix:
    """Mass matrix ``M = sum_t rho_t S_t`` expanded ``x I_d`` (seed eqs. (17)-(20)).

    Args:
        points: Reference vertex positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d+1)``.
        rho: Density, scalar or ``(n_cells,)``.
        lumped: Return the diagonal row-sum matrix instead (seed footnote 4).

    Returns:
        ``(n_vertices * d, n_vertices * d)`` CSR matrix acting on interleaved dofs.
    """
    points, cells = check_mesh(points, cells)
    d = points.shape[1]
    n = points.size
    if lumped:
        return sp.diags(np.repeat(vertex_masses(points, cells, rho), d)).tocsr()
    P = (np.ones((d + 1, d + 1)) + np.eye(d + 1)) / ((d + 1) * (d + 2))
    scalar = np.einsum("n,ij->nij", _cell_masses(points, cells, rho), P)
    # (P x I_d): entry (i*d + k, j*d + k) = P_ij
    local = np.einsum("nij,kl->nikjl", scalar, np.eye(d)).reshape(len(cells), (d + 1) * d, -1)
    dofs = cell_dofs(cells, d)
    m = dofs.shape[1]
    rows = np.repeat(dofs, m, axis=1).ravel()
    cols = np.tile(dofs, (1, m)).ravel()
    return sp.coo_matrix((local.ravel(), (rows, cols)), shape=(n, n)).tocsr()


def gravity_energy(points, cells, rho, g, x: np.ndarray) -> float:
    """Gravity potential ``-int rho dot(g, x) dV``, which is ``-sum_i m_i dot(g, x_i)`` for P1.

    Exact for P1 positions, where it equals ``-(M (1 x g)) . x`` with either mass matrix.

    Args:
        points: Reference vertex positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d+1)``.
        rho: Density, scalar or ``(n_cells,)``.
        g: Gravitational acceleration, ``(d,)``.
        x: Deformed positions, ``(n_vertices * d,)``.
    """
    return float(gravity_gradient(points, cells, rho, g) @ np.asarray(x, dtype=float))


def gravity_gradient(points, cells, rho, g) -> np.ndarray:
    """Constant gradient of :func:`gravity_energy`, ``-m_i g`` at vertex ``i``, ``(n_dofs,)``.

    Arguments as in :func:`gravity_energy`.
    """
    m = vertex_masses(points, cells, rho)
    return -(m[:, None] * np.asarray(g, dtype=float)[None, :]).ravel()
