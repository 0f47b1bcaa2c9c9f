"""Where the camera stands in each frame: framing the bodies, not the ground.

A perspective camera with view angle ``fov`` (degrees, vertical) at ``focal + D d`` looking
along ``-d`` sees a point ``p`` whose offset from the focal point has coordinates
``(x, y, z)`` on the camera's right, up and backward axes inside the picture when

    |y| <= (D - z) tan(fov / 2)   and   |x| <= (D - z) a tan(fov / 2),

``a`` the picture's width over its height. :func:`fit_distance` takes the smallest ``D``
for which every given point satisfies both with a margin, after moving the focal point to
the centre of the points' projection, so the bodies fill the picture whichever their shape.
The three ``render.camera`` modes:

* ``fit_bodies``: one camera for the whole run, fitted to the bodies' positions in all
  frames (obstacles are not fitted: a ground plane does not shrink the bodies);
* ``follow``: the focal point follows the centre of the bodies' box, smoothed over a few
  frames, at one distance (the largest any frame needs), so a body rolling away stays the
  same size in the picture (the default when the bodies travel far, :func:`camera_mode`);
* ``fixed``: ``render.camera_position``, ``render.focal_point`` (default: the bodies'
  centre over the run) and ``render.view_up``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fem_anim.scene.schema import CAMERA_MODES

__all__ = ["Shot", "VIEWS", "CAMERA_MODES", "MARGIN", "camera_mode", "view_axes",
           "fit_distance", "plan_shots"]

#: Named views: direction from the focal point to the camera, and the up vector.
VIEWS = {
    "side": ((0.35, -1.0, 0.3), (0.0, 0.0, 1.0)),  # the default 3D view: z up, from -y
    "iso": ((1.0, 1.0, 1.0), (0.0, 0.0, 1.0)),
    "xy": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "xz": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "yz": ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),
}
#: Share of the picture's half-width and half-height kept free around the bodies.
MARGIN = 0.08
#: Frames over which ``follow`` averages the bodies' centre (an odd number).
FOLLOW_WINDOW = 9
#: Default ``follow`` when the bodies travel further than this many times their size.
FOLLOW_TRAVEL = 2.0


@dataclass(frozen=True)
class Shot:
    """One frame's camera: position, focal point and up vector (m), vertical view angle (deg)."""

    position: tuple[float, float, float]
    focal_point: tuple[float, float, float]
    up: tuple[float, float, float]
    view_angle: float


def camera_mode(settings: dict, frames: list[np.ndarray] | None = None) -> str:
    """``render.camera``, or its default.

    The default is ``fixed`` with a ``render.camera_position``; otherwise ``follow`` when the
    centre of the bodies' box travels further than :data:`FOLLOW_TRAVEL` times their largest
    size in any frame (a body thrown or rolling away: one camera for the whole path would
    make it small), else ``fit_bodies``.

    Args:
        settings: The ``[render]`` table.
        frames: The bodies' surface positions per frame (needed for the default).

    Returns:
        One of :data:`CAMERA_MODES`.
    """
    if settings.get("camera"):
        return settings["camera"]
    if settings.get("camera_position") is not None:
        return "fixed"
    if not frames:
        return "fit_bodies"
    centres = np.array([_box_centre(x) for x in frames])
    size = max(float(np.max(np.ptp(x, axis=0))) for x in frames)
    travel = float(np.max(np.ptp(centres, axis=0)))
    return "follow" if travel > FOLLOW_TRAVEL * size else "fit_bodies"


def view_axes(direction, up) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The camera's backward, right and up unit vectors for a view direction and up hint.

    Args:
        direction: From the focal point towards the camera (3,).
        up: The wanted up direction; only its part across ``direction`` is kept.

    Returns:
        ``(d, right, true_up)``, orthonormal, right-handed (``right = up x d``).
    """
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    up = np.asarray(up, float)
    true_up = up - np.dot(up, d) * d
    if np.linalg.norm(true_up) < 1e-9 * np.linalg.norm(up):  # looking along the up hint
        true_up = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        true_up = true_up - np.dot(true_up, d) * d
    true_up /= np.linalg.norm(true_up)
    return d, np.cross(true_up, d), true_up


def _tangents(fov: float, aspect: float) -> tuple[float, float]:
    t = math.tan(math.radians(fov) / 2.0) * (1.0 - MARGIN)
    return aspect * t, t


def fit_distance(points: np.ndarray, focal: np.ndarray, axes, fov: float, aspect: float,
                 centre: bool = True) -> tuple[np.ndarray, float]:
    """The focal point and the smallest distance at which ``points`` fill the picture.

    Args:
        points: Positions to keep in the picture (n, 3).
        focal: A first focal point (3,), e.g. the points' box centre.
        axes: ``(d, right, up)`` from :func:`view_axes`.
        fov: Vertical view angle (degrees).
        aspect: Picture width over height.
        centre: Move the focal point to the centre of the points' projection first.

    Returns:
        The focal point (moved, if ``centre``) and the camera's distance ``D`` from it: the
        largest of the module's two bounds over the points, with :data:`MARGIN`.
    """
    d, right, up = axes
    tx, ty = _tangents(fov, aspect)

    def distance(focal):
        r = points - focal
        x, y, z = r @ right, r @ up, r @ d
        D = float(np.max(np.maximum(z + np.abs(x) / tx, z + np.abs(y) / ty)))
        return max(D, 1.001 * float(np.max(z)), 1e-6), x, y, z

    D, x, y, z = distance(focal)
    for _ in range(2 if centre else 0):  # centre the projection, fit again
        sx, sy = x / (D - z), y / (D - z)  # picture coordinates (tangents of the angles)
        cx, cy = 0.5 * (sx.min() + sx.max()), 0.5 * (sy.min() + sy.max())
        focal = focal + D * (cx * right + cy * up)
        D, x, y, z = distance(focal)
    return focal, D


def _box_centre(points: np.ndarray) -> np.ndarray:
    return 0.5 * (points.min(axis=0) + points.max(axis=0))


def plan_shots(frames: list[np.ndarray], settings: dict, dim: int, reserve: float = 0.0
               ) -> list[Shot]:
    """The camera of every frame.

    Args:
        frames: The deformed positions of the bodies' surface vertices in each frame
            (k arrays (n, 3)).
        settings: The ``[render]`` table: ``camera``, ``view``, ``camera_position``,
            ``focal_point``, ``view_up``, ``fov``, ``window_size``.
        dim: 2 or 3 (``view = "auto"`` is ``side`` in 3D, ``xy`` in 2D).
        reserve: Share of the picture's height kept free at the bottom (for a scalar bar):
            the bodies are fitted into the rest, by a view angle ``1 - reserve`` times as
            tall, and the camera looks that much lower.

    Returns:
        One :class:`Shot` per frame (the same one unless ``camera = "follow"``).
    """
    mode = camera_mode(settings, frames)
    fov = float(settings.get("fov") or 30.0)
    width, height = settings["window_size"]
    aspect = width / height
    every = np.concatenate(frames)
    if mode == "fixed":
        focal = settings.get("focal_point")
        focal = _box_centre(every) if focal is None else np.asarray(focal, float)
        up = settings.get("view_up") or (0.0, 0.0, 1.0)
        shot = Shot(tuple(map(float, settings["camera_position"])), tuple(map(float, focal)),
                    tuple(map(float, up)), fov)
        return [shot] * len(frames)
    view = settings.get("view") or "auto"
    if view == "auto":
        view = "side" if dim == 3 else "xy"
    axes = view_axes(*VIEWS[view])
    d, _, up = axes
    t = math.tan(math.radians(fov) / 2.0)
    fit_fov = math.degrees(2.0 * math.atan((1.0 - reserve) * t))
    fit_aspect = aspect / (1.0 - reserve)

    def lowered(focal: np.ndarray, D: float) -> np.ndarray:
        return focal - reserve * t * D * up

    if mode == "fit_bodies":
        focal, D = fit_distance(every, _box_centre(every), axes, fit_fov, fit_aspect)
        focal = lowered(focal, D)
        shot = Shot(tuple(focal + D * d), tuple(focal), tuple(up), fov)
        return [shot] * len(frames)
    centres = np.array([_box_centre(x) for x in frames])
    half = FOLLOW_WINDOW // 2
    padded = np.concatenate([np.repeat(centres[:1], half, 0), centres,
                             np.repeat(centres[-1:], half, 0)])
    kernel = np.ones(FOLLOW_WINDOW) / FOLLOW_WINDOW
    smooth = np.column_stack([np.convolve(padded[:, i], kernel, mode="valid")
                              for i in range(3)])
    # the smoothed centre stays the focal point (centring each frame would bring the jitter
    # back); one distance, the largest any frame needs about it
    D = max(fit_distance(x, c, axes, fit_fov, fit_aspect, centre=False)[1]
            for x, c in zip(frames, smooth))
    focals = [lowered(c, D) for c in smooth]
    return [Shot(tuple(f + D * d), tuple(f), tuple(up), fov) for f in focals]
