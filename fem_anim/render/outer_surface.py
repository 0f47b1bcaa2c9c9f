"""The part of a mesh a picture shows: its outward boundary triangles.

A camera sees only the boundary of a tetrahedral mesh, so the renderer draws the triangles
that belong to one tetrahedron only (not the whole grid, whose surface VTK would extract
again every frame), wound so that their normal points away from the tetrahedron's fourth
vertex (outwards, as lighting needs), each with the cell it comes from (to colour it by a
cell field). A triangle mesh (2D) is its own surface.
"""

from __future__ import annotations

import numpy as np

__all__ = ["outer_faces"]

#: The four faces of a tetrahedron (local vertices) and the vertex opposite each.
_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
_OPPOSITE = np.array([0, 1, 2, 3])


def outer_faces(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The boundary triangles of a mesh, wound outwards, and the cell of each.

    Args:
        points: Vertex positions (n, 2 or 3) the winding is decided on (the rest shape).
        cells: Tetrahedra (m, 4) or triangles (m, 3).

    Returns:
        ``(faces, cell)``: triangles (f, 3) and the index of the cell each belongs to (f,).
        For triangles: the cells themselves, counter-clockwise in the xy plane.
    """
    cells = np.asarray(cells, dtype=np.int64)
    x = np.hstack([points, np.zeros((points.shape[0], 3 - points.shape[1]))])
    if cells.shape[1] == 3:
        a, b, c = (x[cells[:, i]] for i in range(3))
        flip = np.cross(b - a, c - a)[:, 2] < 0
        faces = cells.copy()
        faces[flip] = faces[flip][:, [0, 2, 1]]
        return faces, np.arange(cells.shape[0])
    faces = cells[:, _FACES].reshape(-1, 3)
    owner = np.repeat(np.arange(cells.shape[0]), 4)
    opposite = cells[:, _OPPOSITE].ravel()
    _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True,
                                 return_counts=True)
    keep = first[counts == 1]
    faces, owner, opposite = faces[keep], owner[keep], opposite[keep]
    a, b, c = x[faces[:, 0]], x[faces[:, 1]], x[faces[:, 2]]
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), x[opposite] - a) > 0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return faces, owner
