"""The contact surface distributed over MPI ranks: owned facets, a halo, and the exchanges.

IPC's barrier (seed eq. 4's ``E`` with Li et al. 2020's barrier added, see
:mod:`fem_anim.contact.ipc`) is a sum over the pairs of boundary primitives closer than
d_hat, and its continuous collision detection a minimum over the pairs that meet during a
sweep. Both split over ranks without gathering the surface:

* **Ownership.** Each exterior facet belongs to the rank holding its cell (global facet id:
  the rank's offset plus the facet's place in ``exterior_facet_indices``), each surface
  vertex to the rank owning its dof block. A collision (after ipctk merges its candidates
  into vertex-vertex, edge-vertex, edge-edge or face-vertex pairs) belongs to the owner of
  its lowest global vertex; every rank evaluates only the collisions it owns, so each pair
  is counted once and sums are ``allreduce``'d.
* **Halo.** A rank's local collision mesh is its own facets plus every remote facet whose
  bounding box comes within ``radius`` of its *region* and that has a vertex at or above
  the rank's first owned block: the region is the boxes of its facets and of its owned
  surface vertices, grouped in chunks of :data:`CHUNK` items along a Morton curve;
  the chunk boxes are the only thing every rank receives (a replicated coarse
  bounding-volume list), and each rank sends a neighbour only the facets that meet that
  neighbour's boxes. With L the longest surface edge, every primitive of a collision owned
  by a rank, every candidate ipctk merges into it and the one-ring faces that give its area
  weight lie within d_hat + 3 L of its lowest vertex, so a halo of radius
  d_hat + 3 L + 8 m holds all of them while no surface vertex has moved more than m since
  the halo was built (distances change by at most 2 m, edges grow by at most 2 m). Each of
  those facets contains a vertex of the collision (a primitive of it, a candidate holding
  one, a face around one of its vertices or edges), and every vertex of an owned collision
  is at or above its lowest, owned one: a facet whose vertices all belong to lower ranks
  can serve no collision of this rank and is not sent.
* **Detection restricted to owned pairs.** On more than one rank the local mesh's
  ``can_collide`` (ipctk's filter, applied to vertex pairs in its broad phase; a candidate
  is kept when any pair of its vertices passes) admits a pair only if both vertices are at
  or above the first owned block and one of them is owned (:func:`ownership_filter`):
  every candidate that ipctk merges into an owned collision contains that collision's
  lowest vertex and another of its vertices, so it passes, while pairs of the halo that
  belong to another rank are never narrow-phased, merged, filtered in Python nor swept by
  the CCD here. The collision set is then cut to the owned collisions
  (:func:`owned_collisions`), which the filter leaves few to drop.
* **Exchanges.** Positions x = X + u of a local mesh's vertices are fetched from their
  owners each evaluation (point to point, :class:`VertexExchange`); gradient rows and
  Hessian triplets of remote vertices are sent back to their owners and summed there.

On one rank the local mesh is the whole surface in the serial order, so one rank computes
exactly what the serial code did.
"""

from __future__ import annotations

import ipctk
import numpy as np
from mpi4py import MPI

__all__ = ["CHUNK", "SurfaceHalo", "SurfacePartition", "VertexExchange", "owned_collisions",
           "ownership_filter"]

#: Region items (facets and owned vertices) per replicated bounding box.
CHUNK = 32

_KINDS = ("vv_collisions", "ev_collisions", "ee_collisions", "fv_collisions")


class VertexExchange:
    """Rows of surface vertices fetched from, and summed back to, the ranks owning them.

    Args:
        comm: The communicator.
        ranges: Each rank's end of its owned dof-block range (``allgather``'d).
        start: This rank's first owned dof block.
        needed: The global blocks whose rows this rank needs (sorted, unique).
    """

    def __init__(self, comm: MPI.Comm, ranges: np.ndarray, start: int, needed: np.ndarray):
        self.comm = comm
        owner = np.searchsorted(ranges, needed, side="right")
        #: for each rank q, where its rows land in ``needed``
        self.slots = [np.flatnonzero(owner == q) for q in range(comm.size)]
        incoming = comm.alltoall([needed[s] for s in self.slots])
        #: for each rank q, the owned local blocks it asked for
        self.sends = [np.asarray(ids, np.int64) - start for ids in incoming]
        self.size = needed.size

    def fetch(self, owned_rows: np.ndarray) -> np.ndarray:
        """The needed rows, from the owners' ``owned_rows`` (indexed by local block)."""
        got = self.comm.alltoall([np.ascontiguousarray(owned_rows[s]) for s in self.sends])
        out = np.empty((self.size,) + owned_rows.shape[1:], owned_rows.dtype)
        for slots, rows in zip(self.slots, got):
            out[slots] = rows
        return out

    def add_back(self, rows: np.ndarray, owned_rows: np.ndarray) -> None:
        """Add ``rows`` (one per needed vertex) into the owners' ``owned_rows``, rank by rank."""
        got = self.comm.alltoall([np.ascontiguousarray(rows[s]) for s in self.slots])
        for sends, part in zip(self.sends, got):
            np.add.at(owned_rows, sends, part)


class SurfacePartition:
    """What each rank holds of the surface for good: its facets and its owned vertices.

    Args:
        comm: The mesh communicator.
        faces: This rank's exterior facets as global dof blocks, (facets, tdim).
        rest: Their vertices' rest positions, (facets, tdim, gdim).
        free: Their vertices' free components (not pinned), (facets, tdim, gdim).
        body: Each facet's body index.
        labels: Their vertices' component labels (can_collide: different labels only; all
            equal when the surface may touch itself).
        owned_X: Rest positions of all owned dof blocks, (owned blocks, gdim).
        start, end: This rank's owned dof-block range.
        self_contact: Whether vertices of one label may collide.
    """

    def __init__(self, comm: MPI.Comm, faces: np.ndarray, rest: np.ndarray, free: np.ndarray,
                 body: np.ndarray, labels: np.ndarray, owned_X: np.ndarray, start: int, end: int,
                 self_contact: bool):
        self.comm, self.start, self.end = comm, int(start), int(end)
        self.faces, self.rest, self.free, self.labels = faces, rest, free, labels
        self.body = body
        self.tdim, self.gdim = faces.shape[1], rest.shape[2]
        self.self_contact = self_contact
        self.ranges = np.asarray(comm.allgather(self.end))
        offset = comm.scan(len(faces)) - len(faces)
        self.face_ids = offset + np.arange(len(faces), dtype=np.int64)
        # the owned surface vertices: owners learn of every facet touching their blocks
        ids = np.unique(faces)
        owner = np.searchsorted(self.ranges, ids, side="right")
        told = comm.alltoall([ids[owner == q] for q in range(comm.size)])
        #: owned surface vertices as local blocks (sorted)
        self.blocks = np.unique(np.concatenate([np.asarray(t, np.int64) for t in told]
                                               + [np.empty(0, np.int64)])) - self.start
        self.count = comm.allreduce(self.blocks.size)
        #: the rows this rank's own facets need
        self.face_vertices = ids
        self.face_exchange = VertexExchange(comm, self.ranges, self.start, ids)
        #: rest positions of the owned surface vertices (``blocks`` order)
        self.owned_rest = np.asarray(owned_X)[self.blocks]

    def build(self, u_owned: np.ndarray, reach) -> SurfaceHalo:
        """The local collision mesh within ``reach(L)`` of this rank's region (collective).

        Args:
            u_owned: Displacements of the owned dof blocks, (owned blocks, gdim).
            reach: The halo radius (m) as a function of the longest surface edge L (m).
        """
        return SurfaceHalo(self, u_owned, reach)

    def longest_edge(self, x: np.ndarray) -> float:
        """The longest edge of the whole surface at facet positions ``x`` (collective)."""
        k = self.tdim
        lengths = [np.linalg.norm(x[:, i] - x[:, (i + 1) % k], axis=1) for i in range(k)]
        local = float(np.max(np.concatenate(lengths), initial=0.0))
        return self.comm.allreduce(local, op=MPI.MAX)


def _morton(points: np.ndarray) -> np.ndarray:
    """Order of points along a Morton curve in their bounding box (10 bits per axis)."""
    if len(points) == 0:
        return np.empty(0, np.int64)
    lo, hi = points.min(0), points.max(0)
    q = ((points - lo) / np.where(hi > lo, hi - lo, 1.0) * 1023).astype(np.int64)
    code = np.zeros(len(points), np.int64)
    for bit in range(10):
        for axis in range(points.shape[1]):
            code |= ((q[:, axis] >> bit) & 1) << (bit * points.shape[1] + axis)
    return np.argsort(code, kind="stable")


class SurfaceHalo:
    """One rank's local collision mesh: its facets and the halo, with their exchanges.

    Built collectively by :meth:`SurfacePartition.build`. ``vertices`` are global blocks in
    ascending order (the local vertex numbering), ``faces`` local indices in global facet
    order, so on one rank the mesh is the serial surface.
    """

    def __init__(self, part: SurfacePartition, u_owned: np.ndarray, reach):
        comm, g, tdim = part.comm, part.gdim, part.tdim
        near = part.face_exchange.fetch(u_owned)
        x = part.rest + near[np.searchsorted(part.face_vertices, part.faces)]
        #: the longest surface edge when built (m), and the halo radius
        self.longest = part.longest_edge(x)
        self.part = part
        self.radius = radius = float(reach(self.longest))
        lo, hi = x.min(1), x.max(1)
        if comm.size > 1:
            owned_x = part.owned_rest + u_owned[part.blocks]
            item_lo, item_hi = np.concatenate([lo, owned_x]), np.concatenate([hi, owned_x])
            centre = 0.5 * (item_lo + item_hi)
            order = _morton(centre)
            # chunks of CHUNK items along the curve, cut where the curve jumps by more
            # than the radius (a chunk spanning a gap would pull in what lies between)
            jumps = np.linalg.norm(np.diff(centre[order], axis=0), axis=1) > radius
            boxes = []
            for run in np.split(order, np.flatnonzero(jumps) + 1):
                for k in range(0, len(run), CHUNK):
                    chunk = run[k:k + CHUNK]
                    boxes.append((item_lo[chunk].min(0) - radius,
                                  item_hi[chunk].max(0) + radius))
            boxes = np.asarray(boxes).reshape(-1, 2, g)
            every = comm.allgather(boxes)
            starts = np.r_[0, part.ranges[:-1]]
            top = part.faces.max(axis=1)
            sends = []
            for q, theirs in enumerate(every):
                mask = np.zeros(len(lo), bool)
                if q != comm.rank:
                    for box_lo, box_hi in theirs:
                        mask |= np.all(lo <= box_hi, axis=1) & np.all(hi >= box_lo, axis=1)
                    mask &= top >= starts[q]  # facets of lower ranks only: no pair of q's
                sends.append(tuple(a[mask] for a in (part.face_ids, part.faces, part.rest,
                                                     part.free, part.body, part.labels)))
            got = comm.alltoall(sends)
            got[comm.rank] = (part.face_ids, part.faces, part.rest, part.free, part.body,
                              part.labels)
            ids, faces, rest, free, body, labels = (np.concatenate(a) for a in zip(*got))
            order = np.argsort(ids, kind="stable")
            ids, faces, rest, free, body, labels = ids[order], faces[order], rest[order], \
                free[order], body[order], labels[order]
        else:
            ids, faces, rest, free, body, labels = part.face_ids, part.faces, part.rest, \
                part.free, part.body, part.labels
        self.face_ids = ids
        #: the local vertices' global blocks (ascending)
        self.vertices, first = np.unique(faces.ravel(), return_index=True)
        self.faces = np.searchsorted(self.vertices, faces).astype(np.int32)
        rest_v = rest.reshape(-1, g)[first]
        self.free = free.reshape(-1, g)[first].ravel()
        labels_v = labels.ravel()[first]
        #: each local vertex's body index
        self.vertex_body = np.repeat(body, tdim)[first]
        self.owned = (self.vertices >= part.start) & (self.vertices < part.end)
        self.exchange = VertexExchange(comm, part.ranges, part.start, self.vertices)
        edges = ipctk.edges(self.faces) if tdim == 3 else self.faces
        F = self.faces if tdim == 3 else np.empty((0, 3), np.int32)
        self.mesh = ipctk.CollisionMesh(rest_v, np.asfortranarray(edges, np.int32),
                                        np.asfortranarray(F, np.int32))
        if not part.self_contact:
            self.mesh.can_collide = ipctk.make_connected_components_filter(
                _label_triangles(labels_v))
        if comm.size > 1:
            owned = ownership_filter(*np.searchsorted(self.vertices, [part.start, part.end]))
            self.mesh.can_collide = owned if part.self_contact else \
                self.mesh.can_collide & owned
        self.x_built = self.positions(u_owned)

    def positions(self, u_owned: np.ndarray) -> np.ndarray:
        """x = X + u of the local vertices (collective)."""
        return self.mesh.rest_positions + self.exchange.fetch(u_owned)

    def drift(self, x: np.ndarray) -> float:
        """The largest move of an owned local vertex since the halo was built (collective)."""
        local = np.max(np.abs(x[self.owned] - self.x_built[self.owned]), initial=0.0)
        return self.part.comm.allreduce(float(local) * np.sqrt(self.part.gdim), op=MPI.MAX)

    def to_owners(self, rows: np.ndarray, owned_rows: np.ndarray) -> None:
        """Sum per-local-vertex ``rows`` into the owners' ``owned_rows`` (collective)."""
        self.exchange.add_back(rows, owned_rows)


def ownership_filter(first: int, end: int) -> ipctk.CollisionFilter:
    """ipctk's vertex-pair filter of a rank's local mesh: both vertices at or above local
    vertex ``first`` and one of them below ``end`` (the owned local vertices are
    ``first <= i < end``, as local vertices ascend with global blocks).

    ipctk keeps a candidate when any pair of its vertices passes, so it keeps every
    candidate holding the lowest vertex of a collision this rank owns together with another
    vertex of that collision (module docstring); built from ipctk's own filters, so the
    test runs in its broad phase without calling Python.
    """
    at_or_above = ~ipctk.make_static_obstacle_filter(int(first))  # i >= first and j >= first
    return at_or_above & ipctk.make_static_obstacle_filter(int(end))  # i < end or j < end


def _lowest_vertices(kind: str, items: list, edges: np.ndarray,
                     faces: np.ndarray) -> np.ndarray:
    """The lowest local vertex of each collision of one kind (one attribute read each)."""
    if kind == "vv_collisions":
        pairs = np.array([(c.vertex0_id, c.vertex1_id) for c in items], np.int64)
        return pairs.min(axis=1)
    if kind == "ee_collisions":
        pairs = np.array([(c.edge0_id, c.edge1_id) for c in items], np.int64)
        return np.minimum(edges[pairs[:, 0]].min(axis=1), edges[pairs[:, 1]].min(axis=1))
    pairs = np.array([(c.edge_id if kind == "ev_collisions" else c.face_id, c.vertex_id)
                      for c in items], np.int64)
    cells = edges if kind == "ev_collisions" else faces
    return np.minimum(cells[pairs[:, 0]].min(axis=1), pairs[:, 1])


def owned_collisions(halo: SurfaceHalo, collisions: ipctk.NormalCollisions) -> \
        ipctk.NormalCollisions:
    """The collisions this rank owns (lowest global vertex owned here), in ipctk's order.

    Lowest global vertex = lowest local vertex, as local vertices ascend with global blocks.
    """
    if halo.part.comm.size == 1:
        return collisions
    owned = ipctk.NormalCollisions()
    owned.use_area_weighting = collisions.use_area_weighting
    edges, faces = halo.mesh.edges, halo.mesh.faces
    for kind in _KINDS:
        items = getattr(collisions, kind)
        if items:
            keep = halo.owned[_lowest_vertices(kind, items, edges, faces)]
            items = [c for c, k in zip(items, keep) if k]
        setattr(owned, kind, items)
    return owned


def _label_triangles(labels: np.ndarray) -> np.ndarray:
    """Triangles chaining the vertices of each label, so that ipctk's connected-components
    filter sees one component per label."""
    tris = []
    order = np.argsort(labels, kind="stable")
    for group in np.split(order, np.flatnonzero(np.diff(labels[order])) + 1):
        n = group.size
        tris += [[group[k], group[min(k + 1, n - 1)], group[min(k + 2, n - 1)]]
                 for k in range(0, max(n - 1, 1), 2)]
    return np.asarray(tris, np.int32).reshape(-1, 3)


def surface_labels(comm: MPI.Comm, faces: np.ndarray) -> np.ndarray:
    """Connected-component label of each vertex of this rank's facets (collective).

    Components of the whole surface (ipctk's filter for ``self = false``) need its
    connectivity: rank 0 receives the facets' global vertex blocks once, at set-up (no
    positions; nothing per step), labels the components and sends each rank its labels.

    Returns:
        Labels shaped like ``faces``.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    gathered = comm.gather(faces, root=0)
    parts = None
    if comm.rank == 0:
        every = np.concatenate(gathered)
        ids, inverse = np.unique(every, return_inverse=True)
        local = inverse.reshape(every.shape)
        rows = np.repeat(local[:, 0], local.shape[1])
        graph = coo_matrix((np.ones(rows.size), (rows, local.ravel())),
                           shape=(ids.size, ids.size))
        _, label = connected_components(graph, directed=False)
        counts = np.cumsum([len(f) for f in gathered])[:-1]
        parts = np.split(label[local], counts)
    return comm.scatter(parts, root=0)
