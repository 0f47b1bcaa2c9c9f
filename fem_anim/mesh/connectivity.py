"""Is a mesh one body? Connected components of cells and unmerged duplicate vertices.

Two cells belong to the same body when a chain of cells sharing vertices joins them
(the connected components of the cell-vertex graph). A mesh exported cell by cell,
without merging coincident vertices, falls apart into as many bodies as it has cells:
the count of vertices that repeat another one's coordinates shows it. A scene body must
be one piece: :func:`check_one_body` refuses anything else, naming both counts;
:func:`cell_components` labels the pieces, so a scene of several bodies can apply the
same test to each of its bodies.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from fem_anim.errors import MeshError

__all__ = ["cell_components", "duplicate_vertices", "check_one_body", "DUPLICATE_TOLERANCE"]

#: Vertices closer than this fraction of the mesh's extent count as the same point.
DUPLICATE_TOLERANCE = 1e-10


def cell_components(cells: np.ndarray, num_points: int) -> np.ndarray:
    """Label of each cell's connected component (0, 1, ...; cells sharing a vertex agree).

    The bipartite graph cells -- vertices has one edge per (cell, corner); its
    components, restricted to the cell nodes, are the bodies.
    """
    num_cells, k = cells.shape
    rows = np.repeat(np.arange(num_cells), k)
    graph = coo_matrix((np.ones(rows.size), (rows, num_cells + cells.ravel())),
                       shape=(num_cells + num_points,) * 2)
    _, labels = connected_components(graph, directed=False)
    _, compact = np.unique(labels[:num_cells], return_inverse=True)
    return compact.reshape(-1)


def duplicate_vertices(points: np.ndarray) -> int:
    """How many vertices repeat another vertex's coordinates (to
    :data:`DUPLICATE_TOLERANCE` of the extent): an unmerged mesh has many."""
    if points.shape[0] == 0:
        return 0
    extent = float(np.max(np.ptp(points, axis=0))) or 1.0
    q = np.round((points - points.min(axis=0)) / (extent * DUPLICATE_TOLERANCE))
    return int(points.shape[0] - np.unique(q, axis=0).shape[0])


def check_one_body(points: np.ndarray, cells: np.ndarray, source: str,
                   several_pieces: bool = False) -> None:
    """Refuse a mesh of several pieces, or one with coincident unmerged vertices.

    Args:
        points: ``(n, gdim)`` vertex coordinates.
        cells: ``(m, k)`` vertex indices.
        source: What the mesh is, for the message.
        several_pieces: Accept several pieces (a shell's layers of cloth, which meet through
            its self contact only); duplicate vertices are still refused.

    Raises:
        MeshError: naming the number of pieces and of duplicate vertices.
    """
    labels = cell_components(cells, points.shape[0])
    pieces = int(labels.max()) + 1 if labels.size else 0
    if several_pieces:
        pieces = min(pieces, 1)
    duplicates = duplicate_vertices(points)
    if pieces <= 1 and duplicates == 0:
        return
    what = []
    if pieces > 1:
        sizes = np.bincount(labels)
        what.append(f"{pieces} disconnected pieces (cells sharing no vertex; the largest has "
                    f"{int(sizes.max())} of {cells.shape[0]} cells)")
    if duplicates:
        what.append(f"{duplicates} duplicate vertices (coincident but not merged)")
    advice = "merge the duplicate vertices in the mesh tool" if duplicates else \
        "mesh one connected piece per scene"
    raise MeshError(f"{source} is not one body: {' and '.join(what)}; {advice}")
