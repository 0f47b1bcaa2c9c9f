"""Every degree of freedom of a P1 or P2 field, in an order that does not depend on the ranks.

The trajectory's ``displacement`` is the field at the mesh vertices: for a P2 body
(seed section 4.2: quadratic elements) that drops the edge dofs, and a step's discrete
equations (seed eq. 4) cannot be re-checked from it. :class:`DofGather` names each dof
block of a Lagrange space of degree 1 or 2 by the input vertices it sits on: a vertex dof
is ``(i, i)``, an edge dof ``(i, j)`` with ``i < j`` (the edge's two end vertices in the
input mesh's numbering, whatever the partition). The global order is every vertex
``0 .. v-1`` first (so the first ``v`` rows are the vertex values), then the edges in
lexicographic order of ``(i, j)``: a serial run and a run under ``mpirun -n N`` write the
same rows.

Which cell vertices a dof sits on is read from its coordinates (the dof of a vertex is at
the vertex, the dof of an edge at its midpoint, for the affine geometry of fem_anim's
meshes), not from a reference-cell numbering, so it holds for DOLFINx 0.5 and 0.9 alike.
"""

from __future__ import annotations

import numpy as np
from mpi4py import MPI

from fem_anim import compat
from fem_anim.mesh.simplex import SimplexMesh

__all__ = ["DofGather", "CHUNK"]


#: Cells whose dof-to-candidate distances are compared at once (bounds the memory: 10 MB
#: for P2 tetrahedra).
CHUNK = 4096


def _nearest(dof_x: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """For each cell's dofs ``(c, ndofs, 3)``, the candidate point ``(c, k, 3)`` it sits on.

    Raises:
        ValueError: a dof not unambiguously at one candidate.
    """
    dist = np.linalg.norm(dof_x[:, :, None, :] - candidates[:, None, :, :], axis=3)
    order = np.argsort(dist, axis=2)
    best = np.take_along_axis(dist, order[:, :, :1], 2)
    second = np.take_along_axis(dist, order[:, :, 1:2], 2)
    # unambiguous whatever the coordinates' size: a P2 dof is at its vertex or midpoint up
    # to round-off, a P3 dof (at a third of an edge) only half as far from its nearest
    # candidate as from the next
    if np.any(best > 1e-3 * second):
        raise ValueError("a dof sits neither at a vertex nor at an edge midpoint: only "
                         "Lagrange spaces of degree 1 or 2 are gathered")
    return order[:, :, 0]


class DofGather:
    """Collects all dof blocks of a Function on rank 0 in the rank-independent order.

    Args:
        domain: The mesh (its geometry nodes' input vertex numbers).
        V: A Lagrange space of degree 1 or 2 on it (vector or scalar).

    Attributes:
        nodes: (rank 0) The ``(i, j)`` input vertex pair of each global row, ``(n, 2)``.

    Raises:
        ValueError: a dof that sits neither at a vertex nor at an edge midpoint of its cell
            (a space of degree > 2, or a curved geometry).
    """

    def __init__(self, domain: SimplexMesh, V):
        mesh = domain.mesh
        self.comm: MPI.Comm = mesh.comm
        self.bs = V.dofmap.index_map_bs
        tdim = mesh.topology.dim
        nodes = compat.geometry_dofmap(mesh)
        num_cells = mesh.topology.index_map(tdim).size_local + \
            mesh.topology.index_map(tdim).num_ghosts
        nodes = np.asarray(nodes[:num_cells, : tdim + 1], dtype=np.int64)
        vertex = np.asarray(domain.input_index, dtype=np.int64)[nodes]  # (c, tdim+1)
        x = mesh.geometry.x[nodes]  # (c, tdim+1, 3)
        a, b = np.triu_indices(tdim + 1)  # every vertex (a == b) and edge (a < b)
        candidates = 0.5 * (x[:, a] + x[:, b])  # (c, k, 3)
        cell_dofs = np.asarray(compat.cell_dofs(V)[:num_cells], dtype=np.int64)
        dof_x = V.tabulate_dof_coordinates()[cell_dofs]  # (c, ndofs, 3)
        pick = np.concatenate([_nearest(dof_x[k: k + CHUNK], candidates[k: k + CHUNK])
                               for k in range(0, num_cells, CHUNK)] +
                              [np.empty((0, cell_dofs.shape[1]), np.int64)])
        i = np.take_along_axis(vertex, a[pick], 1)
        j = np.take_along_axis(vertex, b[pick], 1)
        key = np.stack([np.minimum(i, j), np.maximum(i, j)], axis=-1).reshape(-1, 2)
        block = cell_dofs.ravel()
        owned = V.dofmap.index_map.size_local
        keep = block < owned
        block, key = block[keep], key[keep]
        self.block, first = np.unique(block, return_index=True)  # owned blocks, each once
        key = key[first]
        parts = self.comm.gather(key, root=0)
        self.nodes = None
        if self.comm.rank == 0:
            every = np.concatenate(parts)
            vertex_rows = every[:, 0] == every[:, 1]
            edges = np.unique(every[~vertex_rows], axis=0)
            verts = np.unique(every[vertex_rows, 0])
            self.nodes = np.concatenate([np.stack([verts, verts], axis=1), edges])
            self._code = self._encode(self.nodes)
        self.num_rows = self.comm.bcast(None if self.nodes is None else self.nodes.shape[0],
                                        root=0)
        self._key = key

    def _encode(self, key: np.ndarray) -> np.ndarray:
        """One sortable integer per ``(i, j)``, increasing in the global row order."""
        big = np.int64(2**31)
        vertex = key[:, 0] == key[:, 1]
        return np.where(vertex, key[:, 0], big + key[:, 0] * big + key[:, 1])

    def _rows(self, key: np.ndarray) -> np.ndarray:
        """The global row of each ``(i, j)`` (rank 0)."""
        return np.searchsorted(self._code, self._encode(key))

    def gather(self, values: np.ndarray) -> np.ndarray | None:
        """All dof blocks of a local dof array on rank 0 (collective).

        Args:
            values: The Function's local dof array (owned and ghost entries).

        Returns:
            ``(n, bs)`` values in the global row order (:attr:`nodes`) on rank 0; None
            elsewhere.
        """
        local = np.asarray(values).reshape(-1, self.bs)[self.block]
        parts = self.comm.gather((self._key, local), root=0)
        if self.comm.rank != 0:
            return None
        out = np.full((self.num_rows, self.bs), np.nan)
        for key, part in parts:
            out[self._rows(key)] = part
        return out

    def scatter(self, rows: np.ndarray | None, values: np.ndarray) -> None:
        """Write global rows (given on rank 0) into the owned entries of a local dof array
        ``values`` in place; ghost entries are left to the caller's ghost update
        (collective)."""
        rows = self.comm.bcast(None if rows is None else np.asarray(rows, float), root=0)
        parts = self.comm.gather(self._key, root=0)
        mine = [self._rows(k) for k in parts] if self.comm.rank == 0 else None
        mine = self.comm.scatter(mine, root=0)
        out = np.asarray(values).reshape(-1, self.bs)
        out[self.block] = rows.reshape(-1, self.bs)[mine]
