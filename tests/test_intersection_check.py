"""The independent intersection check (:mod:`fem_anim.contact.intersection`) sees a crossing.

Every contact test asks this check that *no* frame crosses; a check that always answered
"none" would pass them all. Here it is given frames with known answers: two unit
tetrahedra apart (no crossing), one pushed through the other (a crossing), and apart again;
and a cube of six tetrahedra, whose boundary must be its 12 outer triangles (interior faces
shared by two cells are not surface).
"""

from __future__ import annotations

import numpy as np

from fem_anim.contact.intersection import boundary_triangles, crossed_frames
from fem_anim.meshes.structured import structured_box

TET = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])


def two_tets():
    points = np.concatenate([TET, TET + [2.0, 0.0, 0.0]])
    cells = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    return points, cells


def test_a_planted_crossing_is_found_and_only_there():
    points, cells = two_tets()
    apart = np.zeros_like(points)
    through = apart.copy()
    through[4:] = [-1.8, 0.1, 0.1]  # the second tetrahedron pushed into the first
    touching_not = apart.copy()
    touching_not[4:] = [-0.9, 0.0, 0.0]  # 0.1 apart along x: near, not crossing
    assert crossed_frames(points, cells, [apart, through, touching_not, through]) == [1, 3]


def test_a_vertex_pushed_through_a_face_of_its_own_body():
    """Self-intersection of one body: a cube's corner folded through the opposite face."""
    points, cells = structured_box([1.0, 1.0, 1.0], [1, 1, 1])
    corner = int(np.argmin(np.linalg.norm(points - [1.0, 1.0, 1.0], axis=1)))
    folded = np.zeros_like(points)
    folded[corner] = [-1.5, -0.5, -0.5]  # (1,1,1) -> (-0.5,0.5,0.5): out through x = 0
    assert crossed_frames(points, cells, [np.zeros_like(points), folded]) == [1]


def test_the_surface_of_a_cube_of_six_tetrahedra():
    points, cells = structured_box([1.0, 1.0, 1.0], [1, 1, 1])
    F = boundary_triangles(cells)
    assert F.shape == (12, 3)
    centroids = points[F].mean(axis=1)
    on_face = np.isclose(centroids, 0.0) | np.isclose(centroids, 1.0)
    assert np.all(on_face.sum(axis=1) == 1)  # every surface triangle lies on a face
