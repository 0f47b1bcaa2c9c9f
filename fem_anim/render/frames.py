"""Off-screen pictures with pyvista: the bodies' shaded surfaces, lit, framed by a camera.

Without a display, VTK's EGL render window is selected (no X server needed).
:class:`FrameRenderer` builds the scene graph once (the bodies' outward boundary surface,
:mod:`~fem_anim.render.outer_surface`; the obstacles as tiles and the lights,
:mod:`~fem_anim.render.scenery`; colour map, colour range, background and the frame
counter from the scene's ``[render]`` table) and renders frame after frame into it by
updating the surface's positions, normals and colours in place and moving the camera to
the frame's :class:`~fem_anim.render.camera.Shot`; obstacles that would stand between the
camera and the bodies are hidden in that frame, and the planes' tiles, drawn unlit, take the
colour the lights give them from that camera (:func:`~fem_anim.render.scenery.plane_shade`).
:func:`render_frame` and :func:`render_vtu` make one picture of one state.

Only the rendering process imports this module (:mod:`fem_anim.render.process`): the VTK
wheel's C++ runtime clashes with libraries DOLFINx loads.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from fem_anim.mesh.connectivity import cell_components
from fem_anim.render.camera import Shot, plan_shots
from fem_anim.render.render_defaults import resolve_settings
from fem_anim.render.scenery import OBSTACLE_AMBIENT, OBSTACLE_COLOR, OBSTACLE_DIFFUSE, \
    add_lights, obstacle_mesh, plane_shade, tile_plane, visible_obstacles
from fem_anim.render.outer_surface import outer_faces

__all__ = ["FrameRenderer", "FIELD_LABELS", "CREASE_ANGLE", "SCALAR_BAR_HEIGHT", "body_labels",
           "render_frame", "render_vtu", "scalar_bar_reserve", "stage_of"]

#: Scalar bar titles of the fields ``render.color_by`` names.
FIELD_LABELS = {"displacement": "displacement (m)", "energy_density": "psi (J/m^3)",
                "body": "body"}
#: Colours of the bodies (``color_by = "body"``), in order, repeated past ten.
BODY_COLORMAP = "tab10"
#: Dihedral angle (degrees) above which an edge is drawn sharp rather than smoothed over.
CREASE_ANGLE = 60.0
#: Narrower pictures have no scalar bar (its labels would cover the body).
MIN_SCALAR_BAR_WIDTH = 240
#: Share of the picture's height kept for the scalar bar, its labels and title, at the bottom.
SCALAR_BAR_HEIGHT = 0.2


def _pyvista():
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista

    pyvista.OFF_SCREEN = True
    return pyvista


def _pad3(a: np.ndarray) -> np.ndarray:
    return np.hstack([a, np.zeros((a.shape[0], 3 - a.shape[1]))]) if a.shape[1] < 3 else a


class FrameRenderer:
    """One off-screen plotter: the bodies' surface, whose positions and colours change.

    Args:
        points: Rest positions (n, 2 or 3).
        cells: Simplices (m, 3 or 4).
        settings: The ``[render]`` table, resolved
            (:func:`~fem_anim.render.render_defaults.resolve_settings`).
        clim: Fixed colour range (lo, hi) of the field.
        stage: The bodies' centre (3,) and largest extent (m) over the run: where the
            obstacles' tiles go and how large they are.
        obstacles: The scene's ``[[obstacle]]`` tables (drawn if ``settings["obstacles"]``).
        shaded_tiles: Draw the planes' tiles unlit in the colour the lights give them
            (:func:`~fem_anim.render.scenery.plane_shade`, set again whenever the camera
            moves): the same pixels as VTK's lighting at a fraction of the cost. Without
            shadows only (a shadow falls on a lit tile); ``False`` lets VTK light them.
    """

    def __init__(self, points: np.ndarray, cells: np.ndarray, settings: dict,
                 clim: tuple[float, float], stage: tuple[np.ndarray, float], obstacles=(),
                 shaded_tiles: bool = True):
        import matplotlib.colors

        pv = _pyvista()
        self.dim = points.shape[1]
        self.field = settings["color_by"]
        X = _pad3(points)
        self._rest = X
        faces, self._face_cell = outer_faces(points, cells)
        self._faces = faces
        self.surface = pv.PolyData(X.copy(), faces=np.hstack(
            [np.full((faces.shape[0], 1), 3), faces]).ravel())
        label = FIELD_LABELS[self.field]
        per_vertex = self.field == "displacement"
        data = self.surface.point_data if per_vertex else self.surface.cell_data
        data[label] = np.zeros(points.shape[0] if per_vertex else faces.shape[0])
        self.values = data[label]  # a view on the VTK array: updated in place per frame
        background = matplotlib.colors.to_rgb(settings["background"])
        ink = "black" if np.dot(background, (0.299, 0.587, 0.114)) > 0.5 else "white"
        width, height = settings["window_size"]
        self.plotter = plotter = pv.Plotter(off_screen=True, window_size=[width, height],
                                            lighting="none")
        plotter.disable_anti_aliasing()  # MSAA triples the cost of a software-rendered frame
        plotter.set_background(background)
        add_lights(pv, plotter)
        lo, hi = clim
        bodies = self.field == "body"
        if bodies:  # categorical: body k takes colour k of the palette
            lo, hi = -0.5, 9.5
        actor = plotter.add_mesh(
            _normals_filter(self.surface), scalars=label,
            cmap=BODY_COLORMAP if bodies else settings["colormap"],
            n_colors=10 if bodies else 256, clim=(lo, hi if hi > lo else lo + 1.0),
            show_scalar_bar=width >= MIN_SCALAR_BAR_WIDTH and not bodies,
            show_edges=settings["show_edges"], ambient=0.25, diffuse=0.8, specular=0.15,
            edge_color="#404040" if ink == "black" else "#a0a0a0",
            scalar_bar_args={"title": label, "color": ink, "vertical": False,
                             "position_x": 0.25, "position_y": 0.03, "width": 0.5,
                             "height": 0.1, "fmt": "%.2g", "n_labels": 3})
        actor.prop.interpolation = "gouraud"  # smooth: the normals of _normals_filter
        if settings["ghost"]:
            rest = pv.PolyData(X, faces=self.surface.faces)
            plotter.add_mesh(rest, style="wireframe", color="grey", opacity=0.25,
                             lighting=False)
        # a text actor at a pixel position: a corner annotation fits its font to the window
        # again whenever its text changes, which costs more than rendering the frame
        self.text = plotter.add_text(" ", position=(4, height - 4), font_size=8, color=ink)
        self.text.GetTextProperty().SetVerticalJustificationToTop()
        self.obstacles = list(obstacles) if settings["obstacles"] else []
        centre, size = stage
        self._obstacle_actors = [
            plotter.add_mesh(obstacle_mesh(pv, o, np.asarray(centre, float), size, self.dim),
                             color=OBSTACLE_COLOR, ambient=OBSTACLE_AMBIENT,
                             diffuse=OBSTACLE_DIFFUSE)
            for o in self.obstacles]
        shadows = settings["shadows"] and self.dim == 3
        self._tiles = [(actor.GetProperty(), *tile_plane(o, self.dim))
                       for actor, o in zip(self._obstacle_actors, self.obstacles)
                       if o["type"] == "plane" and shaded_tiles and not shadows]
        self._tile_color = np.array(matplotlib.colors.to_rgb(OBSTACLE_COLOR))
        for prop, _, _ in self._tiles:  # the colour, lit, comes in _shade_tiles
            prop.LightingOff()
            prop.SetAmbient(1.0)
            prop.SetDiffuse(0.0)
        if shadows:
            plotter.enable_shadows()

    def surface_points(self, displacement: np.ndarray) -> np.ndarray:
        """The deformed positions (3D) of the surface's vertices in a state.

        Args:
            displacement: Vertex displacements (n, 2 or 3).

        Returns:
            (s, 3) positions of the vertices on the boundary triangles.
        """
        used = np.unique(self._faces)
        return self._rest[used] + _pad3(displacement[used])

    def render(self, displacement: np.ndarray, values: np.ndarray, title: str = "",
               shot: Shot | None = None) -> np.ndarray:
        """Render the bodies in one state.

        Args:
            displacement: Vertex displacements (n, 2 or 3).
            values: The colour field: per vertex for displacement, per cell otherwise.
            title: Text drawn in the top-left corner.
            shot: The camera of this frame (default: where it was).

        Returns:
            The image, (height, width, 3) uint8.
        """
        x = self._rest + _pad3(displacement)
        self.surface.points = x
        self.values[:] = values if self.field == "displacement" else \
            np.asarray(values)[self._face_cell]
        self.surface.Modified()
        if shot is not None:
            camera = self.plotter.camera
            camera.position, camera.focal_point = shot.position, shot.focal_point
            camera.up, camera.view_angle = shot.up, shot.view_angle
            self.plotter.renderer.ResetCameraClippingRange()
            centre = 0.5 * (x.min(axis=0) + x.max(axis=0))
            for actor, shown in zip(self._obstacle_actors, visible_obstacles(
                    self.obstacles, np.asarray(shot.position), centre, self.dim)):
                actor.SetVisibility(shown)
        self.text.SetInput(title or " ")
        self._shade_tiles()
        self.plotter.render()
        return self.plotter.screenshot(return_img=True)

    def _shade_tiles(self) -> None:
        """Give each unlit tile the colour the lights give it from where the camera is."""
        camera = self.plotter.camera
        for prop, normal, point in self._tiles:
            prop.SetAmbientColor(*plane_shade(normal, point, camera.position,
                                              camera.focal_point, camera.up,
                                              self._tile_color))

    def close(self) -> None:
        """Release the plotter and its render window."""
        self.plotter.close()


def scalar_bar_reserve(settings: dict) -> float:
    """The share of the picture's height the scalar bar takes at the bottom (0 without one).

    Args:
        settings: The resolved ``[render]`` table.

    Returns:
        :data:`SCALAR_BAR_HEIGHT` if a scalar bar is drawn, else 0.
    """
    shown = settings["window_size"][0] >= MIN_SCALAR_BAR_WIDTH and settings["color_by"] != "body"
    return SCALAR_BAR_HEIGHT if shown else 0.0


def _normals_filter(surface):
    """VTK's normals filter on ``surface``: smooth vertex normals, split at edges sharper than
    :data:`CREASE_ANGLE` (a box keeps its edges); it runs again whenever ``surface`` is
    modified, inside the same pipeline."""
    from vtkmodules.vtkFiltersCore import vtkPolyDataNormals

    normals = vtkPolyDataNormals()
    normals.SetInputData(surface)
    normals.SetFeatureAngle(CREASE_ANGLE)
    normals.SplittingOn()
    normals.ConsistencyOff()  # outer_faces winds them outwards already
    normals.AutoOrientNormalsOff()
    normals.ComputeCellNormalsOff()
    return normals


def stage_of(frames: list[np.ndarray]) -> tuple[np.ndarray, float]:
    """The bodies' box centre and largest box side over all frames.

    Args:
        frames: Surface positions per frame (k arrays (s, 3)).

    Returns:
        ``(centre, size)``; ``size`` is positive.
    """
    every = np.concatenate(frames)
    lo, hi = every.min(axis=0), every.max(axis=0)
    return 0.5 * (lo + hi), max(float(np.max(hi - lo)), 1e-9)


def body_labels(cells: np.ndarray) -> np.ndarray:
    """The connected part of the mesh each cell belongs to, numbered by first cell.

    For a ``[[body]]`` scene these are the bodies in their order (their cells are
    concatenated).

    Args:
        cells: Simplices (m, 3 or 4).

    Returns:
        The part number of each cell, (m,) float (a colour field).
    """
    return cell_components(cells, int(cells.max()) + 1).astype(float)


def render_frame(path: Path, points: np.ndarray, cells: np.ndarray, displacement: np.ndarray,
                 energy_density: np.ndarray | None = None, title: str = "",
                 settings: dict | None = None, scene: dict | None = None) -> None:
    """Render one state to a PNG, its colour range and framing from this state alone.

    Args:
        path: PNG file to write.
        points: Rest positions (n, 2 or 3).
        cells: Simplices (m, 3 or 4).
        displacement: Vertex displacements (n, 2 or 3).
        energy_density: Cell energy densities (m,), needed to colour by them.
        title: Text drawn in the top-left corner.
        settings: The scene's ``[render]`` table (default: its defaults).
        scene: The scene table (its pins decide the defaults, its obstacles are drawn).
    """
    import imageio.v3 as iio

    settings = resolve_settings(settings or {}, cells, scene)
    if settings["color_by"] == "energy_density" and energy_density is None:
        settings = settings | {"color_by": "displacement"}  # a file from an older run
    values = {"displacement": lambda: np.linalg.norm(displacement, axis=1),
              "energy_density": lambda: energy_density,
              "body": lambda: body_labels(cells)}[settings["color_by"]]()
    d = points.shape[1]
    used = np.unique(outer_faces(points, cells)[0])
    x = _pad3(points[used] + displacement[used, :d])
    renderer = FrameRenderer(points, cells, settings, (0.0, float(values.max())),
                             stage_of([x]), (scene or {}).get("obstacle") or [])
    try:
        shot = plan_shots([x], settings, d, scalar_bar_reserve(settings))[0]
        iio.imwrite(path, renderer.render(displacement[:, :d], values, title, shot))
    finally:
        renderer.close()


def space_dim(cell_type: str, directory: Path) -> int:
    """The space dimension of a run's mesh: 3 for tetrahedra and for a shell's triangles (its
    ``scene.json`` has a ``[shell]`` table, or a ``[[body]]`` one: a surface in 3D, alone or
    seen with solids' boundaries), 2 for other triangles.

    Args:
        cell_type: meshio's cell type, ``"tetra"`` or ``"triangle"``.
        directory: The run directory (where ``scene.json`` is).
    """
    if cell_type == "tetra":
        return 3
    try:
        scene = json.loads((Path(directory) / "scene.json").read_text())["scene"]
    except (OSError, KeyError, ValueError):
        return 2
    bodies = scene.get("body") or []
    return 3 if "shell" in scene or any("shell" in b for b in bodies) else 2


def render_vtu(vtu: Path, png: Path, title: str = "", settings: dict | None = None) -> None:
    """Render a ``final.vtu``-style file to a PNG.

    Args:
        vtu: A mesh file with point data ``displacement`` (and cell data
            ``energy_density``, to colour by it).
        png: The PNG file to write.
        title: Text drawn in the top-left corner.
        settings: The scene's ``[render]`` table (default: its defaults).
    """
    import meshio

    m = meshio.read(vtu)
    kind = "tetra" if "tetra" in m.cells_dict else "triangle"
    d = space_dim(kind, Path(vtu).parent)
    cells = m.cells_dict[kind]
    psi = m.cell_data_dict.get("energy_density", {}).get(kind)
    render_frame(png, m.points[:, :d], cells, m.point_data["displacement"][:, :d], psi, title,
                 settings)
