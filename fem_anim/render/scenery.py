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

The lights are directional, so a plane's tile (one normal, no specular term) takes one
colour all over: :func:`plane_shade` computes it as VTK's shader does (Phong's model with
the normal turned towards the camera, as two-sided lighting does) and the renderer draws
the tile unlit in that colour, which gives the same pixels without lighting every one of
them each frame (tested against VTK's lit tile).
"""

from __future__ import annotations

import numpy as np

__all__ = ["TILE_SCALE", "OBSTACLE_COLOR", "OBSTACLE_AMBIENT", "OBSTACLE_DIFFUSE", "LIGHTS",
           "obstacle_mesh", "visible_obstacles", "add_lights", "tile_plane", "plane_shade"]

#: The side of a plane's tile over the bodies' largest extent.
TILE_SCALE = 3.0
#: Colour of the obstacles.
OBSTACLE_COLOR = "#d4d4d4"
#: The obstacles' ambient and diffuse coefficients (no specular term).
OBSTACLE_AMBIENT, OBSTACLE_DIFFUSE = 0.3, 0.7
#: The camera lights: position in camera-light coordinates (camera at (0, 0, 1) looking at
#: the origin, y up; the light shines from there towards the origin) and intensity.
LIGHTS = (((-0.8, 1.0, 1.0), 0.85),  # key light, upper left
          ((1.0, -0.2, 0.8), 0.35))  # fill light, right


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
    for position, intensity in LIGHTS:
        plotter.add_light(pv.Light(position=position, light_type="camera light",
                                   intensity=intensity))


def tile_plane(obstacle: dict, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """The plane a plane obstacle's tile lies in: its unit normal and a point of it.

    Args:
        obstacle: A ``type = "plane"`` table.
        dim: 2 or 3 (in 2D the tile is a band in the bodies' plane z = 0).

    Returns:
        ``(normal, point)``, both (3,).
    """
    if dim == 2:
        return np.array([0.0, 0.0, 1.0]), np.zeros(3)
    return _plane(obstacle)


def plane_shade(normal: np.ndarray, point: np.ndarray, camera: np.ndarray,
                focal_point: np.ndarray, view_up: np.ndarray, color: np.ndarray
                ) -> np.ndarray:
    """The colour :data:`LIGHTS` give a plane tile seen from a camera.

    VTK's fragment shader for directional lights gives ``ka c + kd c sum_i I_i max(0,
    n . l_i)`` (``ka``, ``kd`` :data:`OBSTACLE_AMBIENT`, :data:`OBSTACLE_DIFFUSE`; ``l_i``
    the unit vector towards light ``i`` and ``n`` the normal in camera coordinates, ``n``
    turned towards the camera as two-sided lighting does), clipped to [0, 1]. For a plane
    every term is the same at every pixel.

    Args:
        normal: The tile's unit normal (3,) (either side).
        point: A point of the tile's plane (3,).
        camera: The camera position (3,).
        focal_point: The camera's focal point (3,).
        view_up: The camera's up direction (3,).
        color: The tile's RGB colour in [0, 1].

    Returns:
        The lit RGB colour in [0, 1].
    """
    camera, normal = np.asarray(camera, float), np.asarray(normal, float)
    if np.dot(camera - point, normal) < 0:
        normal = -normal  # the side the camera sees
    back = camera - np.asarray(focal_point, float)
    back /= np.linalg.norm(back)
    up = np.asarray(view_up, float) - np.dot(view_up, back) * back
    up /= np.linalg.norm(up)
    n = np.array([np.dot(normal, np.cross(up, back)), np.dot(normal, up), np.dot(normal, back)])
    lit = sum(intensity * max(0.0, float(np.dot(n, position)) / np.linalg.norm(position))
              for position, intensity in LIGHTS)
    color = np.asarray(color, float)
    return np.clip(OBSTACLE_AMBIENT * color + OBSTACLE_DIFFUSE * lit * color, 0.0, 1.0)
