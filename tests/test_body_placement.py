"""Where a ``[[body]]`` stands: rotation about two and three axes, then offset.

The contract (:mod:`fem_anim.mesh.bodies`): a body's mesh is turned by ``rotation`` (degrees
about x, then y, then z, fixed axes) and moved by ``offset``: x = R_z R_y R_x X + offset.
It is checked here against an independent implementation, SciPy's
``Rotation.from_euler("xyz", ...)`` (lowercase: extrinsic, fixed axes, x first), on the
matrix and on the vertices of the scene mesh the simulation runs on. Rotations about one
axis alone cannot tell the order of the factors apart; these use two and three axes.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI
from scipy.spatial.transform import Rotation

from fem_anim.mesh.bodies import build_scene_mesh, rotation_matrix
from fem_anim.meshes.structured import structured_box
from fem_anim.scene import load_scene

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                reason="serial: compares the rank-0 input arrays")

ANGLES = ([30.0, 45.0, 0.0], [0.0, 40.0, 70.0], [25.0, -50.0, 110.0], [90.0, 90.0, 0.0])

SCENE = """
name = "placed"
[[body]]
name = "still"
mesh = {{ shape = "box", size = [0.2, 0.1, 0.1], divisions = [2, 1, 1] }}
[[body]]
name = "turned"
rotation = {rotation}
offset = {offset}
mesh = {{ shape = "box", size = [0.3, 0.2, 0.1], divisions = [3, 2, 1] }}
"""


@pytest.mark.parametrize("angles", ANGLES)
def test_rotation_matrix_is_scipys_extrinsic_xyz(angles):
    expected = Rotation.from_euler("xyz", angles, degrees=True).as_matrix()
    np.testing.assert_allclose(rotation_matrix(angles, 3), expected, atol=1e-14)


@pytest.mark.parametrize("angle", (17.0, -120.0))
def test_rotation_in_2d_turns_counterclockwise_about_z(angle):
    expected = Rotation.from_euler("z", angle, degrees=True).as_matrix()[:2, :2]
    np.testing.assert_allclose(rotation_matrix([angle], 2), expected, atol=1e-14)


@pytest.mark.parametrize("angles", ANGLES[:3])
def test_placed_vertices_of_a_turned_body(tmp_path, angles):
    """The scene mesh's vertices of the second body are SciPy's rotation of its box plus the
    offset; the first body's are its box, untouched."""
    offset = [0.7, -0.4, 0.25]
    path = tmp_path / "placed.toml"
    path.write_text(SCENE.format(rotation=angles, offset=offset))
    domain = build_scene_mesh(MPI.COMM_WORLD, load_scene(path))
    still, _ = structured_box([0.2, 0.1, 0.1], [2, 1, 1])
    turned, _ = structured_box([0.3, 0.2, 0.1], [3, 2, 1])
    expected = Rotation.from_euler("xyz", angles, degrees=True).apply(turned) + offset
    points, cells, markers = domain.points, domain.cells, domain.cell_markers
    for marker, want in ((1, still), (2, expected)):
        got = points[np.unique(cells[markers == marker])]
        # same set of points (vertex order of the union is the bodies' order)
        order = np.lexsort(np.round(got, 9).T)
        want_order = np.lexsort(np.round(want, 9).T)
        np.testing.assert_allclose(got[order], want[want_order], atol=1e-12)
