"""Checks that a simplex mesh or a closed surface is usable, naming the first bad cell.

:func:`check_cells` rejects what DOLFINx cannot simulate (flat, repeated, overlapping or
inverted cells, vertices of no cell, non-finite or overflowing coordinates);
:func:`check_surface` rejects a triangulated surface that does not bound one solid.
:func:`cell_volumes` is the signed volume of affine simplices.

Cell orientation: DOLFINx integrates with ``|det J|``, and its facet normals
``J^{-T} n_ref`` point outward whatever the sign of ``det J``, so a mesh whose cells have
mixed vertex orders (as files from some tools do) is accepted. A cell is *inverted* when
it folds over a neighbour: the two cells sharing a facet lie on the same side of it.
"""

from __future__ import annotations

import math

import numpy as np

from fem_anim.errors import MeshError

__all__ = ["FLAT", "MAX_COORDINATE", "cell_volumes", "check_cells", "check_surface"]

#: Coordinates beyond this (or a mesh smaller across than its inverse) are a unit mix-up:
#: cell volumes would overflow (underflow) in double precision.
MAX_COORDINATE = 1.0e100
#: A cell whose ``|det D_m|`` is below this times its longest edge to the ``d`` is flat.
FLAT = 1e-12


def _fmt(x: np.ndarray) -> str:
    return "(" + ", ".join(f"{c:.6g}" for c in x) + ")"


def _check_simplices(points: np.ndarray, cells: np.ndarray, source: str, what: str) -> None:
    """Shape, emptiness, index range and finite coordinates of a simplex array."""
    if cells.ndim != 2 or cells.shape[0] == 0:
        raise MeshError(f"{source}: the mesh has no {what}s")
    n = points.shape[0]
    bad = (cells < 0) | (cells >= n)
    if np.any(bad):
        c, k = np.argwhere(bad)[0]
        raise MeshError(f"{source}: {what} {c} has vertex index {cells[c, k]} out of range "
                        f"0..{n - 1}")
    finite = np.all(np.isfinite(points), axis=1)
    if not np.all(finite):
        v = int(np.argmin(finite))
        raise MeshError(f"{source}: vertex {v} has a NaN or infinite coordinate "
                        f"{_fmt(points[v])}")
    big = np.max(np.abs(points), axis=1) > MAX_COORDINATE
    if np.any(big):  # volumes (edge lengths to the d) would overflow
        v = int(np.argmax(big))
        raise MeshError(f"{source}: vertex {v} {_fmt(points[v])} has a coordinate beyond "
                        f"{MAX_COORDINATE:g} in magnitude")
    extent = float(np.max(np.ptp(points, axis=0))) if n else 0.0
    if 0.0 < extent < 1.0 / MAX_COORDINATE:  # volumes would underflow to zero
        raise MeshError(f"{source}: the mesh is {extent:.3g} across, smaller than "
                        f"{1.0 / MAX_COORDINATE:g} (a unit mix-up?)")


def _signed_measures(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """``det[X_1 - X_0, ..., X_d - X_0]`` per cell (``d!`` times its signed volume)."""
    return np.linalg.det(points[cells[:, 1:]] - points[cells[:, :1]])


def cell_volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """Signed volume (area in 2D) of each affine simplex ``points[cells]``.

    ``det[X_1 - X_0, ..., X_d - X_0] / d!``: positive for a cell whose vertices are in
    counter-clockwise (right-handed) order.

    Args:
        points: ``(n, d)`` vertex coordinates.
        cells: ``(m, d + 1)`` vertex indices.

    A simplex of lower dimension than the points (a triangle in 3D) has no sign: its measure
    is ``sqrt(det(E^T E)) / k!`` with ``E`` its ``k`` edge vectors.

    Returns:
        ``(m,)`` signed volumes.
    """
    k = cells.shape[1] - 1
    if k < points.shape[1]:
        E = points[cells[:, 1:]] - points[cells[:, :1]]
        return np.sqrt(np.linalg.det(E @ E.transpose(0, 2, 1))) / math.factorial(k)
    return _signed_measures(points, cells) / math.factorial(k)


def check_cells(points: np.ndarray, cells: np.ndarray, source: str) -> None:
    """Reject a simplex mesh DOLFINx cannot use, naming the first offending cell or vertex.

    Checked in order: cells exist and have ``d + 1`` vertices; indices are in range;
    coordinates are finite; every vertex belongs to a cell; no cell is flat
    (``|det D_m| <= 1e-12 h^d``, ``h`` its longest edge); no cell repeats another; no facet
    has more than two cells; and no cell is inverted, i.e. folded over the neighbour across
    one of its facets (both on the same side of it). Mixed vertex orders are fine: DOLFINx
    integrates with ``|det J|`` (module docstring).

    Args:
        points: ``(n, d)`` vertex coordinates, ``d`` 2 or 3.
        cells: ``(m, d + 1)`` vertex indices.
        source: What the mesh is, for the message (e.g. the file).

    Raises:
        MeshError: naming the offending cell (or vertex) and what is wrong with it.
    """
    if cells.size == 0:
        raise MeshError(f"{source}: the mesh has no cells")
    d = points.shape[1] if points.ndim == 2 else 0
    if d not in (2, 3) or cells.ndim != 2 or cells.shape[1] != d + 1:
        raise MeshError(f"{source}: expected points of shape (n, 2 or 3) and cells with one "
                        f"more column, got {points.shape} and {cells.shape}")
    _check_simplices(points, cells, source, "cell")
    used = np.bincount(cells.ravel(), minlength=points.shape[0]) > 0
    if not np.all(used):
        v = int(np.argmin(used))
        raise MeshError(f"{source}: vertex {v} {_fmt(points[v])} belongs to no cell")

    measure = _signed_measures(points, cells)
    X = points[cells]
    h = np.sqrt(np.max(np.sum((X[:, :, None] - X[:, None]) ** 2, axis=-1), axis=(1, 2)))
    flat = np.abs(measure) <= FLAT * h**d
    if np.any(flat):
        c = int(np.argmax(flat))
        raise MeshError(f"{source}: cell {c} (vertices {cells[c].tolist()}) has zero volume "
                        f"({measure[c] / math.factorial(d):.3g})")

    _, first, inverse = np.unique(np.sort(cells, axis=1), axis=0, return_index=True,
                                  return_inverse=True)
    repeat = first[inverse.reshape(-1)] != np.arange(cells.shape[0])
    if np.any(repeat):
        c = int(np.argmax(repeat))
        raise MeshError(f"{source}: cell {c} (vertices {cells[c].tolist()}) duplicates cell "
                        f"{int(first[inverse.reshape(-1)[c]])}")
    _check_facets(points, cells, measure, source)


def _check_facets(points: np.ndarray, cells: np.ndarray, measure: np.ndarray,
                  source: str) -> None:
    """No facet of more than two cells, no two cells on the same side of their facet."""
    d = points.shape[1]
    facet_name = ("edge", "face")[d - 2]
    drop = np.array([np.delete(np.arange(d + 1), k) for k in range(d + 1)])  # facet k: not k
    facets = np.sort(cells[:, drop], axis=2).reshape(-1, d)
    owner = np.repeat(np.arange(cells.shape[0]), d + 1)
    opposite = cells.reshape(-1)
    order = np.lexsort(facets.T[::-1])
    facets, owner, opposite = facets[order], owner[order], opposite[order]
    same = np.all(facets[1:] == facets[:-1], axis=1)  # row i and i + 1 are one facet
    if np.any(same[1:] & same[:-1]):
        i = int(np.argmax(same[1:] & same[:-1]))
        raise MeshError(f"{source}: the {facet_name} with vertices {facets[i].tolist()} belongs to "
                        f"more than two cells ({', '.join(map(str, owner[i:i + 3]))}, ...): "
                        "the mesh overlaps itself")
    i = np.flatnonzero(same)
    base = points[facets[i]]
    span = base[:, 1:] - base[:, :1]

    def side(v: np.ndarray) -> np.ndarray:
        return np.linalg.det(np.concatenate([span, (points[v] - base[:, 0])[:, None]], axis=1))

    folded = side(opposite[i]) * side(opposite[i + 1]) > 0
    if np.any(folded):
        k = int(i[np.argmax(folded)])
        a, b = sorted((int(owner[k]), int(owner[k + 1])))
        majority = np.sign(np.sum(np.sign(measure)))
        if np.sign(measure[a]) == np.sign(measure[b]) or majority == 0:
            what = f"cells {a} and {b} overlap (one of them is inverted)"
        else:
            bad, good = (a, b) if np.sign(measure[a]) != majority else (b, a)
            what = f"cell {bad} is inverted: it folds over cell {good}"
        raise MeshError(f"{source}: {what} across their shared {facet_name} "
                        f"with vertices {facets[k].tolist()}")


def check_surface(points: np.ndarray, triangles: np.ndarray, source: str) -> None:
    """Reject a triangulated surface that does not bound one solid, naming an example.

    The surface must be closed (every edge in exactly two triangles), manifold (no edge in
    more than two, and the triangles around each vertex form one fan) and connected.
    Triangle orientation is not needed.

    Args:
        points: ``(n, 3)`` vertex coordinates.
        triangles: ``(m, 3)`` vertex indices.
        source: What the surface is, for the message (e.g. the file).

    Raises:
        MeshError: naming the defect and an edge, vertex or triangle showing it.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    _check_simplices(points, triangles, source, "triangle")
    X = points[triangles]
    area2 = np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
    h = np.max(np.linalg.norm(X - X[:, [1, 2, 0]], axis=2), axis=1)
    flat = area2 <= FLAT * h**2
    if np.any(flat):
        t = int(np.argmax(flat))
        raise MeshError(f"{source}: triangle {t} (vertices {triangles[t].tolist()}) has zero "
                        "area")

    def edge_text(j: int) -> str:
        a, b = unique[j]
        return f"the edge from vertex {a} {_fmt(points[a])} to vertex {b} {_fmt(points[b])}"

    m = triangles.shape[0]
    edges = triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2)  # row 3 t + k
    unique, inverse, counts = np.unique(np.sort(edges, axis=1), axis=0, return_inverse=True,
                                        return_counts=True)
    inverse = inverse.reshape(-1)
    if np.any(counts == 1):
        j = int(np.argmax(counts == 1))
        raise MeshError(f"{source}: the surface is open ({int(np.sum(counts == 1))} edges "
                        f"belong to one triangle only, e.g. {edge_text(j)}); a volume mesh "
                        "is made only from a closed surface")
    if np.any(counts > 2):
        j = int(np.argmax(counts > 2))
        shared = (np.flatnonzero(inverse == j) // 3).tolist()
        raise MeshError(f"{source}: the surface is not manifold: {edge_text(j)} belongs to "
                        f"{counts[j]} triangles {shared} (at most two are allowed)")

    # every edge now has two rows r1, r2; link the corners of its end vertices across it
    rows = np.argsort(inverse, kind="stable").reshape(-1, 2)
    r = rows.ravel()
    second = 3 * (r // 3) + (r % 3 + 1) % 3  # corner (row 3t + k) of the edge's 2nd vertex
    low = np.where(edges[r, 0] < edges[r, 1], r, second).reshape(-1, 2)
    high = np.where(edges[r, 0] < edges[r, 1], second, r).reshape(-1, 2)
    links = np.concatenate([low, high])
    graph = coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(3 * m, 3 * m))
    _, fan = connected_components(graph, directed=False)
    vertex_fans = np.unique(np.stack([triangles.ravel(), fan]), axis=1)[0]
    fans = np.bincount(vertex_fans, minlength=points.shape[0])
    if np.any(fans > 1):
        v = int(np.argmax(fans > 1))
        raise MeshError(f"{source}: the surface is not manifold at vertex {v} {_fmt(points[v])}"
                        f", where {fans[v]} separate sheets of triangles meet")
    pairs = rows // 3
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    parts, label = connected_components(graph, directed=False)
    if parts > 1:
        t = int(np.argmax(label != label[0]))
        raise MeshError(f"{source}: the surface has {parts} separate parts (triangles 0 and "
                        f"{t} are in different ones); only one closed surface is supported")
