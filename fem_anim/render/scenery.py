"""What surrounds the bodies in a picture: obstacles as finite tiles, and the lights.

An obstacle plane is drawn as a square tile (in 2D a band along the line, on the side the
bodies cannot enter) centred under the bodies, :data:`TILE_SCALE` times their largest
extent over the run; an obstacle sphere as itself. A plane whose half-space boundary lies
between the camera and the bodies (the camera on its far side, the bodies' centre on the
near side) would cover them: :func:`visible_obstacles` leaves it out of that frame, and
likewise a sphere the line of sight from the camera to the bodies' centre passes through.
Obstacles are drawn opaque: a translucent surface costs a depth-sorting pass per frame.

The lights are a key light from the upper left of the camera, a dimmer fill light from its
right and an ambient term on every surface, all attached to the camera (camera lights), so
a following camera keeps the same lighting.
"""

from __future__ import annotations

import numpy as np

__all__ = ["TILE_SCALE", "OBSTACLE_COLOR", "obstacle_mesh", "visible_obstacles", "add_lights"]

#: The side of a plane's tile over the bodies' largest extent.
TILE_SCALE = 3.0
#: Colour of the obstacles.
OBSTACLE_COLOR = "#d4d4d4"


def _pad3(a) -> np.ndarray:
    a = np.asarray(a, float).ravel()
    return np.concatenate([a, np.zeros(3 - a.size)])


def _plane(obstacle: dict) -> tuple[np.ndarray, np.ndarray]:
    normal = _pad3(obstacle["normal"])
    normal /= np.linalg.norm(normal)
    point = obstacle.get("point")
    return normal, _pad3(point if point is not None else [0.0] * len(obstacle["normal"]))


def obstacle_mesh(pv, obstacle: dict, centre: np.ndarray, size: float, dim: int):
    """A pyvista surface of one ``[[obstacle]]`` table.

    Args:
        pv: The pyvista module.
        obstacle: The table (``type``, ``normal``/``point`` or ``center``/``radius``).
        centre: The bodies' centre over the run (3,).
        size: The bodies' largest extent over the run (m).
        dim: 2 or 3.

    Returns:
        A plane's tile (3D: a square of side ``TILE_SCALE * size`` about the foot of
        ``centre`` on the plane; 2D: a band ``TILE_SCALE * size`` long, ``0.1`` of that
        deep, behind the line), or the sphere.
    """
    if obstacle["type"] == "sphere":
        return pv.Sphere(radius=obstacle["radius"], center=_pad3(obstacle["center"]),
                         theta_resolution=48, phi_resolution=24)
    normal, point = _plane(obstacle)
    side = TILE_SCALE * size
    foot = centre - np.dot(centre - point, normal) * normal
    if dim == 3:
        return pv.Plane(center=foot, direction=normal, i_size=side, j_size=side)
    tangent = np.array([-normal[1], normal[0], 0.0])
    depth = 0.1 * side
    corners = np.array([foot - 0.5 * side * tangent, foot + 0.5 * side * tangent,
                        foot + 0.5 * side * tangent - depth * normal,
                        foot - 0.5 * side * tangent - depth * normal])
    corners[:, 2] = -1e-3 * side  # just behind the bodies' plane
    return pv.PolyData(corners, faces=np.array([4, 0, 1, 2, 3]))


def visible_obstacles(obstacles, camera: np.ndarray, centre: np.ndarray, dim: int
                      ) -> list[bool]:
    """Which obstacles leave the camera's view of the bodies' centre free.

    Args:
        obstacles: The ``[[obstacle]]`` tables.
        camera: The camera position (3,).
        centre: The bodies' centre in this frame (3,).
        dim: 2 or 3 (in 2D the camera looks across every line: all are drawn).

    Returns:
        For each obstacle, whether it is drawn: a plane unless the camera and the bodies'
        centre are on opposite sides of it; a sphere unless the segment from the camera
        to the centre passes through it.
    """
    shown = []
    for obstacle in obstacles:
        if dim == 2:
            shown.append(True)
        elif obstacle["type"] == "plane":
            normal, point = _plane(obstacle)
            shown.append(np.dot(camera - point, normal) * np.dot(centre - point, normal) >= 0)
        else:
            c, r = _pad3(obstacle["center"]), float(obstacle["radius"])
            segment = centre - camera
            s = np.clip(np.dot(c - camera, segment) / np.dot(segment, segment), 0.0, 1.0)
            shown.append(bool(np.linalg.norm(camera + s * segment - c) > r))
    return [bool(s) for s in shown]


def add_lights(pv, plotter) -> None:
    """A key light (upper left of the camera), a fill light (right), moving with the camera.

    Args:
        pv: The pyvista module.
        plotter: A plotter made with ``lighting="none"``.
    """
    # camera-light coordinates: camera at (0, 0, 1) looking at the origin, y up
    plotter.add_light(pv.Light(position=(-0.8, 1.0, 1.0), light_type="camera light",
                               intensity=0.85))
    plotter.add_light(pv.Light(position=(1.0, -0.2, 0.8), light_type="camera light",
                               intensity=0.35))
