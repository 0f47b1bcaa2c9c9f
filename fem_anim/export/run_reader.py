"""What an export needs from a run directory, read without DOLFINx.

A run directory (:mod:`fem_anim.output.rundir`) holds ``trajectory.h5`` (rest points,
cells, each frame's vertex displacements and cell energy densities, the cells' body
numbers and, for a P2 body, every dof of its displacement: ``displacement_nodes`` and
``displacement_dofs{k}``, :mod:`fem_anim.output.trajectory`) and ``scene.json`` (the
validated scene: its name, bodies, obstacles, gravity).
:func:`read_run` gathers them into a :class:`RunData`; the exporters take that and nothing
else, so a finished run and a run's staging area (read before it is installed) export
the same way.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError
from fem_anim.export.boundary import BodySurface, body_surfaces, refine_p2

__all__ = ["RunData", "read_run"]


@dataclass
class RunData:
    """A run's frames and what the exporters need to name and place them.

    Attributes:
        name: The scene's name.
        points: Rest positions ``(v, 3)`` (m; 2D runs have z = 0).
        cells: The cells ``(m, d + 1)``.
        body: The body number of each cell ``(m,)``.
        body_names: The name of each body (a one-body scene: the scene's name).
        times: The time of each frame (s).
        dim: The scene's dimension, 2 or 3.
        gravity: The gravity vector (zero when the scene has none), ``(dim,)``.
        obstacles: The scene's ``[[obstacle]]`` tables.
        path: The folder the run was read from.
        nodes: The ``(i, j)`` vertex pair of each row of the displacement's dofs when the
            trajectory holds them with edge rows (a P2 body), else None.
    """

    name: str
    points: np.ndarray
    cells: np.ndarray
    body: np.ndarray
    body_names: list[str]
    times: np.ndarray
    dim: int
    gravity: np.ndarray
    obstacles: list[dict] = field(default_factory=list)
    path: Path | None = None
    nodes: np.ndarray | None = None

    def displacement(self, frame: int) -> np.ndarray:
        """Vertex displacements of one frame ``(v, 3)`` (m)."""
        return self._dataset(f"data{frame + 2}")

    def positions(self, frame: int) -> np.ndarray:
        """Vertex positions of one frame ``(v, 3)`` (m): rest points plus displacement."""
        return self.points + self.displacement(frame)

    def energy_density(self, frame: int) -> np.ndarray:
        """Each cell's mean energy density of one frame ``(m,)`` (J/m^3)."""
        return self._dataset(f"energy_density{frame}")

    def surfaces(self) -> list[BodySurface]:
        """Each body's outward boundary surface (:mod:`fem_anim.export.boundary`); for a P2
        body refined through its edge dofs (:func:`~fem_anim.export.boundary.refine_p2`),
        its ``vertices`` then rows of :meth:`surface_points`."""
        surfaces = body_surfaces(self.points, self.cells, self.body)
        if self.nodes is None:
            return surfaces
        return refine_p2(surfaces, self.nodes, self.points.shape[0])

    def surface_points(self) -> np.ndarray:
        """Rest positions of the rows :meth:`surfaces` numbers ``(n, 3)`` (m): the
        vertices, and for a P2 body also its edge midpoints."""
        if self.nodes is None:
            return self.points
        return 0.5 * (self.points[self.nodes[:, 0]] + self.points[self.nodes[:, 1]])

    def surface_displacement(self, frame: int) -> np.ndarray:
        """The displacement at :meth:`surface_points` of one frame ``(n, 3)`` (m): the P2
        field's dof values where the trajectory holds them."""
        if self.nodes is None:
            return self.displacement(frame)
        u = self._dataset(f"displacement_dofs{frame}")
        return np.hstack([u, np.zeros((u.shape[0], 3 - u.shape[1]))])

    def _dataset(self, name: str) -> np.ndarray:
        import h5py

        with h5py.File(self.path / "trajectory.h5", "r") as h5:
            return np.asarray(h5[name], dtype=float)


def read_run(path: Path) -> RunData:
    """Read a run directory (or its staging area) for export.

    Runs written before the cells carried their body number get it from the mesh's
    connected parts, which are the ``[[body]]`` bodies in order (each body is one piece).

    Args:
        path: The folder holding ``trajectory.h5`` and ``scene.json``.

    Returns:
        The run's data; frames are read when asked for.

    Raises:
        FemAnimError: naming the file that is missing or unreadable.
    """
    import h5py

    from fem_anim.mesh.connectivity import cell_components

    path = Path(path)
    for name in ("trajectory.h5", "scene.json"):
        if not (path / name).is_file():
            raise FemAnimError(f"{path} is not a finished fem-anim run: no {name} in it")
    try:
        scene = json.loads((path / "scene.json").read_text())["scene"]
        with h5py.File(path / "trajectory.h5", "r") as h5:
            points = np.asarray(h5["data0"], dtype=float)
            cells = np.asarray(h5["data1"], dtype=np.int64)
            times = np.asarray(h5.attrs["times"], dtype=float)
            body = np.asarray(h5["body"], dtype=np.int64) if "body" in h5 else \
                cell_components(cells, points.shape[0]).astype(np.int64)
            nodes = np.asarray(h5["displacement_nodes"], dtype=np.int64) \
                if "displacement_nodes" in h5 else None
    except (OSError, ValueError, KeyError, TypeError) as err:
        raise FemAnimError(f"the run in {path} cannot be read: {err}") from None
    bodies = scene.get("body") or []
    names = [b["name"] for b in bodies] if bodies else [scene.get("name", "body")]
    dim = cells.shape[1] - 1
    gravity = np.asarray((scene.get("gravity") or {}).get("acceleration") or np.zeros(dim),
                         dtype=float)
    if int(body.max()) + 1 != len(names):
        raise FemAnimError(f"the run in {path} has {int(body.max()) + 1} bodies in its mesh "
                           f"but {len(names)} in its scene")
    if nodes is not None and np.all(nodes[:, 0] == nodes[:, 1]):
        nodes = None  # vertex dofs only (P1): the vertex displacement is all of it
    return RunData(scene.get("name", "scene"), points, cells, body, names, times, dim,
                   gravity, list(scene.get("obstacle") or []), path, nodes)
