"""An independent check that no frame of a run has an intersection.

The contact code (:mod:`fem_anim.contact.ipc`) builds its collision surface from DOLFINx's
exterior facets; this check builds its own from the tetrahedra alone (the triangles that
belong to one tetrahedron only), so a wrong surface there does not hide a crossing here,
and asks ipctk's ``has_intersections`` of every frame. Demos and tests run it on the
frames read back from ``trajectory.xdmf``.

A shell (cells that are triangles) is its own surface, and is checked without ipctk:
:func:`crossing_pairs` tests every pair of triangles that share no vertex (adjacent
triangles meet along their shared edge or vertex by construction) and whose bounding boxes
overlap (a sweep along x), in numpy, by the segment-triangle test: two such triangles cross
iff an edge of one passes through the other (its ends on opposite sides of the other's
plane, the crossing point inside it). Distances to a plane below 1e-10 of the scene's size
count as zero. It takes any triangle soup, so a sheet and a solid's boundary triangles
(:func:`boundary_triangles`) are checked together by stacking them. Exactly coplanar pairs
(both ends of every edge on the other's plane) are not reported: the check is for crossings,
which contact keeps the shell's thickness away from.

A body wholly inside another crosses nothing (it tunnelled through a face within one step,
or a thin body was thrown into a solid), so the check also asks whether a vertex lies
strictly inside another body (:func:`enclosed_vertices`): the boundary triangles fall into
connected pieces, oriented here from the soup alone (:func:`surface_components`); the
closed pieces bound solids (grouped into bodies by the cells' connectivity,
:func:`solid_bodies`: an outer surface and its cavities), and the generalised winding
number of a body's pieces oriented outward (:func:`winding_numbers`: Jacobson, Kavan and
Sorkine-Hornung 2013, solid angles by van Oosterom and Strackee 1983) at the other bodies'
vertices within its bounding box is 1 in its material, 0 outside and in a cavity. The
seed poses each step as a minimisation (Section 3.1, eq. 4) and has no contact; the IPC
barrier added to it is defined on intersection-free states only, and IPC's continuous
collision detection (not in the seed) keeps every start and iterate there: this check
verifies that outcome, no surface crossing another and no body inside another.
:func:`crossed_frames` asks both of a solid mesh's frames; :func:`intersecting` asks both
of a soup (a solid's boundary triangles stacked with a sheet).

Quadratic tetrahedra (10 nodes, VTK's ``tetra10`` order: the 4 vertices, then the nodes on
the edges 01, 12, 02, 03, 13, 23) are checked on their boundary triangles split in four at
the edge nodes (the contact surface of :mod:`fem_anim.contact.p2_surface`, built here from
the node order alone); :func:`tetra10_cells` puts DOLFINx's P2 cell dofs in that order by
their coordinates (the node nearest each vertex and each edge midpoint), so no part of the
check shares the contact code's reading of the dof layout.
"""

from __future__ import annotations

import numpy as np

__all__ = ["boundary_triangles", "crossed_frames", "crossing_pairs", "enclosed_vertices",
           "intersecting", "solid_bodies", "surface_collision_mesh", "surface_components",
           "tetra10_cells", "winding_numbers"]

#: Rows of the triangles compared at once in :func:`crossing_pairs` (bounds the memory).
CHUNK = 256

#: Point-triangle pairs evaluated at once by :func:`winding_numbers` and
#: :func:`enclosed_vertices` (bounds the memory: ~100 MB of temporaries).
BLOCK = 1 << 18

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


def _segment_crosses(p: np.ndarray, q: np.ndarray, a: np.ndarray, b: np.ndarray,
                     c: np.ndarray, tol: float) -> np.ndarray:
    """Whether segment pq passes through triangle abc (touching counts), row by row.

    The ends' signed distances to the triangle's plane have opposite signs (a distance
    below ``tol`` counts as zero; both zero: coplanar, not reported), and the point where pq
    meets the plane has barycentric coordinates >= 0 in abc.
    """
    n = np.cross(b - a, c - a)
    area2 = np.linalg.norm(n, axis=1)
    sp, sq = (np.einsum("ij,ij->i", n, e - a) / area2 for e in (p, q))
    sp[np.abs(sp) < tol], sq[np.abs(sq) < tol] = 0.0, 0.0
    through_plane = (sp * sq <= 0) & ((sp != 0) | (sq != 0))
    s = np.where(through_plane, sp / np.where(through_plane, sp - sq, 1.0), 0.0)
    r = p + s[:, None] * (q - p) - a
    e1, e2 = b - a, c - a
    d11, d12, d22 = (np.einsum("ij,ij->i", u, v) for u, v in ((e1, e1), (e1, e2), (e2, e2)))
    r1, r2 = np.einsum("ij,ij->i", r, e1), np.einsum("ij,ij->i", r, e2)
    det = d11 * d22 - d12 ** 2
    beta, gamma = (d22 * r1 - d12 * r2) / det, (d11 * r2 - d12 * r1) / det
    eps = 1e-12
    inside = (beta >= -eps) & (gamma >= -eps) & (beta + gamma <= 1 + eps)
    return through_plane & inside


def crossing_pairs(x: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Pairs of triangles sharing no vertex that cross each other (module docstring).

    Args:
        x: Vertex positions, (vertices, 3).
        triangles: (triangles, 3) vertex indices.

    Returns:
        (pairs, 2) indices i < j of the crossing triangles (empty: no intersection).
    """
    order = np.argsort(x[triangles].min(axis=1)[:, 0], kind="stable")  # sweep along x
    tri = np.asarray(triangles, dtype=np.int64)[order]
    corners = x[tri]  # (T, 3, 3)
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    tol = 1e-10 * float(np.linalg.norm(np.ptp(x, axis=0)))  # round-off of the positions
    found = []
    for start in range(0, tri.shape[0], CHUNK):
        rows = np.arange(start, min(start + CHUNK, tri.shape[0]))
        # later triangles (in x order) that start before the chunk ends along x
        cols = np.arange(start, np.searchsorted(lo[:, 0], hi[rows, 0].max(), side="right"))
        overlap = np.all((lo[rows, None] <= hi[None, cols]) & (lo[None, cols] <= hi[rows, None]),
                         axis=2)
        overlap &= rows[:, None] < cols[None]
        i, j = np.nonzero(overlap)
        i, j = rows[i], cols[j]
        shared = (tri[i][:, :, None] == tri[j][:, None, :]).any(axis=(1, 2))
        i, j = i[~shared], j[~shared]
        hit = np.zeros(i.size, bool)
        for s, t in ((i, j), (j, i)):  # an edge of s through triangle t
            a, b, c = (corners[t, k] for k in range(3))
            for e0, e1 in ((0, 1), (1, 2), (2, 0)):
                hit |= _segment_crosses(corners[s, e0], corners[s, e1], a, b, c, tol)
        pairs = np.sort(order[np.stack([i[hit], j[hit]], axis=1)], axis=1)
        found.append(pairs)
    return np.concatenate(found) if found else np.empty((0, 2), np.int64)


def surface_components(triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The connected pieces of a triangle soup, consistently oriented, and which are closed.

    Two triangles are in one piece when they share an edge that no third triangle has. A
    piece is closed when each of its edges is in exactly two of its triangles and it can be
    oriented (each edge run once each way): the boundary of a solid body (its triangles are
    given sorted by :func:`boundary_triangles`, so the orientation is rebuilt here). The
    orientation is found without a loop over triangles: on a graph with two nodes per
    triangle (kept, flipped) each shared edge links the pairs of choices that agree on it,
    and a closed piece's triangles take the choice in the graph component of its first.

    Args:
        triangles: (triangles, 3) vertex indices.

    Returns:
        ``oriented`` (the triangles, rows of closed pieces reordered to one orientation per
        piece), ``piece`` (the piece of each triangle, 0..pieces-1) and ``closed`` (per piece).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    tri = np.asarray(triangles, dtype=np.int64)
    n = tri.shape[0]
    edges = tri[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)  # (3n, 2) directed
    owner = np.repeat(np.arange(n), 3)
    forward = edges[:, 0] < edges[:, 1]
    key = np.sort(edges, axis=1)
    _, which, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    which = which.ravel()
    order = np.argsort(which, kind="stable")
    twice = counts[which[order]] == 2  # the two uses of a manifold edge, consecutive
    first = order[twice][0::2]
    second = order[twice][1::2]
    a, b = owner[first], owner[second]
    flip = forward[first] == forward[second]  # same direction: one of the two must flip
    one = np.ones(a.size)
    pieces, piece = connected_components(coo_matrix((one, (a, b)), shape=(n, n)),
                                         directed=False)
    rows = np.concatenate([a, a + n])
    cols = np.concatenate([np.where(flip, b + n, b), np.where(flip, b, b + n)])
    _, choice = connected_components(
        coo_matrix((np.ones(rows.size), (rows, cols)), shape=(2 * n, 2 * n)), directed=False)
    orientable = np.ones(pieces, bool)
    np.logical_and.at(orientable, piece, choice[:n] != choice[n:])
    border = np.zeros(pieces, bool)  # an edge used once, or by more than two triangles
    np.logical_or.at(border, piece[owner], counts[which] != 2)
    closed = orientable & ~border
    root = np.full(pieces, n)
    np.minimum.at(root, piece, np.arange(n))
    flipped = closed[piece] & (choice[:n] != choice[root[piece]])
    oriented = tri.copy()
    oriented[flipped] = tri[flipped][:, [0, 2, 1]]
    return oriented, piece, closed


def winding_numbers(x: np.ndarray, triangles: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Generalised winding numbers of an oriented triangle surface at points q.

    w(q) = sum over triangles of their solid angle at q / (4 pi) (Jacobson, Kavan and
    Sorkine-Hornung 2013), the solid angle by van Oosterom and Strackee (1983):
    tan(Omega / 2) = det[a b c] / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|), a, b, c
    the corners relative to q. For a closed surface w is 1 inside (outward orientation;
    -1 inward), 0 outside, and jumps only across the surface.

    Args:
        x: Vertex positions, (vertices, 3).
        triangles: (triangles, 3) vertex indices, consistently oriented.
        q: Query points, (points, 3).

    Returns:
        (points,) winding numbers.
    """
    corners = x[np.asarray(triangles, dtype=np.int64)]  # (T, 3, 3)
    w = np.zeros(q.shape[0])
    step = max(1, BLOCK // max(1, corners.shape[0]))
    for start in range(0, q.shape[0], step):
        rel = corners[None] - q[start:start + step, None, None, :]  # (Q, T, 3, 3)
        a, b, c = rel[:, :, 0], rel[:, :, 1], rel[:, :, 2]
        la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
        det = np.einsum("qti,qti->qt", a, np.cross(b, c))
        den = (la * lb * lc + np.einsum("qti,qti->qt", a, b) * lc
               + np.einsum("qti,qti->qt", b, c) * la + np.einsum("qti,qti->qt", c, a) * lb)
        w[start:start + step] = 2.0 * np.arctan2(det, den).sum(axis=1) / (4.0 * np.pi)
    return w


def _point_triangle_distances(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                              c: np.ndarray) -> np.ndarray:
    """Euclidean distance from p to the closed triangle abc (broadcast over leading axes):
    to the plane where p projects inside, else to the nearest edge."""
    def segment(u, v):
        e = v - u
        s = np.clip(np.sum((p - u) * e, -1) / np.maximum(np.sum(e * e, -1), 1e-300), 0, 1)
        return np.linalg.norm(p - u - s[..., None] * e, axis=-1)

    n = np.cross(b - a, c - a)
    area2 = np.linalg.norm(n, axis=-1)
    height = np.sum((p - a) * n, -1) / np.where(area2 > 0, area2, 1.0)
    inside = area2 > 0
    for u, v in ((a, b), (b, c), (c, a)):  # p on the inner side of each edge in the plane
        inside = inside & (np.sum(np.cross(v - u, p - u) * n, -1) >= 0)
    edge = np.minimum(np.minimum(segment(a, b), segment(b, c)), segment(c, a))
    return np.where(inside, np.abs(height), edge)


def _outward(x: np.ndarray, triangles: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """The closed pieces of one body oriented outward from its material: the piece of the
    largest enclosed volume (the outer surface) to a positive signed volume, the others
    (cavities, inside it) to a negative one, so their winding numbers sum to 1 in the
    material and 0 in a cavity."""
    _, local = np.unique(piece, return_inverse=True)
    a, b, c = (x[triangles[:, i]] for i in range(3))
    volume = np.bincount(local, weights=np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0)
    outer = np.argmax(np.abs(volume))
    sign = np.where(np.arange(volume.size) == outer, 1.0, -1.0) * np.sign(volume)
    out = triangles.copy()
    flip = sign[local] < 0
    out[flip] = triangles[flip][:, [0, 2, 1]]
    return out


def enclosed_vertices(x: np.ndarray, triangles: np.ndarray, components=None,
                      bodies=None) -> np.ndarray:
    """Vertices of a triangle soup strictly inside a body they are not part of.

    A body wholly inside another (tunnelled through its surface, or a thin body passed
    into it) has no crossing for :func:`crossing_pairs` to find; its vertices are inside the
    other's closed surface. A body is bounded by closed pieces (:func:`surface_components`):
    by default each closed piece is a body of its own; ``bodies`` groups them (an outer
    surface with its cavities: :func:`crossed_frames` groups by the tetrahedra's
    connectivity). For each body the vertices of the other pieces within its bounding box
    get the winding number of its pieces oriented outward (:func:`winding_numbers`: 1 in its
    material, 0 outside and in a cavity); a vertex is enclosed when |w| > 1/2 and its
    distance to the body's surface is above 1e-10 of the scene's size (a vertex on the
    surface, touching, is not inside; a crossing there is :func:`crossing_pairs`' to find).
    An open piece (a shell) contains nothing; its vertices are tested.

    Args:
        x: Vertex positions, (vertices, 3).
        triangles: (triangles, 3) vertex indices.
        components: :func:`surface_components` of ``triangles``, if already at hand.
        bodies: The body of each piece, (pieces,) ints (default: each piece its own).

    Returns:
        The indices of the enclosed vertices (sorted; empty: none).
    """
    oriented, piece, closed = components or surface_components(triangles)
    if not closed.any():
        return np.empty(0, np.int64)
    body = np.arange(closed.size) if bodies is None else np.asarray(bodies)
    used = np.unique(oriented)
    tol = 1e-10 * float(np.linalg.norm(np.ptp(x[used], axis=0)))
    found = []
    for b in np.unique(body[closed]):
        keep = closed[piece] & (body[piece] == b)
        mine = _outward(x, oriented[keep], piece[keep])
        corners = x[mine]
        lo, hi = corners.min(axis=(0, 1)) - tol, corners.max(axis=(0, 1)) + tol
        others = np.setdiff1d(used, oriented[body[piece] == b])
        q = others[np.all((x[others] >= lo) & (x[others] <= hi), axis=1)]
        if q.size == 0:
            continue
        q = q[np.abs(winding_numbers(x, mine, x[q])) > 0.5]
        step = max(1, BLOCK // (3 * mine.shape[0]))
        for start in range(0, q.size, step):
            p = x[q[start:start + step], None, :]
            d = _point_triangle_distances(p, corners[None, :, 0], corners[None, :, 1],
                                          corners[None, :, 2]).min(axis=1)
            found.append(q[start:start + step][d > tol])
    return np.unique(np.concatenate(found)) if found else np.empty(0, np.int64)


def intersecting(x: np.ndarray, triangles: np.ndarray, components=None,
                 bodies=None) -> bool:
    """Whether a triangle soup has an intersection: a crossing (:func:`crossing_pairs`) or
    a vertex strictly inside another piece's closed surface (:func:`enclosed_vertices`).

    Args:
        x: Vertex positions, (vertices, 3).
        triangles: (triangles, 3) vertex indices.
        components: :func:`surface_components` of ``triangles``, if already at hand.
        bodies: The body of each piece (:func:`enclosed_vertices`).
    """
    return bool(len(crossing_pairs(x, triangles))
                or len(enclosed_vertices(x, triangles, components, bodies)))


def crossed_frames(points: np.ndarray, cells: np.ndarray, frames) -> list[int]:
    """Indices of the frames with an intersection: a crossing, or a body inside another.

    Args:
        points: The rest positions of the vertices, (vertices, 3).
        cells: The tetrahedra, (cells, 4) vertex indices (or (cells, 10), quadratic), or a
            shell's triangles, (cells, 3).
        frames: An iterable of displacements, each (vertices, 3), in vertex order.

    Returns:
        The indices k of ``frames`` where ipctk's ``has_intersections`` is true or a vertex
        is inside another body's boundary (:func:`enclosed_vertices`; solids), or where
        :func:`crossing_pairs` finds a pair (a shell's triangles: open, nothing inside).
    """
    if cells.shape[1] == 3:
        return [k for k, u in enumerate(frames) if len(crossing_pairs(points + u, cells))]
    import ipctk

    mesh, used = surface_collision_mesh(points, cells)
    rest = mesh.rest_positions
    F = boundary_triangles(cells)
    components = surface_components(F)
    bodies = solid_bodies(cells, F, components[1])
    return [k for k, u in enumerate(frames)
            if ipctk.has_intersections(mesh, np.asfortranarray(rest + u[used]))
            or len(enclosed_vertices(points + u, F, components, bodies))]


def solid_bodies(cells: np.ndarray, triangles: np.ndarray, piece: np.ndarray) -> np.ndarray:
    """The body of each piece of a tetrahedral mesh's boundary: pieces whose cells are
    connected (share a vertex) are one body (an outer surface and its cavities).

    Args:
        cells: The tetrahedra, (cells, 4) or (cells, 10).
        triangles: Their :func:`boundary_triangles`.
        piece: The piece of each triangle (:func:`surface_components`).

    Returns:
        (pieces,) body labels.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    corners = np.asarray(cells, dtype=np.int64)
    n = int(corners.max()) + 1
    rows = np.repeat(corners[:, 0], corners.shape[1])
    _, vertex_body = connected_components(
        coo_matrix((np.ones(rows.size), (rows, corners.ravel())), shape=(n, n)),
        directed=False)
    body = np.zeros(int(piece.max()) + 1 if piece.size else 0, np.int64)
    body[piece] = vertex_body[np.asarray(triangles)[:, 0]]
    return body


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
