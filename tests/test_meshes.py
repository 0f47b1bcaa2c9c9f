"""Meshes a user asks for: gmsh primitives, mesh files, closed surfaces, and bad meshes.

Volumes are summed in numpy over the same points and cells DOLFINx is given and compared
with the analytic ones: curved boundaries are inscribed polygons, so the relative shortfall
is about ``(h / rho)^2 / 3`` for element size ``h`` and smallest radius of curvature
``rho``; the tolerance is ``(h / rho)^2 / 2``.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import gmsh
import meshio
import numpy as np
import pytest
from conftest import ROOT, clean_environment, fem_anim_command
from mpi4py import MPI

from fem_anim import meshes
from fem_anim.cli import main
from fem_anim.errors import MeshError, SceneError
from fem_anim.mesh.build import build_mesh
from fem_anim.mesh.checks import cell_volumes, check_cells, check_surface
from fem_anim.mesh.simplex import mesh_from_arrays
from fem_anim.reference.box_mesh import box_mesh
from fem_anim.scene import load_scene
from fem_anim.scene.schema import MESH_SHAPES, SCHEMA

DATA = ROOT / "meshes" / "data"
sys.path.insert(0, str(DATA))
from make_examples import cube_surface  # noqa: E402 (the examples script lives with its data)

R, L, r = 0.1, 0.3, 0.04  # radius, length, minor radius (m)
PRIMITIVES = ("sphere", "cylinder", "torus", "capsule")


def analytic(shape: str, dim: int) -> tuple[float, np.ndarray]:
    """Volume (area in 2D) and centroid offset from ``mesh.origin`` of each primitive."""
    volume = {3: {"sphere": 4 / 3 * math.pi * R**3, "cylinder": math.pi * R**2 * L,
                  "torus": 2 * math.pi**2 * R * r**2,
                  "capsule": math.pi * R**2 * L + 4 / 3 * math.pi * R**3},
              2: {"sphere": math.pi * R**2, "cylinder": 2 * R * L, "torus": 4 * math.pi * R * r,
                  "capsule": 2 * R * L + math.pi * R**2}}[dim][shape]
    along_x = shape in ("cylinder", "capsule")
    return volume, np.eye(dim)[0] * (L / 2 if along_x else 0.0)


def scene_with(*sets: str, dim: int = 3):
    """The default scene with ``--set`` style overrides (2D size, gravity, pin if dim = 2)."""
    extra = ["mesh.dim=2", "mesh.size=[1.0, 0.2]", "gravity.acceleration=[0, -9.81]",
             "pin.0.min=[-1, -1]", "pin.0.max=[1, 1]"] if dim == 2 else []
    return load_scene(None, extra + list(sets))


def volumes(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    d = points.shape[1]
    return np.abs(np.linalg.det(points[cells[:, 1:]] - points[cells[:, :1]])) / math.factorial(d)


def surface_volume(points: np.ndarray, triangles: np.ndarray) -> float:
    """Volume enclosed by an outward-oriented closed surface (divergence theorem, x . n / 3)."""
    a, b, c = (points[triangles[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def build(scene):
    return build_mesh(MPI.COMM_SELF, scene)


# --- gmsh primitives -------------------------------------------------------------------------

@pytest.mark.parametrize("dim", [3, 2])
@pytest.mark.parametrize("shape", PRIMITIVES)
def test_primitive_volume_and_position(shape, dim):
    rho = r if shape == "torus" else R
    h = rho / 4
    origin = [0.5, -0.2, 0.3][:dim]
    domain = build(scene_with(f'mesh.shape="{shape}"', f"mesh.radius={R}", f"mesh.length={L}",
                              f"mesh.minor_radius={r}", f"mesh.element_size={h}",
                              f"mesh.origin={origin}", dim=dim))
    assert domain.dim == dim and domain.points.shape[1] == dim
    check_cells(domain.points, domain.cells, shape)
    w = volumes(domain.points, domain.cells)
    exact, offset = analytic(shape, dim)
    assert abs(w.sum() / exact - 1) < 0.5 * (h / rho) ** 2, (w.sum(), exact)
    if dim == 3:  # inscribed in a convex-curved boundary
        assert w.sum() < exact
    centroid = (w[:, None] * domain.points[domain.cells].mean(axis=1)).sum(axis=0) / w.sum()
    np.testing.assert_allclose(centroid, np.array(origin) + offset, atol=1e-3 * R)
    assert set(domain.cell_markers) == {1}  # the "body" group


BOUNDARY_GROUPS = {
    ("box", 3): {"surface", "xmin", "xmax", "ymin", "ymax", "zmin", "zmax"},
    ("box", 2): {"surface", "xmin", "xmax", "ymin", "ymax"},
    ("sphere", 3): {"surface"}, ("sphere", 2): {"surface"},
    ("cylinder", 3): {"surface", "xmin", "xmax", "side"},
    ("cylinder", 2): {"surface", "xmin", "xmax", "side"},
    ("capsule", 3): {"surface", "xmin", "xmax", "side"},
    ("capsule", 2): {"surface", "xmin", "xmax", "side"},
    ("torus", 3): {"surface"}, ("torus", 2): {"surface", "outer", "inner"},
}


@pytest.mark.parametrize("shape, dim", list(BOUNDARY_GROUPS))
def test_builders_name_their_groups(shape, dim):
    mesh = dict(scene_with(dim=dim)["mesh"], shape=shape, radius=R, length=L, minor_radius=r,
                element_size=R / 2, size=[0.4, 0.2, 0.1][:dim], origin=[0.1, 0.2, 0.3][:dim])
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        model = meshes.BUILDERS[shape](gmsh.model, mesh)
        groups = {model.getPhysicalName(d, g): (d, g) for d, g in model.getPhysicalGroups()}
        assert groups.pop("body") == (dim, 1)
        assert set(groups) == BOUNDARY_GROUPS[shape, dim]
        assert all(d == dim - 1 for d, _ in groups.values())
        assert groups["surface"] == (dim - 1, 1)
        nodes = {name: model.mesh.getNodesForPhysicalGroup(*dg)[1].reshape(-1, 3)
                 for name, dg in groups.items()}
        for name, x in nodes.items():
            assert len(x) > 0, name
        if "xmin" in nodes:  # end faces at x = ox and ox + length; caps beyond them
            ox, length = 0.1, {"box": 0.4, "cylinder": L, "capsule": L}[shape]
            cap = R if shape == "capsule" else 0.0
            xmin, xmax = nodes["xmin"][:, 0], nodes["xmax"][:, 0]
            assert np.all((xmin >= ox - cap - 1e-9) & (xmin <= ox + 1e-9))
            assert np.all((xmax >= ox + length - 1e-9) & (xmax <= ox + length + cap + 1e-9))
            side = nodes["side"][:, 0] if "side" in nodes else xmin
            assert np.all((side >= ox - 1e-9) & (side <= ox + length + 1e-9))
    finally:
        gmsh.finalize()


def test_registry_matches_the_scene_schema():
    assert set(meshes.BUILDERS) == set(MESH_SHAPES) - {"file"}
    for shape, keys in meshes.BUILDER_KEYS.items():
        assert set(keys) <= set(SCHEMA["mesh"]), shape


def test_torus_tube_crossing_its_axis_is_rejected_with_the_scene():
    with pytest.raises(SceneError, match=r"mesh.minor_radius must be < mesh.radius = 0.1"):
        build(scene_with('mesh.shape="torus"', "mesh.radius=0.1", "mesh.minor_radius=0.1"))


# --- files -----------------------------------------------------------------------------------

def test_two_region_msh_reads_with_its_physical_groups():
    domain = build(scene_with('mesh.shape="file"', f'mesh.file="{DATA / "two_region_box.msh"}"'))
    assert set(domain.cell_markers) == {1, 2}
    x = domain.points[domain.cells].mean(axis=1)[:, 0]
    assert np.all(x[domain.cell_markers == 1] < 0.1) and np.all(x[domain.cell_markers == 2] > 0.1)
    assert volumes(domain.points, domain.cells).sum() == pytest.approx(0.2 * 0.1 * 0.1, rel=1e-12)
    assert domain.mesh.topology.index_map(3).size_global == len(domain.cells) == 200


def test_relative_mesh_file_is_found_next_to_the_scene(tmp_path):
    scene_file = tmp_path / "scene.toml"
    scene_file.write_text('[mesh]\nshape = "file"\nfile = "box.msh"\n')
    (tmp_path / "box.msh").write_bytes((DATA / "two_region_box.msh").read_bytes())
    assert len(build(load_scene(scene_file)).cells) == 200


def test_2d_file_takes_triangles_in_a_plane(tmp_path):
    points, cells = box_mesh((3, 2), (0.3, 0.2))
    pad = np.hstack([points, np.full((len(points), 1), 0.5)])
    extra = np.array([[9.0, 9.0, 9.0]])  # a stray point no cell uses: dropped
    path = tmp_path / "plate.vtu"
    meshio.write(path, meshio.Mesh(np.vstack([pad, extra]), [("triangle", cells),
                                                             ("line", cells[:2, :2])]))
    domain = build(scene_with('mesh.shape="file"', f'mesh.file="{path}"', dim=2))
    assert domain.points.shape == (len(points), 2) and len(domain.cells) == len(cells)
    assert volumes(domain.points, domain.cells).sum() == pytest.approx(0.06)

    with pytest.raises(MeshError, match="is a plane triangle mesh without tetrahedra; set "
                                        "mesh.dim = 2"):
        build(scene_with('mesh.shape="file"', f'mesh.file="{path}"'))

    pad[0, 2] = 0.6  # lift one vertex out of the plane
    meshio.write(path, meshio.Mesh(pad, [("triangle", cells)]))
    with pytest.raises(MeshError, match="do not lie in a plane z = const"):
        build(scene_with('mesh.shape="file"', f'mesh.file="{path}"', dim=2))


def test_second_order_tetrahedra_are_read_by_their_corners(tmp_path):
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        meshes.BUILDERS["box"](gmsh.model, {"size": [0.2, 0.1, 0.1], "element_size": 0.05,
                                     "origin": None})
        gmsh.model.mesh.setOrder(2)
        gmsh.write(str(tmp_path / "p2.msh"))
    finally:
        gmsh.finalize()
    domain = build(scene_with('mesh.shape="file"', f'mesh.file="{tmp_path / "p2.msh"}"'))
    assert volumes(domain.points, domain.cells).sum() == pytest.approx(0.002, rel=1e-12)


@pytest.mark.parametrize("name, h", [("cube.stl", 0.05), ("icosphere.stl", 0.025)])
def test_closed_surface_is_filled_with_tetrahedra(name, h):
    surface = meshio.read(DATA / name)
    enclosed = surface_volume(surface.points.astype(float), surface.cells[0].data)
    domain = build(scene_with('mesh.shape="file"', f'mesh.file="{DATA / name}"',
                              f"mesh.element_size={h}"))
    w = volumes(domain.points, domain.cells)
    if name == "cube.stl":  # flat faces: the volume is kept exactly
        assert w.sum() == pytest.approx(enclosed, rel=1e-9)
    else:  # remeshed on the input triangles: chords across the curved surface
        assert abs(w.sum() / enclosed - 1) < 0.5 * (h / 0.1) ** 2
    assert set(domain.cell_markers) == {1}
    lo, hi = surface.points.min(axis=0), surface.points.max(axis=0)
    assert np.all(domain.points >= lo - 1e-7) and np.all(domain.points <= hi + 1e-7)
    edges = domain.points[domain.cells][:, [0, 0, 0, 1, 1, 2]] - \
        domain.points[domain.cells][:, [1, 2, 3, 2, 3, 3]]
    assert np.median(np.linalg.norm(edges, axis=2)) < 1.5 * h  # element_size is followed


def write_surface(path: Path, points, triangles) -> Path:
    meshio.write(path, meshio.Mesh(np.asarray(points, float), [("triangle", triangles)]))
    return path


CUBE_POINTS, CUBE_TRIANGLES = cube_surface(0.2)
TET = np.array([[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]])  # on vertices 0, 1, 2, 3
E = np.eye(3)
BAD_SURFACES = {
    "open": (CUBE_POINTS, CUBE_TRIANGLES[1:]),
    "edge": (np.vstack([np.zeros(3), E, -E[1], -E[2]]),  # two tetrahedra sharing edge 0-1
             np.vstack([TET, [[0, 4, 1], [0, 1, 5], [1, 4, 5], [0, 5, 4]]])),
    "vertex": (np.vstack([np.zeros(3), E, -E]),  # two tetrahedra sharing vertex 0
               np.vstack([TET, [[0, 5, 4], [0, 4, 6], [4, 5, 6], [0, 6, 5]]])),
    "parts": (np.vstack([CUBE_POINTS, CUBE_POINTS + 1]),
              np.vstack([CUBE_TRIANGLES, CUBE_TRIANGLES + 8])),
}
SURFACE_MESSAGES = {
    "open": r"the surface is open \(3 edges belong to one triangle only, e\.g\. the edge from "
            r"vertex \d+ \(.*\) to vertex \d+",
    "edge": r"the surface is not manifold: the edge from vertex \d \(0, 0, 0\) to vertex \d "
            r"\(1, 0, 0\) belongs to 4 triangles",
    "vertex": r"the surface is not manifold at vertex \d \(0, 0, 0\), where 2 separate sheets",
    "parts": r"the surface has 2 separate parts",
}


@pytest.mark.parametrize("defect", list(BAD_SURFACES))
def test_bad_surfaces_are_rejected_before_gmsh(tmp_path, defect):
    points, triangles = BAD_SURFACES[defect]
    with pytest.raises(MeshError, match=SURFACE_MESSAGES[defect]):
        check_surface(points, triangles, "surface")
    path = write_surface(tmp_path / f"{defect}.stl", points, triangles)
    with pytest.raises(MeshError, match=f"mesh file {path}: " + SURFACE_MESSAGES[defect]):
        build(scene_with('mesh.shape="file"', f'mesh.file="{path}"', 'mesh.fill="gmsh"'))


def test_closed_surface_needs_no_consistent_orientation(tmp_path):
    points, triangles = cube_surface(0.2)
    triangles[::2] = triangles[::2, ::-1]
    check_surface(points, triangles, "cube")
    path = write_surface(tmp_path / "flipped.obj", points, triangles)
    domain = build(scene_with('mesh.shape="file"', f'mesh.file="{path}"'))
    assert volumes(domain.points, domain.cells).sum() == pytest.approx(0.008, rel=1e-12)


def test_self_intersecting_surface_is_a_gmsh_error_naming_the_file(tmp_path):
    points, triangles = cube_surface(0.2)
    points[7] = [-0.1, 0.1, 0.1]  # the corner (0.2, 0.2, 0.2) pushed through the cube
    path = write_surface(tmp_path / "folded.stl", points, triangles)
    with pytest.raises(MeshError, match=f"mesh file {path}: gmsh failed: .*intersect"):
        build(scene_with('mesh.shape="file"', f'mesh.file="{path}"', 'mesh.fill="gmsh"'))


@pytest.mark.parametrize("content, suffix, message", [
    (None, ".msh", "does not exist"),
    (b"this is not a mesh\n", ".msh", "cannot be read"),
    (b"\x00\x01garbage", ".vtu", "cannot be read"),
    (b"1 2 3\n", ".xyz", "cannot be read"),
])
def test_unreadable_files(tmp_path, content, suffix, message):
    path = tmp_path / f"mesh{suffix}"
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(MeshError, match=f"mesh file {path}.* {message}"):
        build(scene_with('mesh.shape="file"', f'mesh.file="{path}"'))


def test_file_without_cells_of_the_dimension(tmp_path):
    path = tmp_path / "lines.vtu"
    meshio.write(path, meshio.Mesh(np.eye(3), [("line", np.array([[0, 1], [1, 2]]))]))
    with pytest.raises(MeshError, match=f"mesh file {path} has no tetrahedron cells for "
                                        r"mesh.dim = 3 \(cell types found: line\)"):
        build(scene_with('mesh.shape="file"', f'mesh.file="{path}"'))
    with pytest.raises(MeshError, match="has no triangle cells for mesh.dim = 2"):
        build(scene_with('mesh.shape="file"', f'mesh.file="{path}"', dim=2))


# --- bad cells -------------------------------------------------------------------------------

def signed(points, cells):
    return np.linalg.det(points[cells[:, 1:]] - points[cells[:, :1]])


@pytest.mark.parametrize("d", [2, 3])
def test_mixed_orientation_is_accepted_and_integrates_right(d):
    """DOLFINx uses |det J| and outward normals J^{-T} n_ref: vertex order does not matter."""
    import ufl
    from dolfinx import fem

    points, cells = box_mesh((3,) * d, (0.3, 0.2, 0.1)[:d])
    flip = np.random.default_rng(1).random(len(cells)) < 0.5
    cells[flip, :2] = cells[flip, 1::-1]
    assert np.any(signed(points, cells) < 0) and np.any(signed(points, cells) > 0)
    domain = mesh_from_arrays(MPI.COMM_SELF, points, cells, None, "mixed")
    x, n = ufl.SpatialCoordinate(domain.mesh), ufl.FacetNormal(domain.mesh)
    volume = fem.assemble_scalar(fem.form(1.0 * ufl.dx(domain=domain.mesh)))
    flux = fem.assemble_scalar(fem.form(ufl.dot(x, n) * ufl.ds(domain=domain.mesh)))
    assert volume == pytest.approx(np.prod((0.3, 0.2, 0.1)[:d]), rel=1e-12)
    assert flux == pytest.approx(d * volume, rel=1e-12)  # div x = d: normals point outward


def folded_box():
    """A 4x4x4 Kuhn box with the interior vertex at (0.5, 0.5, 0.5) pushed past a neighbour."""
    points, cells = box_mesh((4, 4, 4))
    v = int(np.argmin(np.linalg.norm(points - 0.5, axis=1)))
    points[v] = [0.83, 0.61, 0.47]
    return points, cells


def bad(kind):
    points, cells = box_mesh((2, 2, 2), (0.2, 0.2, 0.2))
    if kind == "no cells":
        return points, cells[:0], "the mesh has no cells"
    if kind == "out of range":
        cells[5, 2] = len(points)
        return points, cells, f"cell 5 has vertex index {len(points)} out of range 0..26"
    if kind == "nan":
        points[7, 1] = np.nan
        return points, cells, r"vertex 7 has a NaN or infinite coordinate \(0, nan, 0.1\)"
    if kind == "unused vertex":
        return np.vstack([points, [1, 1, 1]]), cells, r"vertex 27 \(1, 1, 1\) belongs to no cell"
    if kind == "zero volume":
        points[cells[4, 3]] = points[cells[4, :3]].mean(axis=0)  # onto the opposite face
        return points, cells, r"cell \d+ \(vertices .*\) has zero volume"
    if kind == "duplicate":
        cells = np.vstack([cells, cells[3, ::-1]])
        return points, cells, rf"cell {len(cells) - 1} \(vertices .*\) duplicates cell 3"
    if kind == "inverted":
        points, cells = folded_box()
        return (points, cells,
                r"cell \d+ is inverted: it folds over cell \d+ across their shared face")
    raise ValueError(kind)


@pytest.mark.parametrize("kind", ["no cells", "out of range", "nan", "unused vertex",
                                  "zero volume", "duplicate", "inverted"])
def test_bad_cells_are_named(kind):
    points, cells, message = bad(kind)
    with pytest.raises(MeshError, match="^mesh: " + message):
        check_cells(points, cells, "mesh")
    with pytest.raises(MeshError, match="^mesh: " + message):  # raised collectively, too
        mesh_from_arrays(MPI.COMM_SELF, points, cells, None, "mesh")


def test_inverted_cell_is_the_one_against_the_majority_orientation():
    points, cells = folded_box()
    with pytest.raises(MeshError) as err:
        check_cells(points, cells, "mesh")
    culprit = int(str(err.value).split("cell ")[1].split()[0])
    assert signed(points, cells)[culprit] < 0 < np.median(signed(points, cells))


def test_bad_cells_in_a_file_name_the_file(tmp_path):
    points, cells = folded_box()
    path = tmp_path / "folded.vtu"
    meshio.write(path, meshio.Mesh(points, [("tetra", cells)]))
    with pytest.raises(MeshError, match=f"mesh file {path}: cell \\d+ is inverted"):
        build(scene_with('mesh.shape="file"', f'mesh.file="{path}"'))


# --- end to end ------------------------------------------------------------------------------

def run_scene(out: Path, *sets: str) -> dict[str, float]:
    args = ["run", "-o", str(out), "-q", "--set", "time.steps=2", "--set", "output.render=false"]
    for s in sets:
        args += ["--set", s]
    assert main(args) == 0
    final = meshio.read(out / "final.vtu")
    return final


def test_sphere_runs_end_to_end(tmp_path):
    final = run_scene(tmp_path / "ball", 'mesh.shape="sphere"', "mesh.element_size=0.04",
                      "pin.0.min=[-1, -1, -1]", "pin.0.max=[1, 1, -0.08]")  # the bottom cap
    u = final.point_data["displacement"]
    assert np.all(np.isfinite(u)) and u[:, 2].min() < 0.0
    assert np.abs(u[final.points[:, 2] <= -0.08]).max() == 0.0


def test_stl_runs_end_to_end(tmp_path):
    final = run_scene(tmp_path / "cube", 'mesh.shape="file"', f'mesh.file="{DATA / "cube.stl"}"',
                      "pin.0.min=[-1, -1, -1e-6]", "pin.0.max=[1, 1, 1e-6]")  # the bottom face
    u = final.point_data["displacement"]
    assert np.all(np.isfinite(u)) and u[:, 2].min() < 0.0
    assert np.abs(u[np.abs(final.points[:, 2]) <= 1e-6]).max() == 0.0


@pytest.mark.parametrize("name, content, message", [
    ("broken.msh", b"$MeshFormat\nnonsense\n", "cannot be read"),
    ("open.stl", None, "the surface is open"),
])
def test_bad_mesh_file_via_cli_exits_2_with_one_line(tmp_path, name, content, message):
    path = tmp_path / name
    if content is None:
        write_surface(path, *BAD_SURFACES["open"])
    else:
        path.write_bytes(content)
    out = tmp_path / "out"
    r = subprocess.run(fem_anim_command() + ["run", "-o", str(out), "-q", "--set",
                                             'mesh.shape="file"', "--set", f'mesh.file="{path}"',
                                             "--set", 'mesh.fill="gmsh"'],
                       check=False, cwd=tmp_path, capture_output=True, text=True, timeout=300,
                       env=clean_environment())
    assert r.returncode == 2, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"fem-anim: error: mesh file {path}") and message in lines[0]
    assert not out.exists()


# --- structured box (mesh.divisions) ---------------------------------------------------------

@pytest.mark.parametrize("size, divisions", [([1.0, 0.2, 0.2], [5, 2, 3]), ([1.0, 0.2], [7, 3])])
def test_structured_box_is_a_conforming_grid_of_equal_simplices(size, divisions):
    """d! simplices per cube of equal volume, the exact total, every face shared by two
    cells or on the boundary, and as many boundary faces as the box's sides hold."""
    points, cells = meshes.structured_box(size, divisions, origin=[0.5, -1.0, 2.0][:len(size)])
    d = len(size)
    v = cell_volumes(points, cells)  # signed: every cell positively oriented
    assert len(cells) == math.factorial(d) * math.prod(divisions)
    assert v.min() > 0 and np.ptp(v) <= 1e-15 * v.max() * 10
    assert abs(v.sum() - math.prod(size)) <= 1e-14 * math.prod(size)
    assert np.allclose(points.min(axis=0), [0.5, -1.0, 2.0][:d])
    assert np.allclose(points.max(axis=0) - points.min(axis=0), size)
    faces = np.sort(np.concatenate([np.delete(cells, k, axis=1) for k in range(d + 1)]), axis=1)
    _, count = np.unique(faces, axis=0, return_counts=True)
    assert set(count) == {1, 2}  # conforming: no face is cut differently by two cells
    n = divisions
    sides = ([n[0] * n[1], n[1] * n[2], n[0] * n[2]] if d == 3 else [n[0], n[1]])
    assert (count == 1).sum() == 2 * (d - 1) * sum(sides)  # 2 triangles (1 edge) per square


def test_structured_scene_gives_the_peers_beam(tmp_path):
    """mesh.divisions = [30, 8, 8]: the 11 520 tetrahedra of the peers' hanging beam, in DOLFINx."""
    scene = scene_with("mesh.divisions=[30, 8, 8]")
    mesh = build(scene)
    assert mesh.mesh.topology.index_map(3).size_global == 11520
    assert abs(volumes(mesh.points, mesh.cells).sum() - 0.04) <= 1e-15


def test_a_body_of_several_takes_its_structured_divisions_too(tmp_path):
    """[[body]] meshes go through the same builder choice: divisions make the structured box."""
    from fem_anim.mesh.bodies import build_scene_mesh

    box = 'mesh = { shape = "box", size = [0.1, 0.1, 0.1], %s }\n'
    text = ('name = "two"\n[contact]\ndhat = 0.005\n'
            '[[body]]\nname = "gmsh"\noffset = [-0.11, 0, 0]\n' + box % "element_size = 0.05" +
            '[[body]]\nname = "grid"\noffset = [0.03, 0, 0]\n' + box % "divisions = [2, 3, 4]")
    path = tmp_path / "two.toml"
    path.write_text(text)
    domain = build_scene_mesh(MPI.COMM_SELF, load_scene(path))
    grid = domain.points[domain.cells].mean(axis=1)[:, 0] > 0.0
    assert grid.sum() == 6 * 2 * 3 * 4
    assert abs(volumes(domain.points, domain.cells)[grid].sum() - 1e-3) <= 1e-17
