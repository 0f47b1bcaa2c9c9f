"""Reading a mesh file: any format meshio reads (glTF/GLB through trimesh), a surface filled
with tetrahedra.

:func:`read_mesh_file` gives the points, simplices, region markers and marker names of a
file (rank 0), its coordinates scaled to metres; a file holding only a triangulated surface
(STL, OBJ, PLY, glTF, GLB) in 3D is filled with tetrahedra: by gmsh when it is closed and
clean (:func:`fem_anim.meshes.build_volume_from_surface`), else by fTetWild, which repairs
holes, duplicated faces and overlapping shells
(:func:`fem_anim.mesh.surface_repair.repair_surface_to_tets`).
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path

import numpy as np

from fem_anim.errors import MeshError
from fem_anim.mesh.checks import check_surface
from fem_anim.mesh.gmsh_session import gmsh_arrays, gmsh_session
from fem_anim.mesh.simplex import CELL_NAMES, drop_unused_points
from fem_anim.mesh.surface_repair import repair_surface_to_tets

__all__ = ["MARKER_KEYS", "MESHIO_TYPES", "TRIMESH_SUFFIXES", "read_mesh_file"]

PLURAL = {2: "triangles", 3: "tetrahedra"}
#: meshio cell types read as simplices of each dimension (higher-order ones by their corners).
MESHIO_TYPES = {2: ("triangle", "triangle6", "triangle7"), 3: ("tetra", "tetra10")}
#: Integer cell data taken as region markers, first found wins.
MARKER_KEYS = ("gmsh:physical", "medit:ref", "cell_markers", "CellEntityIds")
#: Surface formats meshio does not read, read by trimesh (all meshes of the file, placed).
TRIMESH_SUFFIXES = (".gltf", ".glb")


def _fill_surface(points: np.ndarray, triangles: np.ndarray, element_size: float,
                  source: str, fill: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Tetrahedralise the solid a surface bounds.

    ``fill = "gmsh"``: the surface must pass :func:`check_surface` and gmsh fills it;
    ``"tetwild"``: fTetWild repairs and fills it; ``"auto"``: gmsh, and fTetWild when the
    surface is not closed, manifold and connected or gmsh fails (self-intersections).

    Raises:
        MeshError: if the chosen mesher fails, or nothing usable is left of the surface.
    """
    from fem_anim.meshes import build_volume_from_surface

    # merge repeated vertices (an STL has no others), keeping the first occurrences' order
    _, first, inverse = np.unique(points, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    points, triangles = points[first[order]], rank[inverse.reshape(-1)][triangles]
    if fill != "tetwild":
        try:
            check_surface(points, triangles, source)
            with gmsh_session(source, "the surface must not intersect itself") as model:
                model = build_volume_from_surface(model, points, triangles, element_size)
                filled, cells, markers, names = gmsh_arrays(model, 3)
            if cells.shape[0] == 0:
                raise MeshError(f"{source}: gmsh made no tetrahedra inside the surface")
            return filled, cells, markers, names
        except MeshError as err:
            if fill == "gmsh":
                raise MeshError(f"{err} (mesh.fill = \"tetwild\" repairs such surfaces)") \
                    from None
    filled, cells = repair_surface_to_tets(points, triangles, element_size, source)
    return filled, cells, np.ones(len(cells), np.int32), {}


def read_mesh_file(path: Path, dim: int, element_size: float, scale: float = 1.0,
                   fill: str = "auto"
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict[str, int]]:
    """Points, simplices, region markers and their names of a mesh file (rank 0).

    Any format meshio reads. The cells are the file's triangles (``dim = 2``, which must lie
    in a plane ``z = const``) or tetrahedra (``dim = 3``); other cells are ignored (e.g. a
    gmsh file's boundary triangles), and points no cell uses are dropped. Markers come from
    the first of :data:`MARKER_KEYS` present (gmsh physical groups, medit references), else
    all 1; names come from the file's field data (gmsh ``$PhysicalNames``). For ``dim = 3``
    a file of triangles only, such as an STL, OBJ, PLY, glTF or GLB surface, is filled with
    tetrahedra of edge ``element_size`` (:func:`_fill_surface`: gmsh for a closed clean
    surface, fTetWild for an open or self-intersecting one, as ``fill`` says).

    Args:
        path: The mesh file.
        dim: 2 or 3, the scene's ``mesh.dim``.
        element_size: Edge length of the tetrahedra filling a surface (m).
        scale: Metres per unit of the file's coordinates (``mesh.units`` times
            ``mesh.scale``); applied before a surface is filled.
        fill: ``mesh.fill``: ``"auto"``, ``"gmsh"`` or ``"tetwild"``.

    Returns:
        ``(points (n, dim), cells (m, dim + 1), markers (m,), names)``.

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
            m = _read_trimesh(path) if path.suffix.lower() in TRIMESH_SUFFIXES else \
                meshio.read(path)
    except SystemExit:  # meshio's end when no reader for the extension accepts the file
        detail = " ".join(chatter.getvalue().replace("Error:", "").split())
        raise MeshError(f"{source} cannot be read: {detail or 'meshio gave up'}") from None
    except Exception as err:  # noqa: BLE001 (meshio raises many types for malformed files)
        detail = " ".join(str(err).split()) or type(err).__name__
        raise MeshError(f"{source} cannot be read: {detail}") from None
    points = np.asarray(m.points, dtype=np.float64) * scale
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
        points, triangles = drop_unused_points(points, np.concatenate(surface).astype(np.int64))
        if points.shape[1] != 3 or np.ptp(points[:, 2]) == 0.0:
            raise MeshError(f"{source} is a plane triangle mesh without tetrahedra; set "
                            "mesh.dim = 2 for it (a surface to fill must be closed)")
        return _fill_surface(points, triangles, element_size, source, fill)
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
    points, cells = drop_unused_points(points[:, :dim], cells)
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


def _read_trimesh(path: Path):
    """A glTF/GLB file as a meshio mesh of triangles: every mesh of its scene, placed by the
    scene's transforms, concatenated (trimesh)."""
    import meshio
    import trimesh

    mesh = trimesh.load(str(path), force="mesh", process=False)
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError("no triangles in the file")
    return meshio.Mesh(np.asarray(mesh.vertices), [("triangle", np.asarray(mesh.faces))])
