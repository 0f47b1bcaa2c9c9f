"""From a scene's ``[mesh]`` to a distributed DOLFINx mesh (STYLE rule 3).

The mesh is made on rank 0 (a gmsh builder of :mod:`fem_anim.meshes`, or a file meshio
reads, a closed triangulated surface being filled with tetrahedra by gmsh), checked there
(:func:`check_cells`, :func:`check_surface`), and distributed with one collective call.
Rank 0 keeps the input points and cells: output is written in that ordering, so serial
and parallel runs write identical files, and the hand-assembled reference
(:mod:`fem_anim.reference`) can be compared vertex by vertex.

Cell orientation: DOLFINx 0.5 integrates with ``|det J|``, and its facet normals
``J^{-T} n_ref`` point outward whatever the sign of ``det J``, so a mesh whose cells have
mixed vertex orders (as files from some tools do) is accepted. A cell is *inverted* when
it folds over a neighbour: the two cells sharing a facet lie on the same side of it.
"""

from __future__ import annotations

import contextlib
import io
import math
import signal
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim import compat
from fem_anim.mesh.connectivity import check_one_body
from fem_anim.errors import MeshError
from fem_anim.meshes.structured import structured_box

__all__ = [
    "SimplexMesh",
    "build_mesh",
    "cell_volumes",
    "check_cells",
    "check_surface",
    "mesh_arrays",
    "mesh_from_arrays",
    "read_mesh_file",
]

CELL_NAMES = {2: "triangle", 3: "tetrahedron"}
PLURAL = {2: "triangles", 3: "tetrahedra"}
#: meshio cell types read as simplices of each dimension (higher-order ones by their corners).
MESHIO_TYPES = {2: ("triangle", "triangle6", "triangle7"), 3: ("tetra", "tetra10")}
#: Integer cell data taken as region markers, first found wins.
MARKER_KEYS = ("gmsh:physical", "medit:ref", "cell_markers", "CellEntityIds")
#: Coordinates beyond this (or a mesh smaller across than its inverse) are a unit mix-up:
#: cell volumes would overflow (underflow) in double precision.
MAX_COORDINATE = 1.0e100
#: A cell whose ``|det D_m|`` is below this times its longest edge to the ``d`` is flat.
FLAT = 1e-12


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
        return self.mesh.topology.dim

    @property
    def num_vertices_global(self) -> int:
        return self.mesh.geometry.index_map().size_global


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
    """Signed volume (area in 2D) of each affine simplex ``points[cells]`` (vectorised)."""
    return _signed_measures(points, cells) / math.factorial(cells.shape[1] - 1)


def check_cells(points: np.ndarray, cells: np.ndarray, source: str) -> None:
    """Reject a simplex mesh DOLFINx cannot use, naming the first offending cell or vertex.

    Checked in order: cells exist and have ``d + 1`` vertices; indices are in range;
    coordinates are finite; every vertex belongs to a cell; no cell is flat
    (``|det D_m| <= 1e-12 h^d``, ``h`` its longest edge); no cell repeats another; no facet
    has more than two cells; and no cell is inverted, i.e. folded over the neighbour across
    one of its facets (both on the same side of it). Mixed vertex orders are fine: DOLFINx
    integrates with ``|det J|`` (module docstring).

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


def mesh_from_arrays(comm: MPI.Comm, points: np.ndarray, cells: np.ndarray,
                     cell_markers: np.ndarray | None, source: str,
                     marker_names: dict[str, int] | None = None,
                     one_body: bool = False) -> SimplexMesh:
    """Check and distribute a mesh given on rank 0 (collective).

    With ``one_body`` the mesh must also be one connected piece without duplicate
    vertices (:func:`fem_anim.mesh.connectivity.check_one_body`).

    Other ranks pass empty arrays of the right width. The check runs on rank 0 and its
    verdict is broadcast, so a bad mesh raises the same :class:`MeshError` on all ranks.
    ``marker_names`` (rank 0's is used) names the values of ``cell_markers``.
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


@contextlib.contextmanager
def _gmsh_session(source: str, hint: str):
    """An initialised, quiet, single-threaded gmsh; its failures become :class:`MeshError`.

    The message names ``source``, gmsh's own error and ``hint``, the likely cause. The
    SIGINT handler in force before is put back afterwards: gmsh sets SIGINT to the default
    action (4.8 when imported, 4.13 in ``initialize``) and 4.13's ``finalize`` does not
    restore it (the handler it saves lands in a local variable), which left a run that
    pressed Ctrl-C while compiling its forms killed outright instead of stopped cleanly
    (fem_anim.simulation.interrupt).
    """
    sigint = signal.getsignal(signal.SIGINT)  # before the import: gmsh 4.8 sets it there
    import gmsh

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.logger.start()
        try:
            yield gmsh.model
        except MeshError:
            raise
        except Exception as err:
            if type(err) is not Exception:  # gmsh raises bare Exceptions; others are bugs
                raise
            errors = [m for m in gmsh.logger.get() if m.startswith("Error")]
            detail = " ".join((str(err) or (errors[-1] if errors else repr(err))).split())
            raise MeshError(f"{source}: gmsh failed: {detail} ({hint})") from None
    finally:
        gmsh.finalize()
        if sigint is not None and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, sigint)


def _gmsh_arrays(model, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Vertices, simplices, physical-group markers and group names of a meshed gmsh model."""
    tags, coords, _ = model.mesh.getNodes()
    points = coords.reshape(-1, 3)[:, :dim]
    index = np.empty(int(tags.max()) + 1 if tags.size else 0, dtype=np.int64)
    index[tags] = np.arange(tags.size)  # gmsh node tag -> row of points
    etype = {2: 2, 3: 4}[dim]  # gmsh: 3-node triangle, 4-node tetrahedron
    cells_list, markers_list = [], []
    names = {model.getPhysicalName(dim, group): group
             for _, group in model.getPhysicalGroups(dim) if model.getPhysicalName(dim, group)}
    for _, group in model.getPhysicalGroups(dim):
        for entity in model.getEntitiesForPhysicalGroup(dim, group):
            types, _, nodes = model.mesh.getElements(dim, entity)
            for t, n in zip(types, nodes):
                if t == etype:
                    cells_list.append(index[np.asarray(n, dtype=np.int64)].reshape(-1, dim + 1))
                    markers_list.append(np.full(cells_list[-1].shape[0], group, np.int32))
    if not cells_list:
        return points, np.empty((0, dim + 1), np.int64), np.empty(0, np.int32), names
    points, cells = _compact(points, np.concatenate(cells_list))
    return points, cells, np.concatenate(markers_list), names


def _compact(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop the points no cell uses (unless an index is out of range: check_cells says so)."""
    if cells.size == 0 or cells.min() < 0 or cells.max() >= points.shape[0]:
        return points, cells
    used = np.unique(cells)
    remap = np.full(points.shape[0], -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return points[used], remap[cells]


def _build_gmsh(cfg: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Mesh ``cfg["shape"]`` with its builder, given the whole ``[mesh]`` table."""
    from fem_anim.meshes import BUILDERS

    source = f"mesh ({cfg['shape']})"
    hint = f"is mesh.element_size = {cfg['element_size']} too large for the shape?"
    with _gmsh_session(source, hint) as model:
        try:
            model = BUILDERS[cfg["shape"]](model, cfg)
        except ValueError as err:
            raise MeshError(f"{source}: {err}") from None
        return _gmsh_arrays(model, cfg["dim"])


def _fill_surface(points: np.ndarray, triangles: np.ndarray, element_size: float,
                  source: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Tetrahedralise the solid a closed surface bounds (checked first)."""
    from fem_anim.meshes import build_volume_from_surface

    # merge repeated vertices (an STL has no others), keeping the first occurrences' order
    _, first, inverse = np.unique(points, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    points, triangles = points[first[order]], rank[inverse.reshape(-1)][triangles]
    check_surface(points, triangles, source)
    with _gmsh_session(source, "the surface must not intersect itself") as model:
        model = build_volume_from_surface(model, points, triangles, element_size)
        points, cells, markers, names = _gmsh_arrays(model, 3)
    if cells.shape[0] == 0:
        raise MeshError(f"{source}: gmsh made no tetrahedra inside the surface")
    return points, cells, markers, names


def read_mesh_file(path: Path, dim: int, element_size: float
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, int]]:
    """Points, simplices, region markers and their names of a mesh file (rank 0).

    Any format meshio reads. The cells are the file's triangles (``dim = 2``, which must lie
    in a plane ``z = const``) or tetrahedra (``dim = 3``); other cells are ignored (e.g. a
    gmsh file's boundary triangles), and points no cell uses are dropped. Markers come from
    the first of :data:`MARKER_KEYS` present (gmsh physical groups, medit references), else
    all 1; names come from the file's field data (gmsh ``$PhysicalNames``). For ``dim = 3``
    a file of triangles only, such as an STL, OBJ or PLY surface, is
    taken as a closed surface and filled with tetrahedra of edge ``element_size``
    (:func:`check_surface`, :func:`fem_anim.meshes.build_volume_from_surface`).

    Raises:
        MeshError: naming the file, if it is missing, unreadable or has no usable cells.
    """
    import meshio

    source = f"mesh file {path}"
    if not path.is_file():
        raise MeshError(f"{source} does not exist")
    chatter = io.StringIO()  # meshio prints warnings, and errors before sys.exit(1)
    try:
        with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
            m = meshio.read(path)
    except SystemExit:  # meshio's end when no reader for the extension accepts the file
        detail = " ".join(chatter.getvalue().replace("Error:", "").split())
        raise MeshError(f"{source} cannot be read: {detail or 'meshio gave up'}") from None
    except Exception as err:  # noqa: BLE001 (meshio raises many types for malformed files)
        detail = " ".join(str(err).split()) or type(err).__name__
        raise MeshError(f"{source} cannot be read: {detail}") from None
    points = np.asarray(m.points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] not in (2, 3):
        raise MeshError(f"{source}: points must have 2 or 3 coordinates, got shape "
                        f"{points.shape}")
    found = sorted({b.type for b in m.cells}) or ["none"]
    other = sorted({b.type for b in m.cells if _cell_dim(b.type) >= dim
                    and b.type not in MESHIO_TYPES[dim]})
    if other and any(b.type in MESHIO_TYPES[dim] for b in m.cells):
        counts = ", ".join(f"{sum(len(b.data) for b in m.cells if b.type == t)} {t}"
                           for t in other)
        raise MeshError(f"{source} mixes cell types: besides its {CELL_NAMES[dim]} cells it "
                        f"has {counts} cells, which fem_anim cannot simulate (split them into "
                        f"{PLURAL[dim]} in the mesh tool)")
    take = [k for k, b in enumerate(m.cells) if b.type in MESHIO_TYPES[dim]]
    surface = [b.data[:, :3] for b in m.cells if b.type in MESHIO_TYPES[2]]
    if not take and dim == 3 and surface:
        points, triangles = _compact(points, np.concatenate(surface).astype(np.int64))
        if points.shape[1] != 3 or np.ptp(points[:, 2]) == 0.0:
            raise MeshError(f"{source} is a plane triangle mesh without tetrahedra; set "
                            "mesh.dim = 2 for it (a surface to fill must be closed)")
        return _fill_surface(points, triangles, element_size, source)
    if not take:
        raise MeshError(f"{source} has no {CELL_NAMES[dim]} cells for mesh.dim = {dim} (cell "
                        f"types found: {', '.join(found)})")
    cells = np.concatenate([m.cells[k].data[:, :dim + 1] for k in take]).astype(np.int64)
    markers = np.ones(cells.shape[0], dtype=np.int32)
    for key in MARKER_KEYS:
        if key in m.cell_data:
            markers = np.concatenate([np.asarray(m.cell_data[key][k]).reshape(-1)
                                      for k in take]).astype(np.int32)
            break
    if dim == 2 and points.shape[1] == 3:
        z = points[np.unique(cells[(cells >= 0) & (cells < len(points))]), 2]
        if z.size and np.ptp(z) > 1e-12 * max(np.ptp(points[:, :2], axis=0).max(), 1e-300):
            raise MeshError(f"{source}: its triangles do not lie in a plane z = const, as "
                            "mesh.dim = 2 needs (for a closed surface use mesh.dim = 3)")
    points, cells = _compact(points[:, :dim], cells)
    names = {name: int(value[0]) for name, value in m.field_data.items()
             if len(value) >= 2 and int(value[1]) == dim}
    return points, cells, markers, names


def _cell_dim(cell_type: str) -> int:
    """Topological dimension of a meshio cell type (0 for a type not known here)."""
    for dim, prefixes in ((3, ("tetra", "hexahedron", "wedge", "pyramid")),
                          (2, ("triangle", "quad", "polygon")), (1, ("line",))):
        if cell_type.startswith(prefixes):
            return dim
    return 0


def mesh_arrays(cfg: dict, base_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict,
                                                     str]:
    """Vertices, simplices, cell markers, their names and a description of one ``[mesh]``
    table (rank 0): a mesh file (relative to ``base_dir``), a structured box
    (``divisions``: :func:`fem_anim.meshes.structured.structured_box`) or a gmsh builder.

    Raises:
        MeshError: if the mesh cannot be read or made.
    """
    if cfg["shape"] == "file":
        path = Path(cfg["file"])
        path = path if path.is_absolute() else base_dir / path
        return (*read_mesh_file(path, cfg["dim"], cfg["element_size"]), f"mesh file {path}")
    if cfg["shape"] == "box" and cfg.get("divisions") is not None:
        points, cells = structured_box(cfg["size"], cfg["divisions"], cfg["origin"])
        return (points, cells, np.ones(len(cells), np.int32), {"body": 1},
                f"mesh (structured box {cfg['divisions']})")
    return (*_build_gmsh(cfg), f"mesh ({cfg['shape']})")


def build_mesh(comm: MPI.Comm, scene) -> SimplexMesh:
    """Build the scene's mesh on rank 0 and distribute it (collective).

    Raises:
        MeshError: on every rank if the mesh cannot be made or fails :func:`check_cells`.
    """
    cfg = scene["mesh"]
    d = cfg["dim"]
    points = np.empty((0, d))
    cells = np.empty((0, d + 1), np.int64)
    markers = np.empty(0, np.int32)
    names: dict[str, int] = {}
    source = f"mesh ({cfg['shape']})"
    error = None
    if comm.rank == 0:
        try:
            points, cells, markers, names, source = mesh_arrays(cfg, scene.base_dir)
        except MeshError as err:
            error = str(err)
    error = comm.bcast(error, root=0)
    if error:
        raise MeshError(error)
    return mesh_from_arrays(comm, points, cells, markers, source, names, one_body=True)
