"""Off-screen pictures with pyvista: the deformed mesh coloured by a field.

Without a display, VTK's EGL render window is selected (no X server needed).
:class:`FrameRenderer` sets up one plotter (camera, colour map, colour range, background
from the scene's ``[render]`` table) and renders frame after frame into it, so the framing
and the colours stay fixed over an animation (:mod:`fem_anim.render.animation`);
:func:`render_frame` and :func:`render_vtu` make one picture of one state.

Only the rendering process imports this module (:mod:`fem_anim.render.process`): the VTK
wheel's C++ runtime clashes with libraries DOLFINx loads.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from fem_anim.mesh.connectivity import cell_components

__all__ = ["FrameRenderer", "VIEWS", "FIELD_LABELS", "DEFAULT_SETTINGS", "body_labels",
           "render_frame", "render_vtu"]

#: Named views: direction from the focal point to the camera, and the up vector.
VIEWS = {
    "side": ((0.35, -1.0, 0.3), (0.0, 0.0, 1.0)),  # the default 3D view: z up, from -y
    "iso": ((1.0, 1.0, 1.0), (0.0, 0.0, 1.0)),
    "xy": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "xz": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "yz": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
}
#: Scalar bar titles of the fields ``render.color_by`` names.
FIELD_LABELS = {"displacement": "displacement (m)", "energy_density": "psi (J/m^3)",
                "body": "body"}
#: Colours of the bodies (``color_by = "body"``), in order, repeated past ten.
BODY_COLORMAP = "tab10"
#: Narrower pictures have no scalar bar (its labels would cover the body).
MIN_SCALAR_BAR_WIDTH = 240
#: The ``[render]`` table's defaults (see fem_anim/scene/schema.py), for a bare ``render_frame``.
DEFAULT_SETTINGS = {"color_by": "displacement", "colormap": "viridis", "view": "auto",
                    "camera_position": None, "focal_point": None, "view_up": None,
                    "background": "white", "window_size": [800, 600], "show_edges": True}


def _pyvista():
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista

    pyvista.OFF_SCREEN = True
    return pyvista


def _pad3(a: np.ndarray) -> np.ndarray:
    return np.hstack([a, np.zeros((a.shape[0], 3 - a.shape[1]))]) if a.shape[1] < 3 else a


class FrameRenderer:
    """One off-screen plotter: a mesh whose positions and colours change frame by frame.

    Args:
        points: Rest positions (n, 2 or 3).
        cells: Simplices (m, 3 or 4).
        settings: The scene's ``[render]`` table.
        clim: Fixed colour range (lo, hi) of the field.
        bounds: Box (xmin, xmax, ymin, ymax, zmin, zmax) the camera frames: the union of
            all frames' deformed positions, so the view does not jump.
        obstacles: The scene's ``[[obstacle]]`` tables, drawn grey (a plane as a square
            around the bodies' footprint, a sphere as itself).
    """

    def __init__(self, points: np.ndarray, cells: np.ndarray, settings: dict,
                 clim: tuple[float, float], bounds: np.ndarray, obstacles=()):
        import matplotlib.colors

        pv = _pyvista()
        self.dim = points.shape[1]
        self.field = settings["color_by"]
        X = _pad3(points)
        cell_type = pv.CellType.TETRA if cells.shape[1] == 4 else pv.CellType.TRIANGLE
        topology = np.hstack([np.full((cells.shape[0], 1), cells.shape[1]), cells]).ravel()
        types = np.full(cells.shape[0], cell_type, dtype=np.uint8)
        self._rest = X
        self.grid = pv.UnstructuredGrid(topology, types, X.copy())
        label = FIELD_LABELS[self.field]
        data = self.grid.point_data if self.field == "displacement" else self.grid.cell_data
        data[label] = np.zeros(points.shape[0] if self.field == "displacement" else
                               cells.shape[0])
        self.values = data[label]  # a view on the VTK array: updated in place per frame
        background = matplotlib.colors.to_rgb(settings["background"])
        ink = "black" if np.dot(background, (0.299, 0.587, 0.114)) > 0.5 else "white"
        width, height = settings["window_size"]
        self.plotter = plotter = pv.Plotter(off_screen=True, window_size=[width, height])
        plotter.disable_anti_aliasing()  # MSAA triples the cost of a software-rendered frame
        plotter.set_background(background)
        lo, hi = clim
        bodies = self.field == "body"
        if bodies:  # categorical: body k takes colour k of the palette
            lo, hi = -0.5, 9.5
        plotter.add_mesh(self.grid, scalars=label,
                         cmap=BODY_COLORMAP if bodies else settings["colormap"],
                         n_colors=10 if bodies else 256,
                         clim=(lo, hi if hi > lo else lo + 1.0),
                         show_scalar_bar=width >= MIN_SCALAR_BAR_WIDTH and not bodies,
                         show_edges=settings["show_edges"],
                         edge_color="#404040" if ink == "black" else "#a0a0a0",
                         scalar_bar_args={"title": label, "color": ink, "vertical": False,
                                          "position_x": 0.25, "position_y": 0.03,
                                          "width": 0.5, "height": 0.1, "fmt": "%.2g",
                                          "n_labels": 3})
        rest = pv.UnstructuredGrid(topology, types, X)
        plotter.add_mesh(rest, style="wireframe", color="grey", opacity=0.25)
        self.text = plotter.add_text("", position="upper_left", font_size=8, color=ink)
        for obstacle in obstacles:
            plotter.add_mesh(_obstacle_mesh(pv, obstacle, np.asarray(bounds, float)),
                             color="#b0b0b0", opacity=0.6)
        self._place_camera(settings, np.asarray(bounds, float))

    def _place_camera(self, settings: dict, bounds: np.ndarray) -> None:
        center = 0.5 * (bounds[0::2] + bounds[1::2])
        camera = self.plotter.camera
        if settings["camera_position"] is not None:
            focal = settings["focal_point"] if settings["focal_point"] is not None else center
            up = settings["view_up"] if settings["view_up"] is not None else (0.0, 0.0, 1.0)
            self.plotter.camera_position = [tuple(settings["camera_position"]), tuple(focal),
                                            tuple(up)]
            return
        view = settings["view"]
        if view == "auto":
            view = "side" if self.dim == 3 else "xy"
        direction, up = VIEWS[view]
        camera.focal_point = tuple(center)
        camera.position = tuple(center + np.asarray(direction))
        camera.up = up
        self.plotter.renderer.ResetCamera(*bounds)  # keeps the direction, fits the box

    def render(self, displacement: np.ndarray, values: np.ndarray, title: str = "") -> np.ndarray:
        """Render the mesh in one state.

        Args:
            displacement: Vertex displacements (n, 2 or 3).
            values: The colour field: per vertex for displacement, per cell otherwise.
            title: Text drawn in the top-left corner.

        Returns:
            The image, (height, width, 3) uint8.
        """
        self.grid.points = self._rest + _pad3(displacement)
        self.values[:] = values
        self.grid.Modified()
        self.text.SetText(2, title)  # 2: the upper-left corner of the annotation
        self.plotter.render()
        return self.plotter.screenshot(return_img=True)

    def close(self) -> None:
        """Release the plotter and its render window."""
        self.plotter.close()


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


def _obstacle_mesh(pv, obstacle: dict, bounds: np.ndarray):
    """A pyvista surface of an obstacle: a plane as a square twice the bodies' size about
    their centre's projection onto it, a sphere as itself."""
    center = 0.5 * (bounds[0::2] + bounds[1::2])
    if obstacle["type"] == "sphere":
        return pv.Sphere(radius=obstacle["radius"], center=_pad3(
            np.asarray([obstacle["center"]], float))[0], theta_resolution=48,
            phi_resolution=24)
    normal = _pad3(np.asarray([obstacle["normal"]], float))[0]
    normal /= np.linalg.norm(normal)
    point = _pad3(np.asarray([obstacle["point"] or [0.0] * len(obstacle["normal"])], float))[0]
    size = 2.0 * float(np.max(bounds[1::2] - bounds[0::2]))
    foot = center - np.dot(center - point, normal) * normal
    return pv.Plane(center=foot, direction=normal, i_size=size, j_size=size)


def render_frame(path: Path, points: np.ndarray, cells: np.ndarray, displacement: np.ndarray,
                 energy_density: np.ndarray | None = None, title: str = "",
                 settings: dict | None = None) -> None:
    """Render one state to a PNG, its colour range and framing from this state alone.

    Args:
        path: PNG file to write.
        points: Rest positions (n, 2 or 3).
        cells: Simplices (m, 3 or 4).
        displacement: Vertex displacements (n, 2 or 3).
        energy_density: Cell energy densities (m,), needed to colour by them.
        title: Text drawn in the top-left corner.
        settings: The scene's ``[render]`` table (default: its defaults).
    """
    import imageio.v3 as iio

    settings = DEFAULT_SETTINGS | (settings or {})
    if settings["color_by"] == "energy_density" and energy_density is None:
        settings = settings | {"color_by": "displacement"}  # a file from an older run
    values = {"displacement": lambda: np.linalg.norm(displacement, axis=1),
              "energy_density": lambda: energy_density,
              "body": lambda: body_labels(cells)}[settings["color_by"]]()
    x = _pad3(points[:, : points.shape[1]] + displacement[:, : points.shape[1]])
    x = np.vstack([x, _pad3(points)])
    bounds = np.ravel(np.column_stack([x.min(axis=0), x.max(axis=0)]))
    renderer = FrameRenderer(points, cells, settings, (0.0, float(values.max())), bounds)
    try:
        iio.imwrite(path, renderer.render(displacement[:, : points.shape[1]], values, title))
    finally:
        renderer.close()


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
    d = 3 if "tetra" in m.cells_dict else 2
    cells = m.cells_dict["tetra" if d == 3 else "triangle"]
    psi = m.cell_data_dict.get("energy_density", {}).get("tetra" if d == 3 else "triangle")
    render_frame(png, m.points[:, :d], cells, m.point_data["displacement"][:, :d], psi, title,
                 settings)
