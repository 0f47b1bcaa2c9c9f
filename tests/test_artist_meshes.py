"""Artists' surfaces in: open, duplicated, overlapping triangle soups become simulated bodies
(:mod:`fem_anim.mesh.surface_repair`), with ``mesh.units``, ``mesh.scale`` and ``mesh.fill``.

The broken surfaces in ``tests/data/``: an icosphere of radius 0.1 m with four triangles
removed (``sphere_with_hole.obj``; ``sphere_closed.obj`` is the whole one), a 0.2 x 0.1 x
0.1 m box with three triangles given twice and one given again reversed
(``box_duplicated_faces.stl``), two boxes of 0.002 m^3 each overlapping in 0.0007 m^3
(``overlapping_boxes.ply``), a single triangle and a file of zero-area triangles.
"""

from __future__ import annotations

from pathlib import Path

import meshio
import numpy as np
import pytest

import fem_anim
from fem_anim.contact.intersection import boundary_triangles, crossed_frames
from fem_anim.errors import MeshError, SceneError
from fem_anim.mesh import surface_repair
from fem_anim.mesh.build import mesh_arrays
from fem_anim.mesh.mesh_file import read_mesh_file

DATA = Path(__file__).resolve().parent / "data"


def _closed_volume(path: Path) -> float:
    """The volume a closed, consistently wound triangle surface bounds (divergence theorem)."""
    m = meshio.read(path)
    X = m.points[m.cells_dict["triangle"]]
    return abs(np.einsum("ij,ij->i", X[:, 0], np.cross(X[:, 1], X[:, 2])).sum()) / 6.0


def _volumes(points: np.ndarray, tets: np.ndarray) -> np.ndarray:
    a, b, c, d = (points[tets[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


@pytest.fixture(autouse=True)
def _own_cache(tmp_path_factory, monkeypatch):
    """Each test meshes afresh into a cache folder of its own."""
    monkeypatch.setenv("FEM_ANIM_CACHE", str(tmp_path_factory.mktemp("cache")))


#: Each surface, the volume of the closed solid it stands for, and the tolerance: fTetWild
#: keeps the surface within an envelope of 1e-3 of the bounding box diagonal.
BROKEN = {
    "sphere_with_hole.obj": (lambda: _closed_volume(DATA / "sphere_closed.obj"), 2e-3),
    "box_duplicated_faces.stl": (lambda: 0.2 * 0.1 * 0.1, 1e-3),
    "overlapping_boxes.ply": (lambda: 2 * 0.002 - 0.1 * 0.07 * 0.1, 1e-3),
}


@pytest.mark.parametrize("name", sorted(BROKEN))
def test_broken_surface_is_filled(name, tmp_path, monkeypatch):
    """Positive tetrahedra, the closed surface's volume, a closed skin without crossings;
    no file left in the working directory (fTetWild writes one into its own)."""
    reference, rtol = BROKEN[name]
    monkeypatch.chdir(tmp_path)
    points, tets, markers, _ = read_mesh_file(DATA / name, 3, 0.04)
    assert list(tmp_path.iterdir()) == []
    volumes = _volumes(points, tets)
    assert volumes.min() > 0.0 and (markers == 1).all()
    assert volumes.sum() == pytest.approx(reference(), rel=rtol)
    skin = boundary_triangles(tets)
    edges = np.sort(skin[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()  # closed and manifold
    assert crossed_frames(points, tets, [np.zeros_like(points)]) == []


def test_broken_surface_becomes_a_simulated_body(tmp_path):
    """The holed sphere, thrown at the ground: a few frames, every tetrahedron's volume
    positive, no crossing, its rest volume the closed sphere's."""
    scene = fem_anim.Scene.from_dict({
        "name": "holed", "mesh": {"shape": "file", "file": str(DATA / "sphere_with_hole.obj"),
                                  "element_size": 0.05},
        "material": {"youngs_modulus": 5.0e4},
        "time": {"dt": 1 / 48, "steps": 4}, "output": {"render": False, "fps": 24},
        "gravity": {"acceleration": [0.0, 0.0, -9.81]},
        "initial": {"velocity": [0.5, 0.0, -1.0]},
        "obstacle": [{"type": "plane", "point": [0.0, 0.0, -0.11], "normal": [0, 0, 1]}]})
    with fem_anim.run(scene, tmp_path / "out") as run:
        points, cells = run.points, run.cells
        frames = [run.displacement(k) for k in range(len(run.times))]
    assert len(frames) == 3
    assert _volumes(points, cells).sum() == pytest.approx(
        _closed_volume(DATA / "sphere_closed.obj"), rel=2e-3)
    for u in frames:
        assert _volumes(points + u, cells).min() > 0.0
    assert crossed_frames(points, cells, frames) == []
    assert np.abs(frames[-1]).max() > 1e-3


@pytest.mark.parametrize("name, reason", [
    ("one_triangle.obj", "lie in one plane and enclose no volume"),
    ("degenerate_faces.obj", "4 of its 4 triangles have zero area"),
])
def test_garbage_is_one_clear_error(name, reason):
    with pytest.raises(MeshError) as err:
        read_mesh_file(DATA / name, 3, 0.04)
    message = str(err.value)
    assert "nothing usable is left" in message and reason in message and "\n" not in message


def test_garbage_from_the_command_line(tmp_path):
    """One line ``fem-anim: error: ...`` and exit code 2."""
    import subprocess

    from conftest import clean_environment, fem_anim_command

    scene = tmp_path / "garbage.toml"
    scene.write_text(f'[mesh]\nshape = "file"\nfile = "{DATA / "one_triangle.obj"}"\n')
    r = subprocess.run([*fem_anim_command(), "run", str(scene), "-q", "-o",
                        str(tmp_path / "out")], capture_output=True, text=True,
                       env=clean_environment())
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1
    assert lines[0].startswith("fem-anim: error: ") and "nothing usable is left" in lines[0]


def test_a_crash_inside_ftetwild_is_an_error(monkeypatch):
    """fTetWild ends its process on zero-area triangles: here let them through, and the
    crash of the child process is one MeshError, not the end of this one."""
    monkeypatch.setattr(surface_repair, "clean_triangles", lambda p, t, s: t)
    points = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    with pytest.raises(MeshError, match="fTetWild failed"):
        surface_repair.repair_surface_to_tets(points, np.array([[0, 1, 2]]), 0.03, "soup")


def test_fill_modes():
    """``auto`` keeps gmsh for a closed clean surface; ``gmsh`` refuses a broken one, naming
    ``mesh.fill``; ``tetwild`` fills a closed one too."""
    closed, holed = DATA / "sphere_closed.obj", DATA / "sphere_with_hole.obj"
    auto = read_mesh_file(closed, 3, 0.04)
    gmsh = read_mesh_file(closed, 3, 0.04, fill="gmsh")
    assert np.array_equal(auto[0], gmsh[0]) and np.array_equal(auto[1], gmsh[1])
    with pytest.raises(MeshError, match='mesh.fill = "tetwild"'):
        read_mesh_file(holed, 3, 0.04, fill="gmsh")
    points, tets, _, _ = read_mesh_file(closed, 3, 0.04, fill="tetwild")
    assert _volumes(points, tets).sum() == pytest.approx(_closed_volume(closed), rel=2e-3)


def test_units_and_scale(tmp_path):
    """Coordinates in cm are metres / 100; ``mesh.scale`` multiplies them after the unit;
    a surface is scaled before it is filled (``element_size`` is in metres)."""
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1]])
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    meshio.write(tmp_path / "tets.vtu", meshio.Mesh(points * 100, [("tetra", tets)]))
    cfg = {"shape": "file", "file": "tets.vtu", "dim": 3, "element_size": 0.5}
    cm = mesh_arrays(cfg | {"units": "cm"}, tmp_path)
    np.testing.assert_allclose(cm[0], points, rtol=1e-15)
    scaled = mesh_arrays(cfg | {"units": "mm", "scale": 20.0}, tmp_path)
    np.testing.assert_allclose(scaled[0], 2 * points, rtol=1e-15)
    closed = meshio.read(DATA / "sphere_closed.obj")  # 0.1 m, written in km
    meshio.write(tmp_path / "km.obj", meshio.Mesh(closed.points / 1000, closed.cells))
    surface = {"shape": "file", "dim": 3, "element_size": 0.04}
    km = mesh_arrays(surface | {"file": "km.obj", "units": "km"}, tmp_path)
    metres = mesh_arrays(surface | {"file": "sphere_closed.obj"}, DATA)
    assert len(km[1]) == len(metres[1])
    np.testing.assert_allclose(km[0], metres[0], atol=1e-12)
    with pytest.raises(SceneError, match="mesh.units"):
        fem_anim.Scene.from_dict({"mesh": {"units": "inch"}})


def test_glb_is_read(tmp_path):
    """A binary glTF of the holed sphere (trimesh; float32 coordinates): the OBJ's surface up
    to float32 round-off, filled to the closed sphere's volume."""
    import trimesh

    from fem_anim.mesh.mesh_file import _read_trimesh

    m = meshio.read(DATA / "sphere_with_hole.obj")
    glb = tmp_path / "holed.glb"
    trimesh.Trimesh(m.points, m.cells_dict["triangle"], process=False).export(glb)
    surface = _read_trimesh(glb)
    np.testing.assert_allclose(surface.points, m.points, rtol=0, atol=1e-7)
    assert np.array_equal(surface.cells_dict["triangle"], m.cells_dict["triangle"])
    points, tets, _, _ = read_mesh_file(glb, 3, 0.04)
    assert _volumes(points, tets).min() > 0.0
    assert _volumes(points, tets).sum() == pytest.approx(
        _closed_volume(DATA / "sphere_closed.obj"), rel=2e-3)


def test_a_surface_gives_the_same_tetrahedra_again():
    """fTetWild is not deterministic; the cache makes a second read (a run again, a resume)
    give the same tetrahedra, and a damaged cache file is meshed again."""
    holed = DATA / "sphere_with_hole.obj"
    first = read_mesh_file(holed, 3, 0.04)
    files = list(surface_repair.cache_folder().glob("tetwild-*.npz"))
    assert len(files) == 1
    again = read_mesh_file(holed, 3, 0.04)
    assert np.array_equal(first[0], again[0]) and np.array_equal(first[1], again[1])
    files[0].write_bytes(b"not a zip file")
    remeshed = read_mesh_file(holed, 3, 0.04)
    assert _volumes(remeshed[0], remeshed[1]).min() > 0.0
    assert files[0].stat().st_size > 1000  # written again
