"""An independent check that no frame of a run has an intersection.

The contact code (:mod:`fem_anim.contact.ipc`) builds its collision surface from DOLFINx's
exterior facets; this check builds its own from the tetrahedra alone (the triangles that
belong to one tetrahedron only), so a wrong surface there does not hide a crossing here,
and asks ipctk's ``has_intersections`` of every frame. Demos and tests run it on the
frames read back from ``trajectory.xdmf``.

Quadratic tetrahedra (10 nodes, VTK's ``tetra10`` order: the 4 vertices, then the nodes on
the edges 01, 12, 02, 03, 13, 23) are checked on their boundary triangles split in four at
the edge nodes (the contact surface of :mod:`fem_anim.contact.p2_surface`, built here from
the node order alone); :func:`tetra10_cells` puts DOLFINx's P2 cell dofs in that order by
their coordinates (the node nearest each vertex and each edge midpoint), so no part of the
check shares the contact code's reading of the dof layout.
"""

from __future__ import annotations

import numpy as np

__all__ = ["boundary_triangles", "crossed_frames", "surface_collision_mesh", "tetra10_cells"]


#: The vertices of a tetrahedron's faces, and (tetra10) each face's edge nodes: the node on
#: edge (i, j) of VTK's order, for the face's edges (v0 v1), (v1 v2), (v2 v0).
_FACES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
_EDGE_NODE = {(0, 1): 4, (1, 2): 5, (0, 2): 6, (0, 3): 7, (1, 3): 8, (2, 3): 9}
_FACE_EDGES = np.array([[_EDGE_NODE[tuple(sorted((f[i], f[(i + 1) % 3])))] for i in range(3)]
                        for f in _FACES])


def boundary_triangles(cells: np.ndarray) -> np.ndarray:
    """Triangles of a tetrahedral mesh that belong to one tetrahedron only.

    Args:
        cells: The tetrahedra, (cells, 4) vertex indices, or (cells, 10) node indices of
            quadratic ones (``tetra10`` order, module docstring).

    Returns:
        The boundary triangles, (triangles, 3) int32 vertex indices: for 4-node cells each
        row sorted; for 10-node cells each boundary face split into four at its edge nodes.
    """
    corners = cells[:, _FACES].reshape(-1, 3)
    faces = np.sort(corners, axis=1)
    unique, index, counts = np.unique(faces, axis=0, return_index=True, return_counts=True)
    if cells.shape[1] == 4:
        return unique[counts == 1].astype(np.int32)
    once = index[counts == 1]  # rows of the boundary faces among cells x 4 faces
    a, b, c = corners[once].T
    ab, bc, ca = cells[:, _FACE_EDGES].reshape(-1, 3)[once].T
    split = np.stack([np.stack(t, 1) for t in
                      ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))], 1)
    return split.reshape(-1, 3).astype(np.int32)


def tetra10_cells(corners: np.ndarray, nodes: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Quadratic cells in ``tetra10`` order, by the coordinates of their nodes.

    Args:
        corners: The cells' vertex coordinates, (cells, 4, 3), in the order wanted.
        nodes: The cells' 10 node indices in any order, (cells, 10).
        points: The nodes' coordinates, (nodes, 3).

    Returns:
        (cells, 10) node indices: the node at each vertex, then at the midpoint of the
        edges 01, 12, 02, 03, 13, 23.

    Raises:
        ValueError: if a cell's nodes are not its vertices and edge midpoints.
    """
    pairs = sorted(_EDGE_NODE, key=_EDGE_NODE.get)
    mids = np.stack([(corners[:, i] + corners[:, j]) / 2 for i, j in pairs], 1)
    targets = np.concatenate([corners, mids], axis=1)  # (cells, 10, 3)
    x = points[nodes]  # (cells, 10, 3)
    dist = np.linalg.norm(targets[:, :, None, :] - x[:, None, :, :], axis=3)
    pick = dist.argmin(axis=2)
    size = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    if np.any(np.sort(pick, axis=1) != np.arange(10)) or \
            np.any(dist.min(axis=2) > 1e-8 * size[:, None]):
        raise ValueError("the nodes are not the cells' vertices and edge midpoints")
    return np.take_along_axis(nodes, pick, axis=1)


def crossed_frames(points: np.ndarray, cells: np.ndarray, frames) -> list[int]:
    """Indices of the frames where a surface triangle crosses another.

    Args:
        points: The rest positions of the vertices, (vertices, 3).
        cells: The tetrahedra, (cells, 4) vertex indices (or (cells, 10), quadratic).
        frames: An iterable of displacements, each (vertices, 3), in vertex order.

    Returns:
        The indices k of ``frames`` where ipctk's ``has_intersections`` is true.
    """
    import ipctk

    mesh, used = surface_collision_mesh(points, cells)
    rest = mesh.rest_positions
    return [k for k, u in enumerate(frames)
            if ipctk.has_intersections(mesh, np.asfortranarray(rest + u[used]))]


def surface_collision_mesh(points: np.ndarray, cells: np.ndarray):
    """An ipctk ``CollisionMesh`` of the tetrahedra's boundary triangles alone.

    Args:
        points: The rest positions of the vertices, (vertices, 3).
        cells: The tetrahedra, (cells, 4) vertex indices (or (cells, 10), quadratic).

    Returns:
        The collision mesh (its vertices the surface vertices, at rest) and ``used``, the
        indices of those vertices among ``points`` (``x[used]`` are its positions).
    """
    import ipctk

    F = boundary_triangles(cells)
    used = np.unique(F)
    index = np.full(points.shape[0], -1)
    index[used] = np.arange(used.size)
    F = np.asfortranarray(index[F], dtype=np.int32)
    rest = np.asfortranarray(points[used])
    return ipctk.CollisionMesh(rest, np.asfortranarray(ipctk.edges(F), dtype=np.int32), F), used
