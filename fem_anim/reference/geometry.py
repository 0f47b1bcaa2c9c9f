"""Per-element kinematics of P1 simplices (seed sections 4.2 and 4.3).

A mesh is ``points`` (``(n_vertices, d)`` floats) and ``cells`` (``(n_cells, d+1)`` ints), with
``d`` = 2 (triangles) or 3 (tetrahedra). The dof vector ``x`` holds deformed positions,
vertex-major and interleaved, ``x.reshape(-1, d)[i]`` = position of vertex ``i`` (the seed's
``(. x I_3)`` layout, eq. (20)).
"""

from __future__ import annotations

import math

import numpy as np

from fem_anim.reference.tensor import unvec

__all__ = [
    "cell_dofs",
    "cell_volumes",
    "check_mesh",
    "deformation_gradient",
    "deformed_shape_matrix",
    "gradient_operator",
    "rest_shape_matrix",
]


def check_mesh(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Validate and normalise a simplex mesh.

    Args:
        points: Vertex positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.

    Returns:
        ``points`` as float and ``cells`` as int arrays.

    Raises:
        ValueError: If the shapes do not describe triangles in 2D or tetrahedra in 3D.
    """
    points = np.asarray(points, dtype=float)
    cells = np.asarray(cells, dtype=np.int64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise ValueError(
            f"points must have shape (n_vertices, d) with d in (2, 3), got {points.shape}"
        )
    d = points.shape[1]
    if cells.ndim != 2 or cells.shape[1] != d + 1:
        raise ValueError(f"cells must have shape (n_cells, {d + 1}) for d = {d}, got {cells.shape}")
    if cells.size and (cells.min() < 0 or cells.max() >= len(points)):
        raise ValueError(
            f"cells must index points in [0, {len(points)}), "
            f"got values in [{cells.min()}, {cells.max()}]"
        )
    return points, cells


def cell_dofs(cells: np.ndarray, d: int) -> np.ndarray:
    """Global dof numbers of each element.

    Args:
        cells: Simplices, ``(n_cells, d + 1)``.
        d: The dimension.

    Returns:
        ``(n_cells, (d+1) d)`` array, local order ``i*d + k``.
    """
    return (cells[:, :, None] * d + np.arange(d)).reshape(len(cells), -1)


def rest_shape_matrix(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Reference shape matrices ``D_m`` with columns ``X_i - X_last`` (seed eq. (25)).

    Args:
        points: Rest positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.

    Returns:
        ``(n_cells, d, d)`` array.
    """
    X = points[cells]
    return (X[:, :-1, :] - X[:, -1:, :]).transpose(0, 2, 1)


def deformed_shape_matrix(x: np.ndarray, cells: np.ndarray, d: int) -> np.ndarray:
    """Deformed shape matrices ``D_s`` with columns ``x_i - x_last`` (seed eq. (25)).

    Args:
        x: Dof vector of deformed positions, length ``n_vertices * d``.
        cells: Element connectivity.
        d: Spatial dimension.
    """
    return rest_shape_matrix(np.asarray(x, dtype=float).reshape(-1, d), cells)


def cell_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Element measures ``w = |det D_m| / d!`` (seed eq. (28); area ``|det D_m| / 2`` in 2D).

    Args:
        points: Rest positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.

    Returns:
        ``(n_cells,)`` array.
    """
    d = points.shape[1]
    return np.abs(np.linalg.det(rest_shape_matrix(points, cells))) / math.factorial(d)


def gradient_operator(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Per-element matrices ``G_e = (D_m^{-T} S) x I_d`` with ``vec(F) = G_e x_e`` (seed eq. (34)).

    ``S = [I_d | -1]`` is the selector of eq. (33) restricted to the element's ``d+1`` vertices,
    so ``vec(D_s) = (S x I_d) x_e`` (eq. (32)) and ``vec(F) = (D_m^{-T} x I_d) vec(D_s)``
    (eq. (31)). The element dofs ``x_e`` are ordered as in :func:`cell_dofs`.

    Args:
        points: Rest positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.

    Returns:
        ``(n_cells, d*d, (d+1)*d)`` array.
    """
    d = points.shape[1]
    S = np.hstack([np.eye(d), -np.ones((d, 1))])
    B = np.linalg.inv(rest_shape_matrix(points, cells)).transpose(0, 2, 1) @ S
    G = np.einsum("nai,kl->nakil", B, np.eye(d))
    return G.reshape(len(cells), d * d, (d + 1) * d)


def deformation_gradient(points: np.ndarray, cells: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Deformation gradients ``F = D_s D_m^{-1}`` (seed eq. (26)), as ``vec(F) = G_e x_e``.

    Args:
        points: Rest positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.
        x: Deformed positions, a dof vector (vertex-major).

    Returns:
        ``(n_cells, d, d)`` array.
    """
    d = points.shape[1]
    x_e = np.asarray(x, dtype=float)[cell_dofs(cells, d)]
    return unvec(np.einsum("nij,nj->ni", gradient_operator(points, cells), x_e), d)
