"""A structured box: a grid of cubes split into 6 tetrahedra each (squares into 2 triangles).

The mesh the peers' benchmarks use (pbatoolkit's and VBD's hanging beam: a box of
nx x ny x nz cubes, 6 tetrahedra per cube), so fem_anim can be compared on the very same
tetrahedra. Each cube is cut by Kuhn's (Freudenthal's) subdivision: one tetrahedron per
permutation (p0, p1, p2) of the axes, with vertices

    v, v + e_p0, v + e_p0 + e_p1, v + e_p0 + e_p1 + e_p2 = v + (1, 1, 1),

all sharing the cube's main diagonal. Every cube is cut the same way, so the diagonal of
each face is the same seen from both cubes that share it: the mesh is conforming. A
tetrahedron's orientation is the sign of its permutation; odd ones have two vertices
swapped so that every cell has positive volume h_x h_y h_z / 6. In 2D each square is cut
along the diagonal from (0, 0) to (1, 1).
"""

from __future__ import annotations

from collections.abc import Sequence
from itertools import permutations

import numpy as np

__all__ = ["structured_box"]


def _parity(perm: tuple[int, ...]) -> int:
    """+1 for an even permutation of (0, .., n-1), -1 for an odd one."""
    sign, seen = 1, list(perm)
    for i in range(len(seen)):
        while seen[i] != i:
            j = seen[i]
            seen[i], seen[j] = seen[j], seen[i]
            sign = -sign
    return sign


def structured_box(size: Sequence[float], divisions: Sequence[int],
                   origin: Sequence[float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and simplices of the box ``origin + [0, size]`` cut into a grid.

    Args:
        size: Edge lengths, 2 or 3 entries (m).
        divisions: Cubes (squares) per axis, as many entries as ``size``, each >= 1.
        origin: Lower corner, default the coordinate origin.

    Returns:
        ``points`` (prod(divisions + 1), d) and ``cells`` (d! prod(divisions), d + 1), every
        cell positively oriented.
    """
    d = len(size)
    n = np.asarray(divisions, dtype=np.int64)
    if len(divisions) != d or np.any(n < 1):
        raise ValueError(f"divisions must be {d} integers >= 1, got {list(divisions)}")
    lo = np.zeros(d) if origin is None else np.asarray(origin, float)[:d]
    axes = [np.linspace(lo[a], lo[a] + size[a], n[a] + 1) for a in range(d)]
    grid = np.meshgrid(*axes, indexing="ij")
    points = np.stack([g.ravel() for g in grid], axis=1)
    strides = np.array([np.prod(n[a + 1:] + 1) for a in range(d)], dtype=np.int64)
    corner = np.stack(np.meshgrid(*[np.arange(m) for m in n], indexing="ij"), -1)
    base = (corner.reshape(-1, d) * strides).sum(axis=1)  # lower corner of every cube
    cells = []
    for perm in permutations(range(d)):
        offsets = np.cumsum([0] + [strides[a] for a in perm])  # the path v -> v + (1,..,1)
        tet = base[:, None] + offsets[None, :]
        if _parity(perm) < 0:  # odd path: swap two vertices for a positive orientation
            tet = tet[:, [1, 0, *range(2, d + 1)]]
        cells.append(tet)
    return points, np.concatenate(cells)
