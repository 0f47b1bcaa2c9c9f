"""From a scene's ``[mesh]`` to a distributed DOLFINx mesh (STYLE rule 3).

The mesh is made on rank 0 (gmsh builder or meshio file), checked there, and
distributed with one collective call. Rank 0 keeps the input points and cells: output
is written in that ordering, so serial and parallel runs write identical files, and the
hand-assembled reference (:mod:`fem_anim.reference`) can be compared vertex by vertex.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from . import compat
from .errors import MeshError

__all__ = ["SimplexMesh", "build_mesh", "mesh_from_arrays", "check_cells"]

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
    """

    mesh: object
    points: np.ndarray
    cells: np.ndarray
    cell_markers: np.ndarray
    input_index: np.ndarray

    @property
    def dim(self) -> int:
        return self.mesh.topology.dim

    @property
    def num_vertices_global(self) -> int:
        return self.mesh.geometry.index_map().size_global


def check_cells(points: np.ndarray, cells: np.ndarray, source: str) -> None:
    """Reject meshes with no cells, bad indices, or inverted or zero-volume cells.

    Raises:
        MeshError: naming the first offending cell and its signed measure.
    """
    if cells.shape[0] == 0:
        raise MeshError(f"{source}: the mesh has no cells")
    if cells.min() < 0 or cells.max() >= points.shape[0]:
        raise MeshError(f"{source}: cell vertex indices out of range 0..{points.shape[0] - 1}")
    if not np.all(np.isfinite(points)):
        raise MeshError(f"{source}: vertex coordinates contain NaN or inf")
    d = points.shape[1]
    Dm = (points[cells[:, :d]] - points[cells[:, d:d + 1]]).transpose(0, 2, 1)
    measure = np.linalg.det(Dm)
    scale = np.max(np.ptp(points, axis=0)) ** d
    tiny = np.abs(measure) <= 1e-14 * scale
    if np.any(tiny):
        c = int(np.argmax(tiny))
        raise MeshError(f"{source}: cell {c} has zero volume ({measure[c]:.3g})")
    if np.any(measure > 0) and np.any(measure < 0):
        sign = np.sign(np.median(measure))
        c = int(np.argmax(np.sign(measure) != sign))
        raise MeshError(f"{source}: cell {c} is inverted (signed volume {measure[c]:.3g} "
                        "against the orientation of the others)")
    _, first, counts = np.unique(np.sort(cells, axis=1), axis=0, return_index=True,
                                 return_counts=True)
    if np.any(counts > 1):
        raise MeshError(f"{source}: cell {int(first[counts > 1][0])} is duplicated")


def mesh_from_arrays(comm: MPI.Comm, points: np.ndarray, cells: np.ndarray,
                     cell_markers: np.ndarray | None, source: str) -> SimplexMesh:
    """Check and distribute a mesh given on rank 0 (collective).

    Other ranks pass empty arrays of the right width. The check runs on rank 0 and its
    verdict is broadcast, so a bad mesh raises the same :class:`MeshError` on all ranks.
    """
    error = None
    if comm.rank == 0:
        try:
            check_cells(points, cells, source)
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
    return SimplexMesh(mesh, points, cells, cell_markers.astype(np.int32), input_index)


def _gmsh_arrays(model, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices, simplices and physical-group markers of a meshed gmsh model."""
    tags, coords, _ = model.mesh.getNodes()
    points = coords.reshape(-1, 3)[:, :dim]
    index = np.empty(int(tags.max()) + 1, dtype=np.int64)  # gmsh node tag -> row of points
    index[tags] = np.arange(tags.size)
    etype = {2: 2, 3: 4}[dim]  # gmsh: 3-node triangle, 4-node tetrahedron
    cells_list, markers_list = [], []
    for _, group in model.getPhysicalGroups(dim):
        for entity in model.getEntitiesForPhysicalGroup(dim, group):
            types, _, nodes = model.mesh.getElements(dim, entity)
            for t, n in zip(types, nodes):
                if t == etype:
                    cells_list.append(index[np.asarray(n, dtype=np.int64)].reshape(-1, dim + 1))
                    markers_list.append(np.full(cells_list[-1].shape[0], group, np.int32))
    if not cells_list:
        return points, np.empty((0, dim + 1), np.int64), np.empty(0, np.int32)
    cells = np.concatenate(cells_list)
    used = np.unique(cells)
    remap = np.full(points.shape[0], -1, dtype=np.int64)
    remap[used] = np.arange(used.size)
    return points[used], remap[cells], np.concatenate(markers_list)


def _build_gmsh(mesh_cfg: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import gmsh

    from fem_anim.meshes import BUILDERS

    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        model = BUILDERS[mesh_cfg["shape"]](gmsh.model, size=mesh_cfg["size"],
                                            element_size=mesh_cfg["element_size"],
                                            origin=mesh_cfg["origin"])
        return _gmsh_arrays(model, len(mesh_cfg["size"]))
    finally:
        gmsh.finalize()


def _read_file(path: Path, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import meshio

    if not path.is_file():
        raise MeshError(f"mesh file {path} does not exist")
    try:
        m = meshio.read(path)
    except Exception as err:  # meshio raises many types for malformed files
        raise MeshError(f"mesh file {path} cannot be read: {err}") from None
    name = CELL_NAMES[dim]
    blocks = [b.data for b in m.cells if b.type == name]
    if not blocks:
        raise MeshError(f"mesh file {path} has no {name} cells (mesh.dim = {dim})")
    cells = np.concatenate(blocks).astype(np.int64)
    markers = None
    for key in ("gmsh:physical", "medit:ref", "cell_markers"):
        if key in m.cell_data:
            markers = np.concatenate([d for b, d in zip(m.cells, m.cell_data[key])
                                      if b.type == name]).astype(np.int32)
            break
    points = np.asarray(m.points, dtype=np.float64)[:, :dim]
    if markers is None:
        markers = np.ones(cells.shape[0], dtype=np.int32)
    return points, cells, markers


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
    source = f"mesh ({cfg['shape']})"
    error = None
    if comm.rank == 0:
        try:
            if cfg["shape"] == "file":
                path = Path(cfg["file"])
                path = path if path.is_absolute() else scene.base_dir / path
                source = f"mesh file {path}"
                points, cells, markers = _read_file(path, d)
            else:
                points, cells, markers = _build_gmsh(cfg)
        except MeshError as err:
            error = str(err)
    error = comm.bcast(error, root=0)
    if error:
        raise MeshError(error)
    return mesh_from_arrays(comm, points, cells, markers, source)
