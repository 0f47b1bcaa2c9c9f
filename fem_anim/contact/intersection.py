"""An independent check that no frame of a run has an intersection.

The contact code (:mod:`fem_anim.contact.ipc`) builds its collision surface from DOLFINx's
exterior facets; this check builds its own from the tetrahedra alone (the triangles that
belong to one tetrahedron only), so a wrong surface there does not hide a crossing here,
and asks ipctk's ``has_intersections`` of every frame. Demos and tests run it on the
frames read back from ``trajectory.xdmf``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["boundary_triangles", "crossed_frames", "surface_collision_mesh"]


def boundary_triangles(cells: np.ndarray) -> np.ndarray:
    """Triangles of a tetrahedral mesh that belong to one tetrahedron only.

    Args:
        cells: The tetrahedra, (cells, 4) vertex indices.

    Returns:
        The boundary triangles, (triangles, 3) int32 vertex indices, each row sorted.
    """
    faces = np.sort(cells[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    return unique[counts == 1].astype(np.int32)


def crossed_frames(points: np.ndarray, cells: np.ndarray, frames) -> list[int]:
    """Indices of the frames where a surface triangle crosses another.

    Args:
        points: The rest positions of the vertices, (vertices, 3).
        cells: The tetrahedra, (cells, 4) vertex indices.
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
        cells: The tetrahedra, (cells, 4) vertex indices.

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
