"""Blender reads the exports: the USD stage and the OBJ sequence of a pile, in real Blender.

``bpy`` (Blender as a Python module, PyPI; a wheel for CPython 3.11 only, about 370 MB) is
installed once into its own venv outside the clone (``FEM_ANIM_BPY_VENV``, default
``/var/cache/fem_anim/bpy-venv``) and driven in a subprocess: it imports the USD file with
``bpy.ops.wm.usd_import`` and each body's OBJ files with ``bpy.ops.wm.obj_import``, and
reports the scene's frame range and the evaluated, world-space vertex positions and face
normals of every body at the first, a middle and the last frame. They must be the run's own
positions to float32 round-off, one mesh per body named after it, with outward normals.
The test skips, saying why, on another Python or where the wheel cannot be installed.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from fem_anim.cli import main
from fem_anim.export.run_reader import read_run
from fem_anim.export.surface import body_surfaces

pytestmark = pytest.mark.slow

VENV = Path(os.environ.get("FEM_ANIM_BPY_VENV", "/var/cache/fem_anim/bpy-venv"))

#: Runs inside Blender: argv = usd file, obj folder, JSON of {frame: [body names]}, output.
BLENDER_SCRIPT = r'''
import json, sys, time
import bpy

usd, obj_folder, request, out = sys.argv[1], sys.argv[2], json.loads(sys.argv[3]), sys.argv[4]


def world(obj, depsgraph):
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    m = obj.matrix_world
    points = [list(m @ v.co) for v in mesh.vertices]
    normals = [list(m.to_3x3() @ p.normal) for p in mesh.polygons]
    faces = [list(p.vertices) for p in mesh.polygons]
    evaluated.to_mesh_clear()
    return {"points": points, "normals": normals, "faces": faces}


report = {"usd": {}, "obj": {}}
bpy.ops.wm.read_factory_settings(use_empty=True)
start = time.perf_counter()
assert bpy.ops.wm.usd_import(filepath=usd, set_frame_range=True) == {"FINISHED"}
report["usd_import_s"] = time.perf_counter() - start
scene = bpy.context.scene
report["frame_start"], report["frame_end"] = scene.frame_start, scene.frame_end
report["fps"] = scene.render.fps / scene.render.fps_base
report["animated"] = sorted(o.name for o in bpy.data.objects if o.type == "MESH"
                            and any(m.type == "MESH_SEQUENCE_CACHE" for m in o.modifiers))
for frame, names in request["frames"].items():
    scene.frame_set(int(frame))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    report["usd"][frame] = {name: world(bpy.data.objects[name], depsgraph) for name in names}
for frame, files in request["obj"].items():
    report["obj"][frame] = {}
    for name, path in files.items():
        bpy.ops.wm.read_factory_settings(use_empty=True)
        assert bpy.ops.wm.obj_import(filepath=path, forward_axis="Y", up_axis="Z") \
            == {"FINISHED"}
        obj = [o for o in bpy.data.objects if o.type == "MESH"]
        assert len(obj) == 1, [o.name for o in obj]
        report["obj"][frame][name] = dict(world(obj[0], bpy.context.evaluated_depsgraph_get()),
                                          object=obj[0].name)
json.dump(report, open(out, "w"))
'''


def bpy_python() -> Path:
    """The venv's Python with ``bpy`` (installed on first use; skips if it cannot be)."""
    if sys.version_info[:2] != (3, 11):
        pytest.skip(f"bpy has a wheel for CPython 3.11 only; this is "
                    f"{sys.version_info.major}.{sys.version_info.minor}")
    python = VENV / "bin" / "python"
    probe = [str(python), "-c", "import bpy"]
    if python.exists() and subprocess.run(probe, capture_output=True).returncode == 0:
        return python
    tmp = VENV.with_name(VENV.name + ".partial")
    try:
        VENV.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, "-m", "venv", "--clear", str(tmp)], check=True,
                       capture_output=True)
        done = subprocess.run([str(tmp / "bin" / "python"), "-m", "pip", "install", "-q",
                               "--disable-pip-version-check", "bpy"],
                              capture_output=True, text=True, timeout=1800)
    except (OSError, subprocess.SubprocessError) as err:
        pytest.skip(f"cannot make a venv for bpy in {tmp}: {err}")
    if done.returncode != 0:
        pytest.skip("bpy cannot be installed here (no network or no wheel): "
                    + (done.stderr.strip().splitlines() or ["pip failed"])[-1])
    if VENV.exists():
        import shutil

        shutil.rmtree(VENV)  # a venv without bpy, made by this test
    tmp.rename(VENV)
    return python


@pytest.fixture(scope="module")
def pile_exports(tmp_path_factory) -> Path:
    """The coarse pile of ``tests/test_export.py``, with its USD file and OBJ sequence."""
    from test_export import PILE_SETS

    out = tmp_path_factory.mktemp("pile") / "run"
    args = ["run", str(ROOT / "demos" / "pile.toml"), "-o", str(out), "--quiet"]
    for setting in PILE_SETS:
        args += ["--set", setting]
    assert main(args) == 0
    assert main(["export", str(out), "--format", "obj", "-q"]) == 0
    return out


def test_blender_reads_usd_and_obj_as_the_run(pile_exports, tmp_path):
    python = bpy_python()
    run = read_run(pile_exports)
    n = len(run.times)
    frames = sorted({0, n // 2, n - 1})
    request = {"frames": {str(1 + k): run.body_names for k in frames},
               "obj": {str(1 + k): {name: str(pile_exports / "obj" / f"{name}_{1 + k:04d}.obj")
                                    for name in run.body_names} for k in frames}}
    script, out = tmp_path / "check.py", tmp_path / "blender.json"
    script.write_text(BLENDER_SCRIPT)
    start = time.perf_counter()
    done = subprocess.run([str(python), str(script), str(pile_exports / "pile.usdc"),
                           str(pile_exports / "obj"), json.dumps(request), str(out)],
                          capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(out.read_text())
    print(f"blender: {time.perf_counter() - start:.1f} s in all, USD import "
          f"{report['usd_import_s'] * 1e3:.0f} ms, scene fps {report['fps']}")
    assert (report["frame_start"], report["frame_end"]) == (1, n)
    assert report["animated"] == sorted(run.body_names)
    surfaces = body_surfaces(run.points, run.cells, run.body)
    for k in frames:
        x = run.positions(k)
        for surface, name in zip(surfaces, run.body_names):
            expected = x[surface.vertices]
            tol = 2.0 ** -22 * np.abs(expected).max()  # float32 round-off, twice
            for kind in ("usd", "obj"):
                got = report[kind][str(1 + k)][name]
                assert np.allclose(got["points"], expected, rtol=0, atol=tol), (kind, name, k)
                assert np.array_equal(got["faces"], surface.triangles), (kind, name)
                a, b, c = (expected[surface.triangles[:, j]] for j in range(3))
                ours = np.cross(b - a, c - a)
                assert np.all(np.einsum("ij,ij->i", ours, got["normals"]) > 0), (kind, name)
            assert report["obj"][str(1 + k)][name]["object"] == name
