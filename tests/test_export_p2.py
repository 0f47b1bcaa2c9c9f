"""``fem-anim export`` of a P2 run: each boundary triangle split in four through its edge
dofs, so the exported surface's vertices are the quadratic solution's values there.

The check is independent of the writer and of the refinement: the exported OBJ of frame 0
(the rest shape) gives each surface vertex's rest point; DOLFINx evaluates the run's final
P2 displacement there (``Function.eval`` in the cell holding the point), and the last
frame's OBJ must be that point plus that value.
"""

from __future__ import annotations

import meshio
import numpy as np
import pytest
from mpi4py import MPI
from scenes import bar, make_scene

from fem_anim.cli import main


pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: one run per process")


def assert_closed_and_consistent(triangles: np.ndarray) -> None:
    """Every directed edge once, and its reverse once: a closed, consistently wound surface."""
    edges = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    directed = {tuple(e) for e in edges.tolist()}
    assert len(directed) == edges.shape[0]
    assert all((b, a) in directed for a, b in directed)


def enclosed_volume(points: np.ndarray, triangles: np.ndarray) -> float:
    x = points[triangles]
    return float(np.einsum("ij,ij->i", x[:, 0], np.cross(x[:, 1], x[:, 2])).sum() / 6.0)


@pytest.fixture(scope="module")
def p2_run(tmp_path_factory):
    """A P2 bar sagging under gravity for 3 steps: (run folder, final state, simulation)."""
    from fem_anim.simulation.loop import Simulation

    root = tmp_path_factory.mktemp("p2export")
    scene = make_scene(root, bar("p2bar", element={"degree": 2},
                                 gravity={"acceleration": [0.0, 0.0, -9.81]},
                                 material={"youngs_modulus": 2e4},
                                 time={"dt": 0.05, "steps": 3,
                                       "integrator": "implicit_euler"},
                                 output={"render": False}))
    sim = Simulation(scene)
    result = sim.run(root / "run", quiet=True)
    return root / "run", result.state, sim


def test_p2_export_is_the_quadratic_field_on_the_refined_surface(p2_run):
    from dolfinx import fem

    from fem_anim import compat
    from fem_anim.export.boundary import body_surfaces
    from fem_anim.export.run_reader import read_run

    out, state, sim = p2_run
    assert main(["export", str(out), "--format", "obj", "-q"]) == 0
    run = read_run(out)
    first = meshio.read(out / "obj" / "p2bar_0001.obj")
    last = meshio.read(out / "obj" / f"p2bar_{len(run.times):04d}.obj")
    triangles = first.cells_dict["triangle"]
    flat = body_surfaces(run.points, run.cells, run.body)[0]
    assert triangles.shape[0] == 4 * flat.triangles.shape[0]
    assert_closed_and_consistent(triangles)
    volume = enclosed_volume(first.points, triangles)
    assert volume == pytest.approx(1.0 * 0.1 * 0.1, rel=1e-9)  # rest: straight edges
    # the quadratic solution at the refined surface's rest points
    u = fem.Function(sim.problem.V)
    u.x.array[:] = state.u
    rest = np.asarray(first.points, dtype=float)
    colliding = compat.colliding_cells(sim.domain.mesh, rest)
    cells = [colliding.links(k)[0] for k in range(rest.shape[0])]
    expected = rest + u.eval(rest, np.asarray(cells, dtype=np.int32))
    moved = np.abs(expected - rest).max()
    assert moved > 1e-3  # the bar sagged
    assert np.abs(last.points - expected).max() <= 1e-7 * (1.0 + moved)
    # the midside points moved off the flat triangles of the corners: the surface is curved
    x = last.points
    corner_a, corner_b, mid = (x[triangles[0::4, 0]], x[triangles[1::4, 1]],
                               x[triangles[0::4, 1]])
    bow = np.linalg.norm(mid - 0.5 * (corner_a + corner_b), axis=1).max()
    assert bow > 1e-2 * moved


def test_p2_usd_points_are_the_obj_points(p2_run):
    pytest.importorskip("pxr")
    from pxr import Usd, UsdGeom

    out, _, _ = p2_run
    assert main(["export", str(out), "--format", "usd", "-q"]) == 0
    assert main(["export", str(out), "--format", "ply", "-q"]) == 0
    stage = Usd.Stage.Open(str(out / "p2bar.usdc"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/p2bar/p2bar"))
    end = stage.GetEndTimeCode()
    points = np.asarray(mesh.GetPointsAttr().Get(end), dtype=float)
    triangles = np.asarray(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    ply = meshio.read(out / "ply" / f"p2bar_{int(end):04d}.ply")
    np.testing.assert_allclose(points, ply.points, rtol=0, atol=1e-6)
    np.testing.assert_array_equal(triangles, ply.cells_dict["triangle"])


@pytest.mark.slow
def test_blender_reads_the_refined_p2_surface(p2_run, tmp_path):
    """Blender (bpy) imports the P2 run's USD file and OBJ sequence: at the first, a middle
    and the last frame its vertices are the refined surface's, to float32 round-off."""
    import json
    import subprocess

    from test_blender_roundtrip import BLENDER_SCRIPT, bpy_python

    from fem_anim.export.run_reader import read_run

    out, _, _ = p2_run
    python = bpy_python()
    assert main(["export", str(out), "--format", "usd", "-q"]) == 0
    assert main(["export", str(out), "--format", "obj", "-q"]) == 0
    run = read_run(out)
    n = len(run.times)
    frames = sorted({0, n // 2, n - 1})
    request = {"frames": {str(1 + k): run.body_names for k in frames},
               "obj": {str(1 + k): {name: str(out / "obj" / f"{name}_{1 + k:04d}.obj")
                                    for name in run.body_names} for k in frames}}
    script, report_file = tmp_path / "check.py", tmp_path / "blender.json"
    script.write_text(BLENDER_SCRIPT)
    done = subprocess.run([str(python), str(script), str(out / "p2bar.usdc"),
                           str(out / "obj"), json.dumps(request), str(report_file)],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(report_file.read_text())
    surface = run.surfaces()[0]
    rest = run.surface_points()
    for k in frames:
        expected = (rest + run.surface_displacement(k))[surface.vertices]
        tol = 2.0 ** -22 * np.abs(expected).max()
        for kind in ("usd", "obj"):
            got = report[kind][str(1 + k)]["p2bar"]
            assert np.allclose(got["points"], expected, rtol=0, atol=tol), (kind, k)
            assert np.array_equal(got["faces"], surface.triangles), kind
