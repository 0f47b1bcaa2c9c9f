"""What an export needs from a run directory, read without DOLFINx.

A run directory (:mod:`fem_anim.output.rundir`) holds ``trajectory.h5`` (rest points,
cells, each frame's vertex displacements and cell energy densities, the cells' body
numbers and, for a P2 body, every dof of its displacement: ``displacement_nodes`` and
``displacement_dofs{k}``, :mod:`fem_anim.output.trajectory`) and ``scene.json`` (the
validated scene: its name, bodies, obstacles, gravity).
:func:`read_run` gathers them into a :class:`RunData`; the exporters take that and nothing
else, so a finished run and a run's staging area (read before it is installed) export
the same way.

Three kinds of run are read:

* solids (tetrahedra) and 2D runs (triangles in z = 0): each body's surface is its boundary
  (:func:`~fem_anim.export.boundary.boundary_faces`);
* a shell run (``[shell]``: the triangles of a mid-surface in 3D, docs/cloth.md; P1 with the
  hinge, P2 with the Kirchhoff-Love bending, whose trajectory holds the P2 dofs): the
  surface is the triangles themselves (``sheet``), refined through the edge dofs for P2;
* a shell beside solids (:mod:`fem_anim.simulation.joint_run`; one minimisation per step,
  seed eq. 4): its ``trajectory.h5`` is already one triangle surface, the solids' boundary
  triangles and the shell's triangles on all vertices of both meshes (solids first). Its
  triangles are read as a sheet, each body's from its part: the solids' triangles wound
  outward from ``solids.h5``'s tetrahedra (the seen surface stores them with sorted
  vertices), numbered by the solid body of the tetrahedron behind each, the shell's as its
  mesh winds them. The energy density of a face is then the seen surface's own (the solid's
  tetrahedron under it, J/m^3, or the shell's triangle, J/m^2).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError
from fem_anim.export.boundary import BodySurface, body_surfaces, boundary_faces, refine_p2

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
        sheet: The cells are triangles of surfaces in 3D, each its own face (a shell run, or
            the seen surface of a shell beside solids).
        shells: The numbers of the bodies that are shells (two-sided, energy density per
            area, J/m^2).
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
    sheet: bool = False
    shells: frozenset[int] = frozenset()

    def energy_unit(self, body: int) -> str:
        """The unit of a body's energy density: J/m^2 for a shell (per mid-surface area),
        J/m^3 for a solid (a 2D run's too: per unit of depth)."""
        return "J/m^2" if body in self.shells else "J/m^3"

    def displacement(self, frame: int) -> np.ndarray:
        """Vertex displacements of one frame ``(v, 3)`` (m)."""
        return self._dataset(f"data{frame + 2}")

    def positions(self, frame: int) -> np.ndarray:
        """Vertex positions of one frame ``(v, 3)`` (m): rest points plus displacement."""
        return self.points + self.displacement(frame)

    def energy_density(self, frame: int) -> np.ndarray:
        """Each cell's mean energy density of one frame ``(m,)`` (:meth:`energy_unit`)."""
        return self._dataset(f"energy_density{frame}")

    def surfaces(self) -> list[BodySurface]:
        """Each body's outward boundary surface (:mod:`fem_anim.export.boundary`); for a P2
        body refined through its edge dofs (:func:`~fem_anim.export.boundary.refine_p2`),
        its ``vertices`` then rows of :meth:`surface_points`."""
        surfaces = body_surfaces(self.points, self.cells, self.body, self.sheet)
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

        file = self.path / "trajectory.h5"
        try:
            with h5py.File(file, "r") as h5:
                return np.asarray(h5[name], dtype=float)
        except (OSError, KeyError, ValueError, TypeError) as err:
            raise FemAnimError(f"{file}: cannot read {name}: {err}") from None


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
    shells = frozenset(k for k, b in enumerate(bodies) if b.get("shell"))
    if not bodies and scene.get("shell"):
        shells = frozenset({0})
    if cells.ndim != 2 or cells.shape[1] not in (3, 4) or points.ndim != 2:
        raise FemAnimError(f"the run in {path} cannot be exported: its mesh has cells of "
                           f"{cells.shape[-1]} vertices (triangles or tetrahedra only)")
    sheet = bool(shells) and cells.shape[1] == 3
    dim = 3 if sheet else cells.shape[1] - 1
    if shells and bodies and len(shells) < len(bodies):  # a shell beside solids
        cells, body = _joint_surface(path, points, cells, len(bodies), shells)
    gravity = np.asarray((scene.get("gravity") or {}).get("acceleration") or np.zeros(dim),
                         dtype=float)
    if body.size == 0 or int(body.max()) + 1 != len(names):
        raise FemAnimError(f"the run in {path} has {int(body.max()) + 1 if body.size else 0} "
                           f"bodies in its mesh but {len(names)} in its scene")
    if nodes is not None and np.all(nodes[:, 0] == nodes[:, 1]):
        nodes = None  # vertex dofs only (P1): the vertex displacement is all of it
    return RunData(scene.get("name", "scene"), points, cells, body, names, times, dim,
                   gravity, list(scene.get("obstacle") or []), path, nodes, sheet, shells)


def _joint_surface(path: Path, points: np.ndarray, triangles: np.ndarray, num_bodies: int,
                   shells: frozenset[int]) -> tuple[np.ndarray, np.ndarray]:
    """The seen surface of a shell beside solids, each triangle wound as its body wants it
    and numbered by its ``[[body]]``.

    Args:
        path: The run directory (``solids.h5`` is read from it).
        points: The seen surface's points (the solids' vertices, then the shell's).
        triangles: Its triangles (the solids' boundary triangles, then the shell's).
        num_bodies: The number of ``[[body]]`` tables.
        shells: The shell body's number (one).

    Returns:
        ``(triangles, body)``: the solids' triangles wound outward (as their tetrahedra
        give them, :func:`~fem_anim.export.boundary.boundary_faces`), the shell's as stored;
        and the ``[[body]]`` number of each (the solids' in the order of their tables).

    Raises:
        FemAnimError: ``solids.h5`` is missing or does not match the seen surface.
    """
    import h5py

    from fem_anim.mesh.connectivity import cell_components

    file = path / "solids.h5"
    try:
        with h5py.File(file, "r") as h5:
            solid_points = np.asarray(h5["data0"], dtype=float)
            tets = np.asarray(h5["data1"], dtype=np.int64)
            solid_body = np.asarray(h5["body"], dtype=np.int64) if "body" in h5 else \
                cell_components(tets, solid_points.shape[0]).astype(np.int64)
    except (OSError, KeyError, ValueError, TypeError) as err:
        raise FemAnimError(f"the shell-and-solids run in {path} cannot be read: {file}: "
                           f"{err}") from None
    ns = solid_points.shape[0]
    solid_numbers = [k for k in range(num_bodies) if k not in shells]
    if tets.ndim != 2 or tets.shape[1] != 4 or not np.array_equal(points[:ns], solid_points) \
            or int(solid_body.max()) + 1 != len(solid_numbers):
        raise FemAnimError(f"the shell-and-solids run in {path} cannot be read: {file} does "
                           f"not hold the solids of its trajectory.h5")
    faces, owner = boundary_faces(solid_points, tets)
    on_solid = np.all(triangles < ns, axis=1)
    key = np.sort(triangles[on_solid], axis=1)
    ours = np.sort(faces, axis=1)
    order = np.lexsort(ours.T[::-1])
    code = ours[order] @ np.array([ns * ns, ns, 1])
    found = np.minimum(np.searchsorted(code, key @ np.array([ns * ns, ns, 1])), len(code) - 1)
    match = order[found]
    if len(key) != len(faces) or not np.array_equal(np.sort(faces[match], axis=1), key):
        raise FemAnimError(f"the shell-and-solids run in {path} cannot be read: its seen "
                           f"surface is not the boundary of the tetrahedra in {file}")
    out, body = triangles.copy(), np.full(triangles.shape[0], min(shells), dtype=np.int64)
    out[on_solid] = faces[match]
    body[on_solid] = np.asarray(solid_numbers)[solid_body[owner[match]]]
    return out, body
