"""From a scene's ``[mesh]`` table to a distributed DOLFINx mesh: :func:`build_mesh`.

The mesh is made on rank 0, by a gmsh builder of :mod:`fem_anim.meshes`
(:func:`fem_anim.mesh.gmsh_session.gmsh_session`), as a structured box, or read from a file
(:func:`fem_anim.mesh.mesh_file.read_mesh_file`); it is then checked and distributed
(:func:`fem_anim.mesh.simplex.mesh_from_arrays`). A shell scene's surface is made by
:func:`fem_anim.mesh.shell_mesh.build_shell_mesh`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim.errors import MeshError
from fem_anim.mesh.gmsh_session import gmsh_arrays, gmsh_session
from fem_anim.mesh.mesh_file import read_mesh_file
from fem_anim.mesh.shell_mesh import build_shell_mesh
from fem_anim.mesh.simplex import SimplexMesh, mesh_from_arrays
from fem_anim.meshes.structured import structured_box
from fem_anim.scene.schema import LENGTH_UNITS

__all__ = ["build_mesh", "mesh_arrays"]


def _build_gmsh(cfg: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Mesh ``cfg["shape"]`` with its builder of :data:`fem_anim.meshes.BUILDERS` (rank 0).

    Raises:
        MeshError: if the builder refuses the table or gmsh fails.
    """
    from fem_anim.meshes import BUILDERS

    source = f"mesh ({cfg['shape']})"
    hint = f"is mesh.element_size = {cfg['element_size']} too large for the shape?"
    with gmsh_session(source, hint) as model:
        try:
            model = BUILDERS[cfg["shape"]](model, cfg)
        except ValueError as err:
            raise MeshError(f"{source}: {err}") from None
        return gmsh_arrays(model, cfg["dim"])


def mesh_arrays(cfg: dict, base_dir: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict,
                                                     str]:
    """The arrays of one ``[mesh]`` table, made on the calling rank (rank 0).

    A mesh file (relative to ``base_dir``), a structured box (``divisions``:
    :func:`fem_anim.meshes.structured.structured_box`) or a gmsh builder.

    Args:
        cfg: The validated ``[mesh]`` table.
        base_dir: The scene file's folder, against which a relative ``file`` is resolved.

    Returns:
        ``(points, cells, markers, marker names, description)``; the description names
        the mesh in error messages.

    Raises:
        MeshError: if the mesh cannot be read or made.
    """
    if cfg["shape"] == "file":
        path = Path(cfg["file"])
        path = path if path.is_absolute() else base_dir / path
        scale = LENGTH_UNITS[cfg.get("units", "m")] * cfg.get("scale", 1.0)
        return (*read_mesh_file(path, cfg["dim"], cfg["element_size"], scale,
                                cfg.get("fill", "auto")), f"mesh file {path}")
    if cfg["shape"] == "box" and cfg.get("divisions") is not None:
        points, cells = structured_box(cfg["size"], cfg["divisions"], cfg["origin"])
        return (points, cells, np.ones(len(cells), np.int32), {"body": 1},
                f"mesh (structured box {cfg['divisions']})")
    return (*_build_gmsh(cfg), f"mesh ({cfg['shape']})")


def build_mesh(comm: MPI.Comm, scene) -> SimplexMesh:
    """Build the scene's mesh on rank 0 and distribute it (collective).

    Args:
        comm: The communicator of the run.
        scene: The validated scene (its ``[mesh]`` table and ``base_dir``).

    Returns:
        The distributed mesh; it is one connected body
        (:func:`fem_anim.mesh.connectivity.check_one_body`).

    Raises:
        MeshError: on every rank if the mesh cannot be made or fails :func:`check_cells`.
    """
    if "shell" in scene.data:  # a surface in 3D (fem_anim.mesh.shell_mesh)
        return build_shell_mesh(comm, scene)
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
