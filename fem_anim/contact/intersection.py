"""An independent check that no frame of a run has an intersection (issue 16).

The contact code (:mod:`fem_anim.contact.ipc`) builds its collision surface from DOLFINx's
exterior facets; this check builds its own from the tetrahedra alone (the triangles that
belong to one tetrahedron only), so a wrong surface there does not hide a crossing here,
and asks ipctk's ``has_intersections`` of every frame. Demos and tests run it on the
frames read back from ``trajectory.xdmf``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["boundary_triangles", "crossed_frames"]


def boundary_triangles(cells: np.ndarray) -> np.ndarray:
    """Triangles of a tetrahedral mesh that belong to one tetrahedron only (numpy)."""
    faces = np.sort(cells[:, [[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]]].reshape(-1, 3), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    return unique[counts == 1].astype(np.int32)


def crossed_frames(points: np.ndarray, cells: np.ndarray, frames) -> list[int]:
    """Indices of the displacements in ``frames`` where a surface triangle crosses another."""
    import ipctk

    F = boundary_triangles(cells)
    used = np.unique(F)
    index = np.full(points.shape[0], -1)
    index[used] = np.arange(used.size)
    F = np.asfortranarray(index[F], dtype=np.int32)
    rest = np.asfortranarray(points[used])
    mesh = ipctk.CollisionMesh(rest, np.asfortranarray(ipctk.edges(F), dtype=np.int32), F)
    return [k for k, u in enumerate(frames)
            if ipctk.has_intersections(mesh, np.asfortranarray(rest + u[used]))]
