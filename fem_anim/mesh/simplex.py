"""The simplex mesh container and its distribution: :class:`SimplexMesh`, :func:`mesh_from_arrays`.

A mesh is given as arrays on rank 0 (vertex coordinates, cells as rows of ``d + 1`` vertex
indices, one region marker per cell), checked there (:func:`fem_anim.mesh.checks.check_cells`)
and distributed with one collective call. Rank 0 keeps the input arrays: output is written in
their ordering, so serial and parallel runs write identical files, and the hand-assembled
reference (:mod:`fem_anim.reference`) can be compared vertex by vertex.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from mpi4py import MPI

from fem_anim import compat
from fem_anim.errors import MeshError
from fem_anim.mesh.checks import check_cells
from fem_anim.mesh.connectivity import check_one_body

__all__ = ["CELL_NAMES", "SimplexMesh", "drop_unused_points", "mesh_from_arrays"]

#: DOLFINx cell name of the simplex of each dimension.
CELL_NAMES = {2: "triangle", 3: "tetrahedron"}


@dataclass
class SimplexMesh:
    """A distributed DOLFINx mesh and, on rank 0, the input arrays it was made from.

    Attributes:
        mesh: The DOLFINx mesh.
        points: Input vertex coordinates (rank 0; empty elsewhere).
        cells: Input cells (rank 0; empty elsewhere).
        cell_markers: Input per-cell region markers (rank 0; empty elsewhere).
        input_index: For each local geometry node, its row in ``points``.
        marker_names: Names of the cell markers (gmsh physical group name -> tag), on
            every rank; empty when the mesh has no named groups.
    """

    mesh: object
    points: np.ndarray
    cells: np.ndarray
    cell_markers: np.ndarray
    input_index: np.ndarray
    marker_names: dict[str, int] = field(default_factory=dict)

    @property
    def dim(self) -> int:
        """Topological (and geometric) dimension, 2 or 3."""
        return self.mesh.topology.dim

    @property
    def num_vertices_global(self) -> int:
        """Number of geometry nodes over all ranks."""
        return self.mesh.geometry.index_map().size_global


def drop_unused_points(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop the points no cell uses and renumber the cells, keeping the points' order.

    Args:
        points: ``(n, d)`` vertex coordinates.
        cells: ``(m, k)`` vertex indices.

    Returns:
        The used points and the renumbered cells; the input unchanged when ``cells`` is
        empty or has an index out of range (:func:`fem_anim.mesh.checks.check_cells` then
        names it).
    """
    if cells.size == 0 or cells.min() < 0 or cells.max() >= points.shape[0]:
        return points, cells
    used = np.unique(cells)
    remap = np.full(points.shape[0], -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return points[used], remap[cells]


def mesh_from_arrays(comm: MPI.Comm, points: np.ndarray, cells: np.ndarray,
                     cell_markers: np.ndarray | None, source: str,
                     marker_names: dict[str, int] | None = None,
                     one_body: bool = False) -> SimplexMesh:
    """Check and distribute a mesh given on rank 0 (collective).

    The check (:func:`fem_anim.mesh.checks.check_cells`) runs on rank 0 and its verdict is
    broadcast, so a bad mesh raises the same :class:`MeshError` on all ranks.

    Args:
        comm: The communicator the mesh is distributed over.
        points: ``(n, d)`` vertex coordinates on rank 0; other ranks pass empty arrays of
            the right width.
        cells: ``(m, d + 1)`` vertex indices on rank 0 (empty elsewhere).
        cell_markers: Region marker per cell on rank 0, or None for all 1.
        source: What the mesh is, for error messages.
        marker_names: Names of the marker values (rank 0's is used).
        one_body: Also require one connected piece without duplicate vertices
            (:func:`fem_anim.mesh.connectivity.check_one_body`).

    Returns:
        The distributed mesh, rank 0 keeping the input arrays.

    Raises:
        MeshError: on every rank, if the mesh fails a check.
    """
    error = None
    if comm.rank == 0:
        try:
            check_cells(points, cells, source)
            if one_body:
                check_one_body(points, cells, source)
        except MeshError as err:
            error = str(err)
    error = comm.bcast(error, root=0)
    if error:
        raise MeshError(error)
    d = comm.bcast(points.shape[1] if comm.rank == 0 else None, root=0)
    if comm.rank != 0:
        points = np.empty((0, d))
        cells = np.empty((0, d + 1), dtype=np.int64)
        cell_markers = np.empty(0, dtype=np.int32)
    elif cell_markers is None:
        cell_markers = np.ones(cells.shape[0], dtype=np.int32)
    mesh = compat.create_mesh(comm, cells.astype(np.int64), points, d, CELL_NAMES[d])
    input_index = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)
    names = comm.bcast(dict(marker_names or {}), root=0)
    return SimplexMesh(mesh, points, cells, cell_markers.astype(np.int32), input_index, names)
