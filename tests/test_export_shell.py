"""``fem-anim export`` of cloth: a shell run, a P2 (Kirchhoff-Love) shell run, and a shell
beside a solid.

Each run is small (coarse meshes, two steps). Its USD file (written by the run with
``output.usd = true``) and its OBJ/PLY exports are read back with usd-core and meshio and
compared with the run's trajectories read independently with meshio (``trajectory.xdmf``
of a shell run; ``shell.xdmf`` and ``solids.xdmf`` of a joint run): the positions X + u of
every frame to float32 round-off, the faces (a shell's are its own triangles, a solid's its
boundary wound outward), the time codes, two-sidedness, the energy density and its unit;
and a run the reader cannot handle is one line and exit code 2.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import h5py
import meshio
import numpy as np
import pytest
from conftest import ROOT
from mpi4py import MPI

from fem_anim.cli import main

pxr = pytest.importorskip("pxr")
from pxr import Usd, UsdGeom  # noqa: E402 (after the importorskip)

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: one run per process")

#: The drape (cloth over a ball on the ground), coarse and two steps long.
DRAPE_SETS = ["time.steps=2", "output.render=false", "output.usd=true",
              "mesh.element_size=0.1"]
#: The cloth on a soft block, coarse and two steps long.
SOFT_SETS = ["time.steps=2", "output.render=false", "output.usd=true",
             "body.0.mesh.element_size=0.08", "body.1.mesh.element_size=0.1"]

#: A Kirchhoff-Love (P2) sheet held along x = 0, sagging under gravity.
KL_SCENE = """
name = "klsheet"
[mesh]
shape = "sheet"
size = [0.2, 0.1]
origin = [0.0, 0.0, 0.5]
element_size = 0.05
[element]
degree = 2
[shell]
thickness = 0.002
bending_model = "kirchhoff_love"
[material]
model = "stvk"
youngs_modulus = 1.0e6
poisson_ratio = 0.3
density = 300.0
[time]
dt = 0.02
steps = 2
[gravity]
acceleration = [0.0, 0.0, -9.81]
[[pin]]
name = "left"
min = [-1.0, -1.0, -1.0]
max = [0.001, 1.0, 1.0]
[output]
render = false
usd = true
"""


def run(toml: Path, out: Path, sets: list[str]) -> Path:
    args = ["run", str(toml), "-o", str(out), "--quiet"]
    for setting in sets:
        args += ["--set", setting]
    assert main(args) == 0
    return out


@pytest.fixture(scope="module")
def drape(tmp_path_factory) -> Path:
    return run(ROOT / "demos" / "drape.toml", tmp_path_factory.mktemp("drape") / "run",
               DRAPE_SETS)


@pytest.fixture(scope="module")
def kl_sheet(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("kl")
    (folder / "kl.toml").write_text(KL_SCENE)
    return run(folder / "kl.toml", folder / "run", [])


@pytest.fixture(scope="module")
def soft(tmp_path_factory) -> Path:
    return run(ROOT / "demos" / "drape_soft.toml", tmp_path_factory.mktemp("soft") / "run",
               SOFT_SETS)


def xdmf_frames(path: Path) -> tuple[np.ndarray, np.ndarray, list[tuple[float, dict, dict]]]:
    """meshio's reading of a trajectory: rest points, cells, (t, point data, cell data)."""
    reader = meshio.xdmf.TimeSeriesReader(str(path))
    points, cells = reader.read_points_cells()
    frames = [reader.read_data(k) for k in range(reader.num_steps)]
    return np.asarray(points, dtype=float), cells[0].data, frames


def usd_mesh(stage, path: str):
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath(path))
    assert mesh, path
    assert np.all(np.asarray(mesh.GetFaceVertexCountsAttr().Get()) == 3)
    return mesh, np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)


def float32_close(got, expected) -> bool:
    return np.allclose(got, expected, rtol=0, atol=2.0 ** -22 * np.abs(expected).max())


def tet_boundary(tets: np.ndarray) -> np.ndarray:
    """The triangles of a tetrahedral mesh that belong to one tetrahedron, vertices sorted."""
    faces = np.sort(np.concatenate([tets[:, [0, 1, 2]], tets[:, [0, 1, 3]], tets[:, [0, 2, 3]],
                                    tets[:, [1, 2, 3]]]), axis=1)
    unique, counts = np.unique(faces, axis=0, return_counts=True)
    return unique[counts == 1]


def test_shell_usd_is_the_trajectory_at_every_frame(drape):
    points, cells, frames = xdmf_frames(drape / "trajectory.xdmf")
    stage = Usd.Stage.Open(str(drape / "drape.usdc"))
    times = np.array([t for t, _, _ in frames])
    assert len(times) == 3
    assert stage.GetTimeCodesPerSecond() == pytest.approx(1.0 / (times[1] - times[0]))
    assert (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (1.0, 3.0)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    mesh, triangles = usd_mesh(stage, "/drape/drape")
    assert np.array_equal(triangles, cells)  # the cloth's own triangles, as its mesh winds them
    assert mesh.GetDoubleSidedAttr().Get() is True
    assert mesh.GetPointsAttr().GetTimeSamples() == [1.0, 2.0, 3.0]
    energy = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("energy_density")
    assert energy.GetAttr().GetDocumentation().endswith("J/m^2")
    for k, (_, point_data, cell_data) in enumerate(frames):
        expected = points + point_data["displacement"]
        assert float32_close(np.asarray(mesh.GetPointsAttr().Get(1.0 + k)), expected)
        psi = cell_data["energy_density"][0]
        assert np.allclose(np.asarray(energy.Get(1.0 + k)), psi, rtol=1e-6,
                           atol=1e-7 * np.abs(psi).max())  # float32 (1e-29 J/m^2 at rest)
    assert np.abs(frames[-1][1]["displacement"]).max() > 1e-4  # the cloth did fall
    ball = UsdGeom.Sphere(stage.GetPrimAtPath("/drape/obstacles/ball"))
    world = UsdGeom.Xformable(ball).ComputeLocalToWorldTransform(Usd.TimeCode.Default())
    assert list(world.ExtractTranslation()) == pytest.approx([0.0, 0.0, 0.12])
    ground = UsdGeom.Mesh(stage.GetPrimAtPath("/drape/obstacles/ground"))
    quad = np.asarray(ground.GetPointsAttr().Get())
    assert np.allclose(quad[:, 2], 0.0)


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_shell_sequences_are_the_trajectory(drape, fmt):
    points, cells, frames = xdmf_frames(drape / "trajectory.xdmf")
    assert main(["export", str(drape), "--format", fmt, "-q"]) == 0
    assert len(list((drape / fmt).iterdir())) == len(frames)
    for k in (0, len(frames) - 1):
        mesh = meshio.read(drape / fmt / f"drape_{1 + k:04d}.{fmt}")
        expected = points + frames[k][1]["displacement"]
        tol = 1e-8 * np.abs(expected).max() if fmt == "obj" else 0.0
        assert np.allclose(mesh.points, expected, rtol=0, atol=tol)
        assert np.array_equal(mesh.cells_dict["triangle"], cells)


def test_p2_shell_exports_its_quadratic_field_refined(kl_sheet):
    points, cells, frames = xdmf_frames(kl_sheet / "trajectory.xdmf")
    with h5py.File(kl_sheet / "trajectory.h5", "r") as h5:
        nodes = np.asarray(h5["displacement_nodes"])
        dofs = [np.asarray(h5[f"displacement_dofs{k}"]) for k in range(len(frames))]
    assert np.any(nodes[:, 0] != nodes[:, 1])  # the trajectory holds the P2 edge dofs
    stage = Usd.Stage.Open(str(kl_sheet / "klsheet.usdc"))
    mesh, triangles = usd_mesh(stage, "/klsheet/klsheet")
    assert triangles.shape[0] == 4 * cells.shape[0]
    assert mesh.GetDoubleSidedAttr().Get() is True
    rest = 0.5 * (points[nodes[:, 0]] + points[nodes[:, 1]])
    for k, (_, point_data, _) in enumerate(frames):
        x = np.asarray(mesh.GetPointsAttr().Get(1.0 + k), dtype=float)
        assert x.shape[0] == nodes.shape[0]  # every dof of the P2 field is a vertex
        assert float32_close(x, rest + dofs[k])
        at_vertices = nodes[:, 0] == nodes[:, 1]  # and the vertices are meshio's trajectory
        assert float32_close(x[at_vertices], (points + point_data["displacement"])[
            nodes[at_vertices, 0]])
    # each child triangle keeps its parent's normal direction (the mesh's winding)
    x0 = np.asarray(mesh.GetPointsAttr().Get(1.0), dtype=float)
    normal = np.cross(x0[triangles[:, 1]] - x0[triangles[:, 0]],
                      x0[triangles[:, 2]] - x0[triangles[:, 0]])
    parent = np.cross(points[cells[:, 1]] - points[cells[:, 0]],
                      points[cells[:, 2]] - points[cells[:, 0]])
    assert np.all(np.einsum("ij,ij->i", normal, np.repeat(parent, 4, axis=0)) > 0)


def test_joint_run_exports_the_solid_and_the_cloth(soft):
    scene = json.loads((soft / "scene.json").read_text())["scene"]
    assert [b["name"] for b in scene["body"]] == ["jelly", "cloth"]
    stage = Usd.Stage.Open(str(soft / "drape_soft.usdc"))
    prims = [p.GetName() for p in stage.GetDefaultPrim().GetChildren() if p.IsA(UsdGeom.Mesh)]
    assert prims == ["jelly", "cloth"]
    cloth, cloth_faces = usd_mesh(stage, "/drape_soft/cloth")
    jelly, jelly_faces = usd_mesh(stage, "/drape_soft/jelly")
    shell_points, shell_cells, shell_frames = xdmf_frames(soft / "shell.xdmf")
    solid_points, tets, solid_frames = xdmf_frames(soft / "solids.xdmf")
    assert len(shell_frames) == len(solid_frames) == 3
    assert [t for t, _, _ in shell_frames] == [t for t, _, _ in solid_frames]
    assert cloth.GetPointsAttr().GetTimeSamples() == jelly.GetPointsAttr().GetTimeSamples() \
        == [1.0, 2.0, 3.0]
    assert np.array_equal(cloth_faces, shell_cells)
    assert cloth.GetDoubleSidedAttr().Get() is True and not jelly.GetDoubleSidedAttr().Get()
    boundary = tet_boundary(tets)
    used = np.unique(boundary)
    assert jelly_faces.shape[0] == boundary.shape[0]
    assert np.array_equal(np.unique(np.sort(used[jelly_faces], axis=1), axis=0), boundary)
    for k in range(3):
        x = np.asarray(cloth.GetPointsAttr().Get(1.0 + k), dtype=float)
        assert float32_close(x, shell_points + shell_frames[k][1]["displacement"])
        y = np.asarray(jelly.GetPointsAttr().Get(1.0 + k), dtype=float)
        solid = solid_points + solid_frames[k][1]["displacement"]
        assert float32_close(y, solid[used])
        t = solid[tets]
        volume = np.abs(np.einsum("ij,ij->i", np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]),
                                  t[:, 3] - t[:, 0])).sum() / 6.0
        enclosed = np.einsum("ij,ij->i", y[jelly_faces[:, 0]],
                             np.cross(y[jelly_faces[:, 1]], y[jelly_faces[:, 2]])).sum() / 6.0
        assert enclosed == pytest.approx(volume, rel=1e-5)  # closed and wound outward
    units = [UsdGeom.PrimvarsAPI(m).GetPrimvar("energy_density").GetAttr().GetDocumentation()
             for m in (jelly, cloth)]
    assert units[0].endswith("J/m^3") and units[1].endswith("J/m^2")
    assert [UsdGeom.PrimvarsAPI(m).GetPrimvar("body").Get() for m in (jelly, cloth)] == [0, 1]
    last = solid_frames[-1][2]["energy_density"][0]
    assert np.any(last > 0)


@pytest.mark.parametrize("fmt", ["obj", "ply"])
def test_joint_run_sequences(soft, fmt):
    assert main(["export", str(soft), "--format", fmt, "-q"]) == 0
    shell_points, shell_cells, frames = xdmf_frames(soft / "shell.xdmf")
    solid_points, tets, solid_frames = xdmf_frames(soft / "solids.xdmf")
    assert len(list((soft / fmt).iterdir())) == 2 * len(frames)
    used = np.unique(tet_boundary(tets))
    for k in (0, len(frames) - 1):
        cloth = meshio.read(soft / fmt / f"cloth_{1 + k:04d}.{fmt}")
        jelly = meshio.read(soft / fmt / f"jelly_{1 + k:04d}.{fmt}")
        tol = 1e-8 if fmt == "obj" else 0.0
        assert np.allclose(cloth.points, shell_points + frames[k][1]["displacement"],
                           rtol=0, atol=tol)
        assert np.array_equal(cloth.cells_dict["triangle"], shell_cells)
        assert np.allclose(jelly.points, (solid_points + solid_frames[k][1]["displacement"])[
            used], rtol=0, atol=tol)


def test_joint_body_numbers_follow_the_scene(soft, tmp_path):
    """The cloth listed first: the prims and ``body`` primvars keep the scene's order."""
    from fem_anim.export.run_reader import read_run

    copy = tmp_path / "swapped"
    shutil.copytree(soft, copy)
    data = json.loads((copy / "scene.json").read_text())
    data["scene"]["body"] = data["scene"]["body"][::-1]
    (copy / "scene.json").write_text(json.dumps(data))
    run_data = read_run(copy)
    assert run_data.body_names == ["cloth", "jelly"] and run_data.shells == {0}
    surfaces = run_data.surfaces()
    with h5py.File(copy / "shell.h5", "r") as h5:
        shell_cells = np.asarray(h5["data1"])
    with h5py.File(copy / "solids.h5", "r") as h5:
        num_solid = h5["data0"].shape[0]
    assert np.array_equal(surfaces[0].vertices[surfaces[0].triangles], shell_cells + num_solid)
    assert np.all(surfaces[1].vertices < num_solid)


@pytest.mark.mpi
def test_joint_usd_of_a_parallel_run_is_the_serial_one(soft, tmp_path):
    """Under ``mpirun -n 2`` the joint run writes the same stage: faces and samples."""
    import subprocess

    from conftest import clean_environment, fem_anim_command, mpirun_command

    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("no mpirun")
    out = tmp_path / "run"
    args = ["run", str(ROOT / "demos" / "drape_soft.toml"), "-o", str(out), "--quiet"]
    for setting in SOFT_SETS:
        args += ["--set", setting]
    done = subprocess.run(mpirun + fem_anim_command() + args, capture_output=True, text=True,
                          timeout=600, env=clean_environment())
    assert done.returncode == 0, done.stderr[-2000:]
    serial, parallel = (Usd.Stage.Open(str(p / "drape_soft.usdc")) for p in (soft, out))
    for name in ("jelly", "cloth"):
        a, ta = usd_mesh(serial, f"/drape_soft/{name}")
        b, tb = usd_mesh(parallel, f"/drape_soft/{name}")
        assert np.array_equal(ta, tb)
        for code in (1.0, 3.0):
            xa = np.asarray(a.GetPointsAttr().Get(code))
            xb = np.asarray(b.GetPointsAttr().Get(code))
            assert np.allclose(xa, xb, rtol=0, atol=1e-6 * np.abs(xa).max())


def one_line_error(capsys, args) -> str:
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fem-anim: error:"), err
    return err[0]


def test_unreadable_runs_are_one_line(drape, soft, tmp_path, capsys):
    broken = tmp_path / "broken"
    shutil.copytree(drape, broken)
    with h5py.File(broken / "trajectory.h5", "a") as h5:
        del h5["data3"]  # frame 1's displacement
    assert "data3" in one_line_error(capsys, ["export", str(broken), "-o",
                                              str(tmp_path / "b.usda")])
    assert "data3" in one_line_error(capsys, ["export", str(broken), "--format", "ply", "-o",
                                              str(tmp_path / "b")])
    lines = tmp_path / "lines"  # cells that are neither triangles nor tetrahedra
    shutil.copytree(drape, lines)
    with h5py.File(lines / "trajectory.h5", "a") as h5:
        cells = np.asarray(h5["data1"])
        del h5["data1"]
        h5["data1"] = cells[:, :2]
    assert "triangles or tetrahedra" in one_line_error(capsys, ["export", str(lines)])
    joint = tmp_path / "joint"
    shutil.copytree(soft, joint)
    (joint / "solids.h5").unlink()
    assert "solids.h5" in one_line_error(capsys, ["export", str(joint)])
    other = tmp_path / "other"  # solids.h5 of another mesh
    shutil.copytree(soft, other)
    with h5py.File(other / "solids.h5", "a") as h5:
        tets = np.asarray(h5["data1"])
        del h5["data1"]
        h5["data1"] = tets[1:]
    assert "solids.h5" in one_line_error(capsys, ["export", str(other)])
    edited = tmp_path / "edited"  # a hand-edited scene.json: a sphere without its radius
    shutil.copytree(drape, edited)
    data = json.loads((edited / "scene.json").read_text())
    del data["scene"]["obstacle"][0]["radius"]
    (edited / "scene.json").write_text(json.dumps(data))
    assert "radius" in one_line_error(capsys, ["export", str(edited)])


@pytest.mark.slow
def test_blender_reads_the_cloth(soft, tmp_path):
    """Blender (bpy) imports the joint run's USD file and OBJ files: the cloth's and the
    block's vertices at the first and the last frame are the run's, to float32 round-off."""
    import subprocess

    from test_blender_roundtrip import BLENDER_SCRIPT, bpy_python

    python = bpy_python()
    assert main(["export", str(soft), "--format", "obj", "-q"]) == 0
    shell_points, shell_cells, frames = xdmf_frames(soft / "shell.xdmf")
    solid_points, tets, solid_frames = xdmf_frames(soft / "solids.xdmf")
    used = np.unique(tet_boundary(tets))
    names = ["jelly", "cloth"]
    request = {"frames": {str(1 + k): names for k in (0, 2)},
               "obj": {str(1 + k): {n: str(soft / "obj" / f"{n}_{1 + k:04d}.obj")
                                    for n in names} for k in (0, 2)}}
    script, report_file = tmp_path / "check.py", tmp_path / "blender.json"
    script.write_text(BLENDER_SCRIPT)
    done = subprocess.run([str(python), str(script), str(soft / "drape_soft.usdc"),
                           str(soft / "obj"), json.dumps(request), str(report_file)],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(report_file.read_text())
    assert (report["frame_start"], report["frame_end"]) == (1, 3)
    assert report["animated"] == sorted(names)
    for k in (0, 2):
        cloth = shell_points + frames[k][1]["displacement"]
        jelly = (solid_points + solid_frames[k][1]["displacement"])[used]
        for kind in ("usd", "obj"):
            got = report[kind][str(1 + k)]
            assert float32_close(np.asarray(got["cloth"]["points"]), cloth), (kind, k)
            assert np.array_equal(got["cloth"]["faces"], shell_cells), kind
            assert float32_close(np.asarray(got["jelly"]["points"]), jelly), (kind, k)
