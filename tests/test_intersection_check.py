"""The independent intersection check (:mod:`fem_anim.contact.intersection`) sees a crossing.

Every contact test asks this check that *no* frame crosses; a check that always answered
"none" would pass them all. Here it is given frames with known answers: two unit
tetrahedra apart (no crossing), one pushed through the other (a crossing), and apart again;
and a cube of six tetrahedra, whose boundary must be its 12 outer triangles (interior faces
shared by two cells are not surface). A body wholly inside another has no crossing: a
small box inside a big one, a sheet inside a cube (P1 and P2 cells) must be reported, the
same just outside or resting on a face must not.
"""

from __future__ import annotations

import numpy as np
import pytest

from fem_anim.contact.intersection import (boundary_triangles, crossed_frames, crossing_pairs,
                                           enclosed_vertices, intersecting, solid_bodies,
                                           surface_components, winding_numbers)
from fem_anim.meshes.sheet import structured_sheet
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


# A body wholly inside another: no crossing, found by the winding number of the other's
# closed boundary at its vertices (fem_anim.contact.intersection.enclosed_vertices).


def _boxes(shift, small=0.2, n=2):
    """A unit box (n^3 Kuhn cubes) and a small box (one cube) at ``shift``, one tet mesh."""
    big_points, big_cells = structured_box([1.0, 1.0, 1.0], [n, n, n])
    points, cells = structured_box([small] * 3, [1, 1, 1])
    return (np.concatenate([big_points, points + shift]),
            np.concatenate([big_cells, cells + len(big_points)]))


def _quadratic(points, cells):
    """The same tetrahedra with a node at each edge midpoint (tetra10 order)."""
    pairs = [(0, 1), (1, 2), (0, 2), (0, 3), (1, 3), (2, 3)]
    edges = np.sort(cells[:, pairs].reshape(-1, 2), axis=1)
    unique, inverse = np.unique(edges, axis=0, return_inverse=True)
    mids = points[unique].mean(axis=1)
    nodes = len(points) + inverse.reshape(len(cells), 6)
    return np.concatenate([points, mids]), np.concatenate([cells, nodes], axis=1)


@pytest.mark.parametrize("degree", [1, 2])
def test_a_box_inside_a_box_is_found_and_one_outside_is_not(degree):
    """A small box wholly inside a bigger one (0.3 from every face: no crossing) is an
    intersection; the same box 1 mm outside a face is not, nor one with a face lying on the
    big box's face from outside (touching, within the tolerance); 1 mm inside a face it is;
    with a face on it from inside, the vertices on the face are not inside, the others are.
    Quadratic cells: their faces split at the edge nodes."""
    cases = {(0.4, 0.4, 0.4): True, (1.001, 0.4, 0.4): False, (0.799, 0.4, 0.4): True}
    for shift, inside in cases.items():
        points, cells = _boxes(shift)
        if degree == 2:
            points, cells = _quadratic(points, cells)
        F = boundary_triangles(cells)
        assert len(crossing_pairs(points, F)) == 0  # no crossing for the old check to see
        assert (crossed_frames(points, cells, [np.zeros_like(points)]) == [0]) == inside
    points, cells = _boxes((1.0, 0.4, 0.4))  # touching from outside: on, not in
    assert len(enclosed_vertices(points, boundary_triangles(cells))) == 0
    points, cells = _boxes((0.8, 0.4, 0.4))
    found = enclosed_vertices(points, boundary_triangles(cells))
    assert np.all(np.isclose(points[found, 0], 0.8))  # the 4 at x = 0.8, not those on x = 1
    assert len(found) == 4


def test_the_winding_number_is_one_inside_whatever_the_triangle_order():
    """The pieces are oriented from the soup alone: a box's boundary with rows permuted at
    random has |w| = 1 at interior points, 0 outside, and is one closed piece; a sheet is an
    open piece."""
    rng = np.random.default_rng(1)
    points, cells = structured_box([1.0, 1.0, 1.0], [2, 2, 2])
    F = boundary_triangles(cells)
    F = np.array([rng.permutation(row) for row in F])
    oriented, piece, closed = surface_components(F)
    assert closed.tolist() == [True] and np.all(piece == 0)
    q = rng.uniform(0.05, 0.95, (20, 3))
    assert np.allclose(np.abs(winding_numbers(points, oriented, q)), 1.0, atol=1e-12)
    assert np.allclose(winding_numbers(points, oriented, q + [1.2, 0.0, 0.0]), 0.0, atol=1e-12)
    sheet_points, sheet_cells = structured_sheet([1.0, 1.0], [2, 2], triangulation="right")
    assert surface_components(sheet_cells)[2].tolist() == [False]


def test_a_sheet_inside_a_cube_is_found_and_one_resting_on_it_is_not():
    """A sheet (an open piece: it contains nothing) wholly inside a cube, 0.2 from every
    face, is an intersection of the soup of the cube's boundary and the sheet; the sheet a
    thickness t above the top face is not; a sheet through the cube is (a crossing)."""
    cube_points, cube_cells = structured_box([1.0, 1.0, 1.0], [2, 2, 2])
    sheet_points, sheet_cells = structured_sheet([0.6, 0.6], [3, 3], triangulation="right")
    sheet_points = np.c_[sheet_points[:, :2], np.zeros(len(sheet_points))]
    soup = np.concatenate([boundary_triangles(cube_cells), sheet_cells + len(cube_points)])
    t = 1e-3
    for lift, expected in (((0.2, 0.2, 0.5), True), ((0.2, 0.2, 1.0 + t), False),
                           ((-0.2, 0.2, 0.5), True)):
        x = np.concatenate([cube_points, sheet_points + lift])
        assert intersecting(x, soup) == expected
    x = np.concatenate([cube_points, sheet_points + (0.2, 0.2, 0.5)])
    assert len(crossing_pairs(x, soup)) == 0
    assert np.all(enclosed_vertices(x, soup) >= len(cube_points))
    assert len(enclosed_vertices(x, soup)) == len(sheet_points)


def test_only_vertices_in_a_bodys_bounding_box_get_its_winding_number(monkeypatch):
    """The bounding-box prefilter keeps large frames cheap: for a small box 1 mm beside a
    big one no winding number is evaluated at all; lowered 0.1 into the big one's top, only
    its 4 bottom vertices (in the big box's box) and the big box's vertex at the centre of
    its top face (in the small box's box) are, and all 5 are inside the other body."""
    from fem_anim.contact import intersection

    evaluated = []
    real = intersection.winding_numbers

    def spy(x, triangles, q):
        evaluated.append(len(q))
        return real(x, triangles, q)

    monkeypatch.setattr(intersection, "winding_numbers", spy)
    points, cells = _boxes((1.001, 0.4, 0.4))
    assert len(enclosed_vertices(points, boundary_triangles(cells))) == 0
    assert sum(evaluated) == 0
    points, cells = _boxes((0.4, 0.4, 0.9))  # 0.9 < z < 1.1: half in the big box
    found = enclosed_vertices(points, boundary_triangles(cells))
    assert sorted(evaluated) == [1, 4] and len(found) == 5
    assert np.allclose(points[found], [[0.5, 0.5, 1.0]] + [[a, b, 0.9] for a in (0.4, 0.6)
                                                           for b in (0.4, 0.6)])


def _hollow_box():
    """A unit box of 5^3 Kuhn cubes with the middle cube (0.4 < x, y, z < 0.6) left out:
    two closed pieces of one body, the outer surface and the cavity's."""
    points, cells = structured_box([1.0, 1.0, 1.0], [5, 5, 5])
    middle = np.all(np.abs(points[cells].mean(axis=1) - 0.5) < 0.1, axis=1)
    return points, cells[~middle]


def test_a_body_in_a_cavity_is_outside_and_one_in_the_material_is_inside():
    """The cavity's surface lies inside the body's outer surface: grouped into one body by
    the cells (:func:`solid_bodies`, outer piece outward, cavity inward) it encloses nothing,
    and a small box in the cavity is not inside the body; the same box in the material
    (0.05 to 0.15 from the corner, crossing no face) is."""
    points, cells = _hollow_box()
    F = boundary_triangles(cells)
    components = surface_components(F)
    assert components[2].tolist() == [True, True]
    assert solid_bodies(cells, F, components[1]).tolist() == [0, 0]
    assert crossed_frames(points, cells, [np.zeros_like(points)]) == []
    assert len(enclosed_vertices(points, F)) > 0  # pieces taken apart: the cavity is "in"
    small_points, small_cells = structured_box([0.1, 0.1, 0.1], [1, 1, 1])
    for shift, inside in (((0.45, 0.45, 0.45), False), ((0.05, 0.05, 0.05), True)):
        x = np.concatenate([points, small_points + shift])
        both = np.concatenate([cells, small_cells + len(points)])
        assert (crossed_frames(x, both, [np.zeros_like(x)]) == [0]) == inside
