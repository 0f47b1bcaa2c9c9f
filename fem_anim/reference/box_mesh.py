"""Structured simplex meshes of boxes, built with numpy (no gmsh), for reference tests."""

from __future__ import annotations

import itertools

import numpy as np

__all__ = ["box_mesh"]


def box_mesh(
    divisions: tuple[int, ...], lengths: tuple[float, ...] | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Kuhn (Freudenthal) triangulation of the box ``[0, L_0] x (...) x [0, L_{d-1}]``.

    Each of the ``prod(divisions)`` grid cells is split into ``d!`` simplices (2 triangles in
    2D, 6 tetrahedra in 3D) sharing the cell's main diagonal; the simplex of permutation ``pi``
    walks from the lower corner along ``e_pi(0), e_pi(1), ...``. Since every grid cell is split
    the same way the mesh is conforming. Vertices are ordered so that
    ``det[X_1 - X_0, ..., X_d - X_0] > 0``.

    Args:
        divisions: Number of grid cells per axis, length ``d`` (2 or 3).
        lengths: Box edge lengths (default all 1).

    Returns:
        ``(points, cells)`` with shapes ``(prod(divisions + 1), d)`` and
        ``(d! prod(divisions), d + 1)``.
    """
    d = len(divisions)
    if d not in (2, 3) or min(divisions) < 1:
        raise ValueError(f"divisions must be 2 or 3 positive integers, got {divisions}")
    lengths = np.ones(d) if lengths is None else np.asarray(lengths, dtype=float)
    axes = [np.linspace(0.0, L, n + 1) for L, n in zip(lengths, divisions, strict=True)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, d)

    shape = np.array(divisions) + 1
    strides = np.array([np.prod(shape[k + 1:]) for k in range(d)], dtype=np.int64)
    lower = np.stack(np.meshgrid(*[np.arange(n) for n in divisions], indexing="ij"), -1)
    base = lower.reshape(-1, d) @ strides  # vertex number of each grid cell's lower corner

    cells = []
    for perm in itertools.permutations(range(d)):
        offsets = np.cumsum([0] + [strides[k] for k in perm])
        simplex = base[:, None] + offsets
        inversions = sum(p > q for i, p in enumerate(perm) for q in perm[i + 1:])
        if inversions % 2:  # odd permutation: swap two vertices to keep positive orientation
            simplex[:, [0, 1]] = simplex[:, [1, 0]]
        cells.append(simplex)
    return points, np.concatenate(cells).astype(np.int64)
