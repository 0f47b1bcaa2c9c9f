"""The contact surface of a P1 or P2 displacement: triangles (segments in 2D) on its dofs.

IPC's barrier (:mod:`fem_anim.contact.ipc`) acts on a triangle surface whose vertices move
with the displacement. For P1 those are the boundary facets on their vertex dofs. A P2
displacement bends each boundary facet into a quadratic patch; its contact surface here is
that patch sampled as a finer triangle set whose vertices ARE the P2 dofs: each boundary
triangle (a, b, c) with edge-midpoint dofs m_ab, m_bc, m_ca is split into four,

    (a, m_ab, m_ca), (m_ab, b, m_bc), (m_ca, m_bc, c), (m_ab, m_bc, m_ca),

all with the orientation of (a, b, c); in 2D a boundary edge (a, b) with midpoint dof m_ab
is split into (a, m_ab), (m_ab, b). The surface is then piecewise linear in the dofs, so
the barrier's gradient and Hessian with respect to the surface vertices are its gradient
and Hessian with respect to the P2 dofs, with no interpolation matrix between them. The
sub-triangles are the piecewise-linear interpolant of the quadratic patch on the
once-refined facet: they pass through its six nodes, and the patch departs from them
between the nodes by at most (h/2)^2 / 8 times its second derivative (h the facet's edge
length). The contact guarantee (no crossing on any accepted state) holds for these
triangles, exactly as for a P1 body refined once on its boundary; the quadratic patch
itself is not checked between its nodes (docs/contact.md). IPC's contact term of E in the
step objective (seed eq. 4) is thereby a function of the P2 dofs alone.

The dofs are located by the reference cell's topology (basix: the vertices of each edge)
and the element's dof layout (the dof of each vertex and edge), so nothing depends on the
geometry; tests compare the midpoints with the dof coordinates.
"""

from __future__ import annotations

import basix
import numpy as np

from fem_anim import compat

__all__ = ["surface_faces"]


def _cell_type(tdim: int):
    return basix.CellType.tetrahedron if tdim == 3 else basix.CellType.triangle


def surface_faces(V, entities: np.ndarray,
                  c_to_v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The contact surface of the surface ``entities`` on the dof blocks of ``V``.

    Args:
        V: The displacement space, Lagrange of degree 1 or 2 on a simplex mesh.
        entities: Local vertex indices of each surface entity, (n, k): a solid's exterior
            facets, or a shell's triangles
            (:func:`~fem_anim.contact.contact_surface.surface_entities`); k = 3 (triangles)
            or 2 (segments).
        c_to_v: Cell -> vertex connectivity, (cells of the rank, tdim + 1).

    Returns:
        ``faces``: the surface's triangles (segments) as local dof blocks of ``V``, (m, k);
        ``parent``: for each of them, its row in ``entities`` (so a property of the entity,
        e.g. its body, carries over). Degree 1 gives one face per entity, degree 2 gives
        2^(k - 1) (module docstring).

    Raises:
        ValueError: for a degree other than 1 or 2.
    """
    tdim = c_to_v.shape[1] - 1
    layout = V.dofmap.dof_layout
    cell_dofs = compat.cell_dofs(V)
    n_vertices = int(c_to_v.max()) + 1 if c_to_v.size else 0
    vertex_dof = np.empty(n_vertices, dtype=np.int64)
    vertex_columns = [layout.entity_dofs(0, v)[0] for v in range(tdim + 1)]
    vertex_dof[c_to_v.ravel()] = cell_dofs[:, vertex_columns].ravel()
    corners = vertex_dof[entities]  # (n, k)
    per_edge = len(layout.entity_dofs(1, 0))  # dofs per edge: degree - 1
    if per_edge == 0:
        return corners, np.arange(entities.shape[0])
    if per_edge != 1:
        raise ValueError(f"contact surfaces are built for degree 1 or 2, not {per_edge + 1}")
    # every cell edge (as a sorted vertex pair) -> its midpoint dof block
    edges = np.asarray(basix.topology(_cell_type(tdim))[1])  # (edges, 2) local vertices
    pairs = np.sort(c_to_v[:, edges], axis=2).reshape(-1, 2).astype(np.int64)
    edge_columns = [layout.entity_dofs(1, e)[0] for e in range(edges.shape[0])]
    mid = cell_dofs[:, edge_columns].ravel()
    keys, first = np.unique(pairs[:, 0] * n_vertices + pairs[:, 1], return_index=True)
    mid = mid[first]

    def midpoint(i: int, j: int) -> np.ndarray:
        a, b = entities[:, i], entities[:, j]
        key = np.minimum(a, b).astype(np.int64) * n_vertices + np.maximum(a, b)
        return mid[np.searchsorted(keys, key)]

    if entities.shape[1] == 2:
        m = midpoint(0, 1)
        faces = np.stack([np.stack([corners[:, 0], m], 1), np.stack([m, corners[:, 1]], 1)], 1)
    else:
        a, b, c = corners.T
        ab, bc, ca = midpoint(0, 1), midpoint(1, 2), midpoint(2, 0)
        faces = np.stack([np.stack(t, 1) for t in
                          ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))], 1)
    n_sub = faces.shape[1]
    return faces.reshape(-1, entities.shape[1]), np.repeat(np.arange(entities.shape[0]), n_sub)
