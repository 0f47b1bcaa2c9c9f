"""Each body's boundary surface, wound outward, as animation packages want it.

A run stores the whole volume mesh (tetrahedra, or triangles in 2D); a renderer or an
animation package wants the skin. A boundary face of a tetrahedral mesh is a face that
belongs to exactly one tetrahedron. It is wound so that its normal
``(b - a) x (c - a)`` points away from the tetrahedron's fourth vertex, i.e. out of the
body: counter-clockwise seen from outside, USD's ``rightHanded`` orientation and the
convention of OBJ and PLY. A 2D run's bodies are flat sheets in the plane z = 0; their
surface is the triangles themselves, counter-clockwise seen from +z. A shell (a triangle
mesh of the mid-surface in 3D, docs/cloth.md; its triangles are linear simplices, seed
eq. 26) has no inside: its surface is its triangles themselves, in the run's vertex order,
each normal ``(b - a) x (c - a)`` the one its mesh gives it (``sheet=True``); the exporters
mark it two-sided.

Each body's surface has its own vertex numbering (the mesh vertices its faces use, in
mesh order), so a body exports as one self-contained mesh; ``vertices`` maps it back to
the run's vertices, and ``owner`` names the cell behind each face (its energy density is
the face's).

A P2 body (seed section 4.2) deforms its faces into curved quadratic patches; its vertex
values alone draw the flat triangle of the corners. :func:`refine_p2` splits each boundary
triangle (a, b, c) into four, (a, ab, ca), (ab, b, bc), (ca, bc, c) and (ab, bc, ca), through
the midpoints of its edges, where the P2 field has its edge dofs: every vertex of the refined
surface carries a dof of the solution, so its positions are the P2 field's exact values
there (the trajectory's ``displacement_dofs``, :mod:`fem_anim.output.trajectory`). The four
children keep their parent's winding and owner cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["BodySurface", "boundary_faces", "body_surfaces", "refine_p2"]

#: The faces of a tetrahedron (a, b, c, d): face k is opposite vertex k.
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


@dataclass
class BodySurface:
    """One body's boundary surface.

    Attributes:
        body: The body's number (0, 1, ... in the scene's ``[[body]]`` order).
        vertices: The run's vertex number of each surface vertex, ``(n,)``.
        triangles: Outward-wound triangles as surface vertex numbers, ``(f, 3)``.
        owner: The run's cell number behind each triangle, ``(f,)``.
    """

    body: int
    vertices: np.ndarray
    triangles: np.ndarray
    owner: np.ndarray


def boundary_faces(points: np.ndarray, cells: np.ndarray,
                   sheet: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """The boundary faces of a simplex mesh, wound outward, and the cell owning each.

    Args:
        points: Rest vertex coordinates ``(v, d)``, d = 2 or 3.
        cells: Tetrahedra ``(m, 4)`` or triangles ``(m, 3)`` (a 2D run's, or a shell's).
        sheet: The triangles are a surface in 3D (a shell): each is its own face, as wound
            in ``cells``.

    Returns:
        ``(faces, owner)``: triangles ``(f, 3)`` of run vertex numbers whose normal points
        out of their cell (in 2D: every triangle, counter-clockwise about +z; a sheet's:
        every triangle as given), and the cell number of each.
    """
    cells = np.asarray(cells, dtype=np.int64)
    if cells.ndim != 2 or cells.shape[1] not in (3, 4):
        raise ValueError(f"cells of {cells.shape[-1]} vertices: not triangles or tetrahedra")
    if sheet:
        if cells.shape[1] != 3:
            raise ValueError("a shell's cells must be triangles")
        return cells.copy(), np.arange(cells.shape[0])
    if cells.shape[1] == 3:  # 2D: the sheet itself, counter-clockwise about +z
        x = points[cells]
        area2 = (x[:, 1, 0] - x[:, 0, 0]) * (x[:, 2, 1] - x[:, 0, 1]) \
            - (x[:, 1, 1] - x[:, 0, 1]) * (x[:, 2, 0] - x[:, 0, 0])
        faces = np.where((area2 < 0)[:, None], cells[:, [0, 2, 1]], cells)
        return faces, np.arange(cells.shape[0])
    all_faces = cells[:, TET_FACES].reshape(-1, 3)
    owner = np.repeat(np.arange(cells.shape[0]), 4)
    opposite = cells.ravel()  # face k of a cell is opposite its vertex k
    key = np.sort(all_faces, axis=1)
    _, index, counts = np.unique(key, axis=0, return_index=True, return_counts=True)
    once = np.sort(index[counts == 1])  # faces of one cell only, in cell order
    faces, owner, opposite = all_faces[once], owner[once], opposite[once]
    a, b, c = (points[faces[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    inward = np.einsum("ij,ij->i", normal, points[opposite] - a) > 0.0
    faces[inward] = faces[inward][:, [0, 2, 1]]
    return faces, owner


def body_surfaces(points: np.ndarray, cells: np.ndarray, body: np.ndarray,
                  sheet: bool = False) -> list[BodySurface]:
    """The boundary surface of every body, each with its own vertex numbering.

    Args:
        points: Rest vertex coordinates ``(v, d)``.
        cells: The run's cells.
        body: The body number of each cell, ``(m,)`` (0, 1, ...).
        sheet: The cells are triangles of surfaces in 3D (:func:`boundary_faces`).

    Returns:
        One :class:`BodySurface` per body, in body order.
    """
    faces, owner = boundary_faces(points, cells, sheet)
    surfaces = []
    for k in range(int(body.max()) + 1 if body.size else 0):
        mine = body[owner] == k
        used, local = np.unique(faces[mine], return_inverse=True)
        surfaces.append(BodySurface(k, used, local.reshape(-1, 3), owner[mine]))
    return surfaces


def refine_p2(surfaces: list[BodySurface], nodes: np.ndarray,
              num_points: int) -> list[BodySurface]:
    """Each surface's triangles split in four through their edges' P2 dofs.

    Args:
        surfaces: The bodies' surfaces (:func:`body_surfaces`), numbered in run vertices.
        nodes: The ``(i, j)`` run vertex pair of each row of the P2 field, ``(n, 2)``
            (vertex rows ``i == j``, edge rows ``i < j``;
            :class:`~fem_anim.output.dof_gather.DofGather`).
        num_points: The run's number of vertices.

    Returns:
        The refined surfaces, whose ``vertices`` are rows of ``nodes`` (not run vertices).

    Raises:
        ValueError: an edge of a boundary triangle has no row in ``nodes`` (not a P2 field).
    """
    nodes = np.asarray(nodes, dtype=np.int64)
    code = nodes[:, 0] * num_points + nodes[:, 1]
    order = np.argsort(code)

    def row(i: np.ndarray, j: np.ndarray) -> np.ndarray:
        key = np.minimum(i, j) * num_points + np.maximum(i, j)
        at = np.minimum(np.searchsorted(code, key, sorter=order), code.size - 1)
        found = order[at]
        if not np.array_equal(code[found], key):
            raise ValueError("a boundary edge has no dof in the field: not a P2 field")
        return found

    out = []
    for surface in surfaces:
        a, b, c = surface.vertices[surface.triangles].T
        va, vb, vc = row(a, a), row(b, b), row(c, c)
        ab, bc, ca = row(a, b), row(b, c), row(c, a)
        children = np.stack([np.stack(t, axis=1) for t in (
            (va, ab, ca), (ab, vb, bc), (ca, bc, vc), (ab, bc, ca))], axis=1).reshape(-1, 3)
        used, local = np.unique(children, return_inverse=True)
        out.append(BodySurface(surface.body, used, local.reshape(-1, 3),
                               np.repeat(surface.owner, 4)))
    return out
