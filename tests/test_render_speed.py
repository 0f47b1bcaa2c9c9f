"""The renderer's shortcuts give the pictures the plain way would.

:class:`~fem_anim.render.frames.FrameRenderer` keeps one scene graph for all frames and draws
plane tiles unlit in the colour the lights give them
(:func:`~fem_anim.render.scenery.plane_shade`). Checked here on two cubes of tetrahedra made
in numpy, in small off-screen pictures: a tile drawn that way equals VTK's lit tile, from the
front and from the back, in 3D and 2D; and a frame drawn after others by one renderer equals
the same frame drawn by a fresh renderer (nothing of an earlier frame stays: positions,
colours, the tiles' shade, the obstacles culled). The frames' PNG files are lossless and the
MP4's frames stay near them.
"""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from fem_anim.render.camera import plan_shots
from fem_anim.render.frames import FrameRenderer, stage_of
from fem_anim.render.outer_surface import outer_faces
from fem_anim.render.png_writer import encode_png
from fem_anim.render.render_defaults import resolve_settings
from fem_anim.render.scenery import OBSTACLE_COLOR, plane_shade

WINDOW = [160, 120]
KUHN = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7],
                 [0, 4, 6, 7]])
#: A ground under the cubes, seen from above (its front); a plane facing down under them,
#: seen from its back with the cubes on its back side too (drawn: nothing is hidden); a
#: wall beside them.
PLANES = [{"type": "plane", "normal": [0.0, 0.0, 1.0], "point": [0.0, 0.0, -0.05]},
          {"type": "plane", "normal": [0.0, 0.0, -1.0], "point": [0.0, 0.0, -0.3]},
          {"type": "plane", "normal": [1.0, 0.0, 0.0], "point": [-0.2, 0.0, 0.0]}]


def _two_cubes():
    bits = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], float)
    points = np.vstack([0.2 * bits, 0.2 * bits + [0.3, 0.0, 0.0]])
    return points, np.vstack([KUHN, KUHN + 8])


def _two_squares():
    points = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [2, 0], [3, 0], [3, 1], [2, 1]], float)
    cells = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    return 0.2 * points, cells


def _frames(points, k=4):
    """k states: the bodies moved and squeezed a little more each frame."""
    return np.stack([np.column_stack([0.03 * i * np.ones(len(points)),
                                      -0.02 * i * points[:, 1]]
                                     + ([0.01 * i * points[:, 2]] if points.shape[1] == 3
                                        else [])) for i in range(k)])


def _renderer(points, cells, u, settings, obstacles, shaded):
    d = points.shape[1]
    used = np.unique(outer_faces(points, cells)[0])
    surfaces = [np.hstack([points[used] + x[used], np.zeros((used.size, 3 - d))]) for x in u]
    values = np.linalg.norm(u, axis=2)
    renderer = FrameRenderer(points, cells, settings, (0.0, float(values.max())),
                             stage_of(surfaces), obstacles, shaded_tiles=shaded)
    return renderer, values, plan_shots(surfaces, settings, d)


def _grey(image):
    """Pixels of a tile: grey (r = g = b), neither the white background nor black text."""
    r, g, b = (image[..., i].astype(int) for i in range(3))
    return (r == g) & (g == b) & (r > 40) & (r < 250)


def _main_grey(image) -> int:
    """The commonest grey level: the largest tile's shade."""
    levels, counts = np.unique(image[_grey(image)][:, 0], return_counts=True)
    return int(levels[np.argmax(counts)])


@pytest.mark.parametrize("view, planes", [("side", PLANES), ("iso", PLANES), ("yz", PLANES),
                                          ("side", PLANES[1:2])])
def test_shaded_tiles_equal_vtks_lit_tiles_3d(view, planes):
    """The tiles from the cameras of three views, and a tile seen from its back alone."""
    points, cells = _two_cubes()
    u = _frames(points)
    settings = resolve_settings({"window_size": WINDOW, "view": view}, cells, None)
    images = []
    for shaded in (False, True):
        renderer, values, shots = _renderer(points, cells, u, settings, planes, shaded)
        try:
            images.append(renderer.render(u[2], values[2], "t", shots[2]).astype(int))
        finally:
            renderer.close()
    lit, shaded = images
    assert _grey(lit).sum() > 0.05 * lit.shape[0] * lit.shape[1]  # the tiles are in sight
    difference = np.abs(lit - shaded)
    assert difference.mean() < 0.01 and difference.max() <= 1


def test_shaded_tiles_equal_vtks_lit_tiles_2d():
    points, cells = _two_squares()
    u = _frames(points)
    settings = resolve_settings({"window_size": WINDOW}, cells, None)
    line = [{"type": "plane", "normal": [0.0, 1.0], "point": [0.0, -0.05]}]
    images = []
    for shaded in (False, True):
        renderer, values, shots = _renderer(points, cells, u, settings, line, shaded)
        try:
            images.append(renderer.render(u[1], values[1], "t", shots[1]).astype(int))
        finally:
            renderer.close()
    assert _grey(images[0]).sum() > 100
    assert np.abs(images[0] - images[1]).max() <= 1


def test_plane_shade_front_and_back():
    """The shade seen from either side of a plane is the same (two-sided lighting), depends
    on where the camera looks from, and is between ambient-only and fully lit."""
    color = np.array([0.8, 0.8, 0.8])
    normal, point = np.array([0.0, 0.0, 1.0]), np.zeros(3)
    up = np.array([0.0, 1.0, 0.0])
    above = plane_shade(normal, point, [0.2, 0.1, 2.0], [0.2, 0.1, 0.0], up, color)
    below = plane_shade(normal, point, [0.2, 0.1, -2.0], [0.2, 0.1, 0.0], up, color)
    np.testing.assert_allclose(above, below)
    slanted = plane_shade(normal, point, [2.0, 0.0, 0.5], [0.0, 0.0, 0.0], [0, 0, 1], color)
    assert np.all(np.abs(slanted - above) > 0.05)
    assert np.all(above > 0.3 * color) and np.all(above <= 1.0)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_frame_after_others_equals_a_fresh_renderers(dim):
    """One renderer drawing frames 0, 3, 1 with three different cameras gives, for frame 1,
    the image a new renderer gives for frame 1 alone; and frames of other states differ."""
    points, cells = _two_squares() if dim == 2 else _two_cubes()
    u = _frames(points)
    obstacles = (PLANES if dim == 3
                 else [{"type": "plane", "normal": [0.0, 1.0], "point": [0.0, -0.05]}])
    views = ["side", "iso", "yz"] if dim == 3 else ["xy", "xy", "xy"]
    shot_of = []
    for view, k in zip(views, (0, 3, 1)):
        settings = resolve_settings({"window_size": WINDOW, "view": view,
                                     "camera": "follow"}, cells, None)
        renderer, values, shots = _renderer(points, cells, u, settings, obstacles, True)
        renderer.close()
        shot_of.append((k, shots[k]))
    renderer, values, _ = _renderer(points, cells, u, settings, obstacles, True)
    try:
        images = [renderer.render(u[k], values[k], f"frame {k}", shot) for k, shot in shot_of]
    finally:
        renderer.close()
    fresh, values, _ = _renderer(points, cells, u, settings, obstacles, True)
    try:
        alone = fresh.render(u[1], values[1], "frame 1", shot_of[2][1])
    finally:
        fresh.close()
    np.testing.assert_array_equal(images[2], alone)
    assert np.abs(images[0].astype(int) - images[2]).sum() > 0
    if dim == 3:  # the tiles' shade changed with the camera between the frames
        shades = {_main_grey(image) for image in images}
        assert len(shades) >= 2


def test_png_is_lossless(tmp_path):
    rng = np.random.default_rng(1)
    image = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    image[10:20] = [212, 212, 212]
    (tmp_path / "a.png").write_bytes(encode_png(image))
    np.testing.assert_array_equal(iio.imread(tmp_path / "a.png"), image)


def test_obstacle_colour_is_grey():
    """_grey finds the tiles only if their colour is grey (r = g = b)."""
    import matplotlib.colors

    r, g, b = matplotlib.colors.to_rgb(OBSTACLE_COLOR)
    assert r == g == b
