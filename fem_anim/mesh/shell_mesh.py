"""A shell's mid-surface as a distributed DOLFINx mesh: triangles in 3D (gdim 3, tdim 2).

:func:`build_shell_mesh` makes the triangles on rank 0 from the scene's ``[mesh]`` (the
gmsh sheet of :mod:`fem_anim.meshes.sheet`, or a surface file meshio reads), checks
them (:func:`check_shell_surface`: no degenerate triangle, no edge shared by more than two
triangles, no unmerged duplicate vertex; several pieces are layers of one shell, which meet
through its self contact; orientation is not needed: the bending energy orients the
two triangles of each edge by their rest normals, :mod:`fem_anim.problem.shell_terms`) and
distributes them with the manifold coordinate element of :func:`fem_anim.compat.create_mesh`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim import compat
from fem_anim.errors import MeshError
from fem_anim.mesh.checks import FLAT
from fem_anim.mesh.connectivity import check_one_body
from fem_anim.mesh.gmsh_session import gmsh_arrays, gmsh_session
from fem_anim.mesh.simplex import SimplexMesh

__all__ = ["build_shell_mesh", "check_shell_surface", "shell_arrays"]


def check_shell_surface(points: np.ndarray, triangles: np.ndarray, source: str) -> None:
    """Reject a surface a shell cannot be: degenerate, non-manifold or unmerged (several
    connected pieces are accepted: layers of cloth of one material).

    Args:
        points: ``(n, 3)`` vertex coordinates.
        triangles: ``(m, 3)`` vertex indices.
        source: What the surface is, for the message.

    Raises:
        MeshError: naming the first defect (a triangle, an edge or the pieces).
    """
    if triangles.ndim != 2 or triangles.shape[1] != 3 or len(triangles) == 0:
        raise MeshError(f"{source}: a shell needs triangles, got cells of shape "
                        f"{triangles.shape}")
    if points.ndim != 2 or points.shape[1] != 3 or not np.all(np.isfinite(points)):
        raise MeshError(f"{source}: a shell needs finite 3D points, got shape {points.shape}")
    if triangles.min() < 0 or triangles.max() >= len(points):
        raise MeshError(f"{source}: a triangle's vertex index is out of range")
    X = points[triangles]
    area2 = np.linalg.norm(np.cross(X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]), axis=1)
    h = np.max(np.linalg.norm(X - X[:, [1, 2, 0]], axis=2), axis=1)
    if np.any(area2 <= FLAT * h**2):
        t = int(np.argmax(area2 <= FLAT * h**2))
        raise MeshError(f"{source}: triangle {t} (vertices {triangles[t].tolist()}) has zero "
                        "area")
    half = triangles[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)  # directed edges
    key = np.sort(half, axis=1)
    unique, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    if np.any(counts > 2):
        a, b = unique[int(np.argmax(counts > 2))]
        raise MeshError(f"{source}: non-manifold surface: the edge from vertex {a} to vertex "
                        f"{b} belongs to {counts.max()} triangles (a shell's edges have one "
                        "or two)")
    check_one_body(points, triangles, source, several_pieces=True)


def shell_arrays(cfg: dict, base_dir: Path) -> tuple[np.ndarray, np.ndarray, str]:
    """The surface of one ``[mesh]`` table (rank 0): a sheet, or a surface file.

    Args:
        cfg: The validated ``[mesh]`` table of a shell scene.
        base_dir: The scene file's folder, against which a relative ``file`` is resolved.

    Returns:
        ``(points (n, 3), triangles (m, 3), description)``.

    Raises:
        MeshError: if the file cannot be read or holds no triangles.
    """
    if cfg["shape"] == "sheet":  # gmsh's structured sheet in the plane z = origin_z
        from fem_anim.meshes import BUILDERS

        source = "mesh (sheet)"
        with gmsh_session(source, "is mesh.element_size too large for the sheet?") as model:
            try:
                model = BUILDERS["sheet"](model, cfg)
            except ValueError as err:
                raise MeshError(f"{source}: {err}") from None
            points, cells, _, _ = gmsh_arrays(model, 2)
        z = 0.0 if cfg["origin"] is None else float(cfg["origin"][2])
        return np.column_stack([points, np.full(len(points), z)]), cells, source
    import meshio

    path = Path(cfg["file"])
    path = path if path.is_absolute() else base_dir / path
    source = f"mesh file {path}"
    try:
        data = meshio.read(path)
    except Exception as err:  # meshio raises many types for unreadable files
        raise MeshError(f"{source}: cannot read it: {' '.join(str(err).split())}") from None
    triangles = [block.data for block in data.cells if block.type == "triangle"]
    if not triangles:
        raise MeshError(f"{source}: holds no triangles for a shell")
    points = np.asarray(data.points, float)
    if points.shape[1] == 2:
        points = np.column_stack([points, np.zeros(len(points))])
    cells = np.concatenate(triangles).astype(np.int64)
    used = np.unique(cells)
    remap = np.full(len(points), -1, np.int64)
    remap[used] = np.arange(used.size)
    return points[used], remap[cells], source


def build_shell_mesh(comm: MPI.Comm, scene) -> SimplexMesh:
    """Build the shell scene's surface on rank 0, check it and distribute it (collective).

    Args:
        comm: The communicator of the run.
        scene: The validated scene (its ``[mesh]`` table and ``base_dir``).

    Returns:
        The distributed surface mesh (gdim 3, tdim 2); rank 0 keeps the input arrays.

    Raises:
        MeshError: on every rank if the surface cannot be made or fails the checks.
    """
    points, cells = np.empty((0, 3)), np.empty((0, 3), np.int64)
    error = None
    if comm.rank == 0:
        try:
            points, cells, source = shell_arrays(scene["mesh"], scene.base_dir)
            check_shell_surface(points, cells, source)
        except MeshError as err:
            error = str(err)
    error = comm.bcast(error, root=0)
    if error:
        raise MeshError(error)
    mesh = compat.create_mesh(comm, cells, points, 3, "triangle", interior_facets=True)
    input_index = np.asarray(mesh.geometry.input_global_indices, dtype=np.int64)
    return SimplexMesh(mesh, points, cells, np.ones(len(cells), np.int32), input_index,
                       {"body": 1})
