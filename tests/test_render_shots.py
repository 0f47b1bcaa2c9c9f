"""Shot-ready pictures: the camera frames the bodies, walls never hide them, scene defaults.

The renderer is driven directly (no simulation): two cubes of tetrahedra made here in numpy,
drawn by :func:`fem_anim.render.frames.render_frame` or a
:class:`~fem_anim.render.parallel_frames.FrameJob` into small off-screen pictures, read
back as arrays. The cameras of :mod:`fem_anim.render.camera` are checked by projecting the
bodies' vertices with the pinhole model the module describes.
"""

from __future__ import annotations

import math

import imageio.v3 as iio
import numpy as np
import pytest

from fem_anim.errors import SceneError
from fem_anim.render import frames as frames_module
from fem_anim.render.camera import plan_shots, view_axes
from fem_anim.render.frames import render_frame, stage_of
from fem_anim.render.outer_surface import outer_faces
from fem_anim.render.parallel_frames import FrameJob, frame_images
from fem_anim.render.render_defaults import resolve_settings
from fem_anim.render.scenery import visible_obstacles
from fem_anim.scene.loading import validate_render

WINDOW = [160, 120]
#: The 6 tetrahedra of a unit cube around its diagonal 0-7 (vertex i: bits x, y, z).
KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7],
                 [0, 4, 6, 7]])


def _cube(size: float, corner) -> tuple[np.ndarray, np.ndarray]:
    bits = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], float)
    return np.asarray(corner, float) + size * bits, KUHN.copy()


def _two_cubes(gap: float = 0.1):
    (p, c), (q, d) = _cube(0.2, (0, 0, 0)), _cube(0.2, (0.2 + gap, 0, 0))
    return np.vstack([p, q]), np.vstack([c, d + 8])


def _render(tmp_path, settings, scene=None, displacement=None):
    points, cells = _two_cubes()
    u = np.zeros_like(points) if displacement is None else displacement
    path = tmp_path / "shot.png"
    render_frame(path, points, cells, u, settings={"window_size": WINDOW} | settings,
                 scene=scene)
    return iio.imread(path).astype(int)


def _body_pixels(image):
    """Pixels of the two cubes: tab10's blue and orange hues, shaded (not grey, not red)."""
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    blue = (b > r + 40) & (b > g)
    orange = (r > b + 60) & (g > b + 20)
    return blue | orange


def _project(points, shot, window):
    """Pixel coordinates (x right, y up, from the centre, in half-heights) of points."""
    d, right, up = view_axes(np.subtract(shot.position, shot.focal_point), shot.up)
    r = points - np.asarray(shot.position)
    depth = -(r @ d)
    t = math.tan(math.radians(shot.view_angle) / 2)
    return np.column_stack([(r @ right) / depth / t, (r @ up) / depth / t])


def test_camera_fills_the_picture_with_the_bodies(tmp_path):
    """fit_bodies: the bodies' pixels span most of the picture's width or height."""
    image = _render(tmp_path, {"obstacles": False})
    rows, cols = np.nonzero(_body_pixels(image))
    assert rows.size > 0
    height, width = image.shape[:2]
    fill = max((cols.max() - cols.min() + 1) / width, (rows.max() - rows.min() + 1) / height)
    assert fill > 0.7, fill
    # centred: the box's middle within a tenth of the picture's middle
    assert abs(0.5 * (cols.max() + cols.min()) / width - 0.5) < 0.1
    assert abs(0.5 * (rows.max() + rows.min()) / height - 0.5) < 0.1


def test_a_wall_between_camera_and_bodies_is_not_drawn(tmp_path, monkeypatch):
    """Side view (camera at -y): a pure red wall in front of the bodies (y = -0.3, the
    bodies on its +y side) is culled, so no pixel is red; the same wall behind them
    (y = 0.5, facing -y) is drawn, and red shows around the bodies."""
    monkeypatch.setattr(frames_module, "OBSTACLE_COLOR", "#ff0000")
    front = {"type": "plane", "normal": [0.0, 1.0, 0.0], "point": [0.0, -0.3, 0.0]}
    behind = {"type": "plane", "normal": [0.0, -1.0, 0.0], "point": [0.0, 0.5, 0.0]}

    def red(image):
        return (image[..., 0] > 150) & (image[..., 1] < 80) & (image[..., 2] < 80)

    shown = _render(tmp_path, {"view": "side"}, {"obstacle": [behind]})
    assert np.count_nonzero(red(shown)) > 0.1 * red(shown).size
    hidden = _render(tmp_path, {"view": "side"}, {"obstacle": [front]})
    assert np.count_nonzero(red(hidden)) == 0
    assert np.count_nonzero(_body_pixels(hidden)) > 0.1 * red(hidden).size
    off = _render(tmp_path, {"view": "side", "obstacles": False}, {"obstacle": [behind]})
    assert np.count_nonzero(red(off)) == 0


def test_visible_obstacles_rule():
    ground = {"type": "plane", "normal": [0, 0, 1], "point": [0, 0, 0]}
    ball = {"type": "sphere", "center": [0.6, -1, 0.5], "radius": 0.2}
    centre = np.array([0.0, 0.0, 0.5])
    above, below = np.array([0.0, -3.0, 1.0]), np.array([0.0, -3.0, -1.0])
    assert visible_obstacles([ground, ball], above, centre, 3) == [True, True]
    assert visible_obstacles([ground], below, centre, 3) == [False]
    assert visible_obstacles([ball | {"center": [0.0, -1.0, 0.6]}], above, centre, 3) == \
        [False]  # the line of sight passes through this ball
    assert visible_obstacles([ground], below, centre, 2) == [True]


def test_follow_keeps_a_travelling_body_the_same_size():
    """A cube moving 20 sizes along x: ``follow`` keeps its projected size and keeps it in
    the picture in every frame; ``fit_bodies`` has one camera, so the cube is small."""
    cube, _ = _cube(0.1, (0, 0, 0))
    frames = [cube + [0.1 * k, 0.0, 0.0] for k in range(21)]
    settings = {"window_size": [400, 300], "view": "side"}
    follow = plan_shots(frames, settings | {"camera": "follow"}, 3)
    fixed = plan_shots(frames, settings | {"camera": "fit_bodies"}, 3)
    assert len(set(fixed)) == 1
    assert plan_shots(frames, settings, 3) == follow  # the default for a body travelling far
    assert len(set(plan_shots(frames[:2], settings, 3))) == 1  # not for one moving 1 size
    aspect = 400 / 300
    sizes = []
    for x, shot in zip(frames, follow):
        p = _project(x, shot, settings["window_size"])
        assert np.all(np.abs(p[:, 0]) <= aspect) and np.all(np.abs(p[:, 1]) <= 1.0)
        sizes.append(np.ptp(p, axis=0).max())
    assert max(sizes) / min(sizes) < 1.3 and min(sizes) > 0.4, sizes
    still = [np.ptp(_project(x, fixed[0], None), axis=0).max() for x in frames]
    assert max(still) < 0.5 * min(sizes)
    every = np.concatenate([_project(x, fixed[0], None) for x in frames])
    assert np.all(np.abs(every[:, 0]) <= aspect) and np.all(np.abs(every[:, 1]) <= 1.0)


def test_fixed_camera_is_where_the_keys_put_it():
    cube, _ = _cube(0.1, (0, 0, 0))
    shots = plan_shots([cube], {"window_size": [100, 100], "camera_position": [1, 2, 3],
                                "focal_point": [0, 0, 1], "fov": 45.0}, 3)
    assert shots[0].position == (1.0, 2.0, 3.0) and shots[0].focal_point == (0.0, 0.0, 1.0)
    assert shots[0].view_angle == 45.0


def test_defaults_by_scene_kind():
    """Free bodies: one colour per body (several bodies), no ghost, no edges; pins: ghost
    and edges on; a single body: coloured by displacement; given keys win."""
    points, cells = _two_cubes()
    one = cells[:6]
    pile = {"pin": [], "body": [{"pin": []}, {"pin": []}]}
    beam = {"pin": [{"box": [0, 0, 0, 1, 1, 1]}]}
    free = resolve_settings({}, cells, pile)
    assert (free["color_by"], free["ghost"], free["show_edges"]) == ("body", False, False)
    held = resolve_settings({}, one, beam)
    assert (held["color_by"], held["ghost"], held["show_edges"]) == ("displacement", True, True)
    pinned_body = {"pin": [], "body": [{"pin": [{"box": [0] * 6}]}, {"pin": []}]}
    assert resolve_settings({}, cells, pinned_body)["ghost"] is True
    assert resolve_settings({"ghost": False, "color_by": "displacement"}, cells,
                            pinned_body)["ghost"] is False
    assert resolve_settings({}, one, None)["color_by"] == "displacement"


def test_render_keys_are_checked():
    assert validate_render({}, ['render.camera="follow"', "render.fov=40"])["camera"] == \
        "follow"
    with pytest.raises(SceneError, match="render.camera_position"):
        validate_render({}, ['render.camera="fixed"'])
    with pytest.raises(SceneError, match='render.camera = "fixed"'):
        validate_render({}, ['render.camera="follow"', "render.camera_position=[1,2,3]"])
    with pytest.raises(SceneError, match="render.fov"):
        validate_render({}, ["render.fov=180"])


def test_outer_faces_point_outwards():
    points, cells = _cube(1.0, (0, 0, 0))
    faces, owner = outer_faces(points, cells)
    assert faces.shape == (12, 3) and np.all(owner < 6)
    a, b, c = (points[faces[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    outward = np.einsum("ij,ij->i", normal, (a + b + c) / 3 - 0.5)
    assert np.all(outward > 0)


def test_workers_render_the_same_frames_in_order(tmp_path):
    """Two worker processes give the serial renderer's images, frame by frame."""
    points, cells = _two_cubes()
    settings = resolve_settings({"window_size": [64, 48], "camera": "follow"}, cells, None)
    k = 6
    u = np.stack([np.tile([0.05 * i, 0.0, -0.02 * i], (points.shape[0], 1))
                  for i in range(k)])
    used = np.unique(outer_faces(points, cells)[0])
    surfaces = [points[used] + x[used] for x in u]
    values = np.linalg.norm(u, axis=2)
    job = FrameJob(points, cells, settings, (0.0, float(values.max())), stage_of(surfaces),
                   [{"type": "plane", "normal": [0, 0, 1], "point": [0, 0, -0.2]}], u,
                   values, [f"frame {i}" for i in range(k)], plan_shots(surfaces, settings, 3),
                   [tmp_path / f"{i}.png" for i in range(k)])
    serial = list(frame_images(job, list(range(k)), 1))
    parallel = list(frame_images(job, list(range(k)), 2))
    assert len(parallel) == k
    for a, b, i in zip(serial, parallel, range(k)):
        np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(iio.imread(tmp_path / f"{i}.png"), b)
    assert any(np.abs(a.astype(int) - b).sum() > 0 for a, b in zip(serial, serial[1:]))
