"""A gmsh session for meshing, and the arrays of a meshed gmsh model.

:func:`gmsh_session` initialises a quiet, single-threaded gmsh, turns its failures into
:class:`~fem_anim.errors.MeshError` and finalises it; :func:`gmsh_arrays` reads the simplices
of a model's physical groups with their markers and names. Builders
(:mod:`fem_anim.meshes`) take the model and return it; they never own the session.
"""

from __future__ import annotations

import contextlib
import signal
import threading

import numpy as np

from fem_anim.errors import MeshError
from fem_anim.mesh.simplex import drop_unused_points

__all__ = ["gmsh_arrays", "gmsh_session"]


@contextlib.contextmanager
def gmsh_session(source: str, hint: str):
    """An initialised, quiet, single-threaded gmsh model, finalised on exit.

    The SIGINT handler in force before is put back afterwards: gmsh sets SIGINT to the
    default action (4.8 when imported, 4.13 in ``initialize``) and 4.13's ``finalize`` does
    not restore it, so without this a Ctrl-C later in the run would kill the process instead
    of stopping it cleanly (:mod:`fem_anim.simulation.interrupt`).

    Args:
        source: What is being meshed, for the message (e.g. ``mesh (beam)``).
        hint: The likely cause of a gmsh failure, appended to the message.

    Yields:
        ``gmsh.model``, for a builder to fill and mesh.

    Raises:
        MeshError: when gmsh fails inside the block, naming ``source``, gmsh's own error
            and ``hint``. A :class:`MeshError` raised inside passes through unchanged.
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


def gmsh_arrays(model, dim: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """Vertices, simplices, physical-group markers and group names of a meshed gmsh model.

    Only the linear simplices of dimension ``dim`` that belong to a physical group are
    taken; points no such cell uses are dropped.

    Args:
        model: A meshed ``gmsh.model``.
        dim: 2 (triangles) or 3 (tetrahedra).

    Returns:
        ``(points (n, dim), cells (m, dim + 1), markers (m,), names)``, ``markers`` being
        each cell's physical group tag and ``names`` the named groups' name -> tag.
    """
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
    points, cells = drop_unused_points(points, np.concatenate(cells_list))
    return points, cells, np.concatenate(markers_list), names
