"""``fem-anim export`` and ``[output] usd``: USD stages and OBJ/PLY sequences of a run.

A coarse pile (four bodies on a ground plane, a few steps) is run once; its USD file
(written at the end of the run) and its exports are read back with ``usd-core`` and
meshio and compared with the run's own trajectory: the time samples, the frame rate, one
closed outward-wound mesh per body (the volume its surface encloses is the body's volume),
the primvars, the obstacles, the body ids of the XDMF and VTU files; and the files
fem_anim does not own are left alone. Blender's own reading of the same files is
``tests/test_blender_roundtrip.py``.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from conftest import ROOT, clean_environment, fem_anim_command, mpirun_command

from fem_anim.cli import main
from fem_anim.export.boundary import body_surfaces, boundary_faces
from fem_anim.export.run_reader import read_run
from fem_anim.export.usd_stage import write_usd
from fem_anim.output.rundir import MARKER, read_manifest

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom  # noqa: E402 (after the importorskip)

#: A coarse pile: four bodies, few cells, six steps (about 5 s).
PILE_SETS = ["time.steps=6", "output.render=false", "output.usd=true",
             "body.0.mesh.element_size=0.06", "body.1.mesh.element_size=0.05",
             "body.2.mesh.element_size=0.05", "body.3.mesh.element_size=0.036"]


@pytest.fixture(scope="module")
def pile(tmp_path_factory) -> Path:
    """The coarse pile, run once for the module, with ``output.usd = true``."""
    out = tmp_path_factory.mktemp("pile") / "run"
    args = ["run", str(ROOT / "demos" / "pile.toml"), "-o", str(out), "--quiet"]
    for setting in PILE_SETS:
        args += ["--set", setting]
    assert main(args) == 0
    return out


def tet_volume(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    x = points[cells]
    return np.einsum("ij,ij->i", np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]),
                     x[:, 3] - x[:, 0]) / 6.0


def enclosed_volume(points: np.ndarray, triangles: np.ndarray) -> float:
    """Divergence theorem: positive for a closed surface wound outward."""
    x = points[triangles]
    return float(np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() / 6.0)


def assert_closed_and_consistent(triangles: np.ndarray) -> None:
    """Every directed edge once, and its reverse once: a closed, consistently wound surface."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == edges.shape[0]
    assert all((b, a) in directed for a, b in directed)


def usd_mesh_arrays(stage, path: str, code: float) -> tuple[np.ndarray, np.ndarray]:
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(path))
    assert mesh, path
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get())
    assert np.all(counts == 3)
    triangles = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    return np.asarray(mesh.GetPointsAttr().Get(code), dtype=float), triangles


def validation_errors(path: Path) -> list[str]:
    """usd-core's own validators (UsdValidation; ComplianceChecker on older usd-core)."""
    try:
        from pxr import UsdValidation
    except ImportError:
        from pxr import UsdUtils

        checker = UsdUtils.ComplianceChecker(rootPackageOnly=False, skipVariants=False)
        checker.CheckCompliance(str(path))
        return list(checker.GetErrors()) + list(checker.GetFailedChecks())
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    return [f"{e.GetName()}: {e.GetMessage()}" for e in context.Validate(Usd.Stage.Open(
        str(path))) if e.GetType() == UsdValidation.ValidationErrorType.Error]


def test_boundary_of_a_cube_is_closed_and_outward():
    from fem_anim.reference.box_mesh import box_mesh

    points, cells = box_mesh((2, 2, 3), (1.0, 2.0, 3.0))
    cells[::2] = cells[::2][:, [0, 2, 1, 3]]  # half the cells wound the other way
    faces, owner = boundary_faces(points, cells)
    assert_closed_and_consistent(faces)
    assert enclosed_volume(points, faces) == pytest.approx(6.0, rel=1e-12)
    assert faces.shape[0] == 2 * 2 * (2 * 2 + 2 * 3 + 2 * 3)  # two triangles per square
    assert all(set(f) <= set(cells[c]) for f, c in zip(faces.tolist(), owner.tolist()))


def test_usd_validates_and_has_one_prim_per_body(pile):
    path = pile / "pile.usdc"
    assert "pile.usdc" in read_manifest(pile)  # installed with the run, fem_anim's own
    assert validation_errors(path) == []
    stage = Usd.Stage.Open(str(path))
    names = [b["name"] for b in json.loads((pile / "scene.json").read_text())["scene"]["body"]]
    bodies = [p.GetName() for p in stage.GetDefaultPrim().GetChildren()
              if p.IsA(UsdGeom.Mesh)]
    assert bodies == names
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    for name in names:
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/pile/{name}"))
        assert mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.rightHanded
        assert mesh.GetSubdivisionSchemeAttr().Get() == UsdGeom.Tokens.none
        ok, why = UsdGeom.Mesh.ValidateTopology(mesh.GetFaceVertexIndicesAttr().Get(),
                                                mesh.GetFaceVertexCountsAttr().Get(),
                                                len(mesh.GetPointsAttr().Get(1.0)))
        assert ok, why


def test_usd_time_samples_are_the_trajectory(pile):
    run = read_run(pile)
    with h5py.File(pile / "trajectory.h5", "r") as h5:
        times = np.asarray(h5.attrs["times"])
        frames = [np.asarray(h5[f"data{k + 2}"]) for k in range(times.size)]
    stage = Usd.Stage.Open(str(pile / "pile.usdc"))
    fps = 1.0 / (times[1] - times[0])
    assert stage.GetTimeCodesPerSecond() == pytest.approx(fps) == 100.0  # dt = 0.01 s
    assert stage.GetFramesPerSecond() == pytest.approx(fps)
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1.0, float(times.size))
    surfaces = body_surfaces(run.points, run.cells, run.body)
    for surface, name in zip(surfaces, run.body_names):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/pile/{name}"))
        assert mesh.GetPointsAttr().GetTimeSamples() == [1.0 + k for k in range(times.size)]
        for k, u in enumerate(frames):
            x, _ = usd_mesh_arrays(stage, f"/pile/{name}", 1.0 + k)
            expected = (run.points + u)[surface.vertices]
            assert np.allclose(x, expected, rtol=0, atol=4e-7 * np.abs(expected).max())
            lengths = np.asarray(UsdGeom.PrimvarsAPI(mesh).GetPrimvar("displacement")
                                 .Get(1.0 + k))
            assert np.allclose(lengths, np.linalg.norm(u[surface.vertices], axis=1),
                               rtol=1e-6, atol=1e-12)
        assert np.any(frames[-1][surface.vertices] != 0.0)  # the bodies did move


def test_each_body_surface_encloses_its_volume(pile):
    run = read_run(pile)
    stage = Usd.Stage.Open(str(pile / "pile.usdc"))
    for k, name in enumerate(run.body_names):
        x, triangles = usd_mesh_arrays(stage, f"/pile/{name}", 1.0)
        assert_closed_and_consistent(triangles)
        volume = tet_volume(run.points, run.cells[run.body == k]).sum()
        assert volume > 0
        assert enclosed_volume(x, triangles) == pytest.approx(volume, rel=1e-5)


def test_body_ids_in_xdmf_vtu_and_usd(pile):
    scene = json.loads((pile / "scene.json").read_text())["scene"]
    reader = meshio.xdmf.TimeSeriesReader(str(pile / "trajectory.xdmf"))
    points, cells = reader.read_points_cells()
    _, _, cell_data = reader.read_data(len(read_run(pile).times) - 1)
    body = np.asarray(cell_data["body"][0])
    assert np.array_equal(np.asarray(meshio.read(pile / "final.vtu").cell_data["body"][0]),
                          body)
    assert sorted(set(body.tolist())) == [0, 1, 2, 3]
    tets = cells[0].data
    offsets = np.array([b["offset"] for b in scene["body"]], dtype=float)
    for k in range(len(offsets)):  # each id selects its own body: the cells numbered k lie
        x = points[tets[body == k]]  # around body k's offset, nearer it than any other's
        volume = np.abs(np.linalg.det(x[:, 1:] - x[:, :1]))
        centre = (volume[:, None] * x.mean(axis=1)).sum(axis=0) / volume.sum()
        assert np.linalg.norm(offsets - centre, axis=1).argmin() == k
    stage = Usd.Stage.Open(str(pile / "pile.usdc"))
    for k, entry in enumerate(scene["body"]):
        mesh = UsdGeom.Mesh(stage.GetPrimAtPath(f"/pile/{entry['name']}"))
        assert UsdGeom.PrimvarsAPI(mesh).GetPrimvar("body").Get() == k


def test_energy_density_primvar_is_the_cells_behind_the_faces(pile):
    run = read_run(pile)
    stage = Usd.Stage.Open(str(pile / "pile.usdc"))
    last = len(run.times) - 1
    psi = run.energy_density(last)
    for surface, name in zip(body_surfaces(run.points, run.cells, run.body), run.body_names):
        primvar = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(f"/pile/{name}")) \
            .GetPrimvar("energy_density")
        assert primvar.GetInterpolation() == UsdGeom.Tokens.uniform
        assert np.allclose(np.asarray(primvar.Get(1.0 + last)), psi[surface.owner], rtol=1e-6)


def test_ground_is_a_finite_quad_under_the_bodies(pile):
    run = read_run(pile)
    stage = Usd.Stage.Open(str(pile / "pile.usdc"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/pile/obstacles/ground"))
    quad = np.asarray(mesh.GetPointsAttr().Get(), dtype=float)
    assert list(mesh.GetFaceVertexCountsAttr().Get()) == [4]
    normal = np.cross(quad[1] - quad[0], quad[2] - quad[0])
    assert normal / np.linalg.norm(normal) == pytest.approx([0.0, 0.0, 1.0])
    assert np.allclose(quad[:, 2], 0.0)
    reach = run.positions(len(run.times) - 1)
    assert np.all(quad[:, :2].min(axis=0) < reach[:, :2].min(axis=0))
    assert np.all(quad[:, :2].max(axis=0) > reach[:, :2].max(axis=0))


def test_export_command_writes_the_same_usd(pile, capsys):
    out = pile.parent / "shot.usda"
    assert main(["export", str(pile), "-o", str(out), "--start-frame", "101"]) == 0
    stage, ran = Usd.Stage.Open(str(out)), Usd.Stage.Open(str(pile / "pile.usdc"))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (101.0, 107.0)
    for name in read_run(pile).body_names:
        a, ta = usd_mesh_arrays(stage, f"/pile/{name}", 104.0)
        b, tb = usd_mesh_arrays(ran, f"/pile/{name}", 4.0)
        assert np.array_equal(a, b) and np.array_equal(ta, tb)


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_mesh_sequences_read_back_with_meshio(pile, fmt):
    run = read_run(pile)
    assert main(["export", str(pile), "--format", fmt, "--start-frame", "7", "-q"]) == 0
    folder = pile / fmt
    n = len(run.times)
    names = sorted(p.name for p in folder.iterdir())
    assert len(names) == len(run.body_names) * n
    assert f"ring_{7 + n - 1:04d}.{fmt}" in names and f"log_0007.{fmt}" in names
    assert {f"{fmt}/{name}" for name in names} <= read_manifest(pile)
    surfaces = body_surfaces(run.points, run.cells, run.body)
    for k in (0, n - 1):
        x = run.positions(k)
        for surface, name in zip(surfaces, run.body_names):
            mesh = meshio.read(folder / f"{name}_{7 + k:04d}.{fmt}")
            expected = x[surface.vertices]
            tol = 1e-8 * np.abs(expected).max() if fmt == "obj" else 0.0
            assert np.allclose(mesh.points, expected, rtol=0, atol=tol)
            assert np.array_equal(mesh.cells_dict["triangle"], surface.triangles)


def test_a_shorter_sequence_replaces_the_older_frames_only(pile):
    folder = pile / "obj"
    assert main(["export", str(pile), "--format", "obj", "-q"]) == 0
    (folder / "notes.txt").write_text("mine")
    assert main(["export", str(pile), "--format", "obj", "--start-frame", "50", "-q"]) == 0
    names = sorted(p.name for p in folder.iterdir())
    assert "notes.txt" in names and "ring_0001.obj" not in names and "ring_0050.obj" in names
    assert "obj/ring_0001.obj" not in read_manifest(pile)


def test_export_never_overwrites_a_users_file(pile, tmp_path, capsys):
    user = tmp_path / "mine.usdc"
    user.write_text("precious")
    assert main(["export", str(pile), "-o", str(user)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fem-anim: error:") and "mine.usdc" in err[0]
    assert user.read_text() == "precious"
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "a.obj").write_text("mine")
    assert main(["export", str(pile), "--format", "obj", "-o", str(tmp_path / "frames")]) == 2
    assert sorted(p.name for p in (tmp_path / "frames").iterdir()) == ["a.obj"]
    new = tmp_path / "seq"  # a new folder becomes fem_anim's: a second export replaces
    for _ in range(2):
        assert main(["export", str(pile), "--format", "ply", "-o", str(new), "-q"]) == 0
    assert (new / MARKER).is_file() and len(read_manifest(new)) == 4 * len(read_run(pile).times)
    assert main(["export", str(pile), "-o", str(tmp_path / "x.abc")]) == 2
    assert main(["export", str(tmp_path), "--format", "usd"]) == 2  # not a run


def test_2d_run_and_sphere_obstacle(tmp_path):
    """A synthetic 2D run: sheets wound counter-clockwise about +z, Y up, a sphere prim."""
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    cells = np.array([[0, 2, 1], [1, 2, 3]])  # the first clockwise
    with h5py.File(tmp_path / "trajectory.h5", "w") as h5:
        h5["data0"], h5["data1"] = points, cells
        h5.attrs["times"] = np.array([0.0, 0.04, 0.08])
        for k in range(3):
            h5[f"data{k + 2}"] = np.full((4, 3), 0.1 * k)
            h5[f"energy_density{k}"] = np.zeros(2)
    scene = {"name": "sheet", "gravity": {"acceleration": [0.0, -9.81]},
             "obstacle": [{"name": "ball", "type": "sphere", "center": [0.5, -1.0],
                           "radius": 0.5}]}
    (tmp_path / "scene.json").write_text(json.dumps({"scene": scene}))
    write_usd(read_run(tmp_path), tmp_path / "sheet.usda")
    stage = Usd.Stage.Open(str(tmp_path / "sheet.usda"))
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert stage.GetTimeCodesPerSecond() == pytest.approx(25.0)
    x, triangles = usd_mesh_arrays(stage, "/sheet/sheet", 3.0)
    assert np.allclose(x, points + 0.2)
    e1, e2 = x[triangles[:, 1]] - x[triangles[:, 0]], x[triangles[:, 2]] - x[triangles[:, 0]]
    assert np.all(np.cross(e1, e2)[:, 2] > 0)
    sphere = UsdGeom.Sphere(stage.GetPrimAtPath("/sheet/obstacles/ball"))
    assert sphere.GetRadiusAttr().Get() == 0.5
    world = UsdGeom.Xformable(sphere).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    assert list(world.ExtractTranslation()) == [0.5, -1.0, 0.0]


@pytest.mark.mpi
def test_usd_of_a_parallel_run_is_the_serial_one(pile, tmp_path):
    """Under ``mpirun -n 2`` rank 0 writes the same stage: the same surfaces, the same samples."""
    import subprocess

    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("no mpirun")
    out = tmp_path / "run"
    args = ["run", str(ROOT / "demos" / "pile.toml"), "-o", str(out), "--quiet"]
    for setting in PILE_SETS + ["time.steps=2"]:  # the serial run's first frames
        args += ["--set", setting]
    done = subprocess.run(mpirun + fem_anim_command() + args, capture_output=True, text=True,
                          timeout=600, env=clean_environment())
    assert done.returncode == 0, done.stderr[-2000:]
    serial, parallel = (Usd.Stage.Open(str(p / "pile.usdc")) for p in (pile, out))
    for name in read_run(pile).body_names:
        for code in (1.0, 3.0):
            a, ta = usd_mesh_arrays(serial, f"/pile/{name}", code)
            b, tb = usd_mesh_arrays(parallel, f"/pile/{name}", code)
            assert np.array_equal(ta, tb)
            assert np.allclose(a, b, rtol=0, atol=1e-6 * np.abs(a).max())


def test_output_usd_is_off_by_default():
    from fem_anim.scene import load_scene

    assert load_scene(None, [])["output"]["usd"] is False
