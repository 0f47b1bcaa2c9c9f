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
from fem_anim.export.boundary import body_surfaces
from fem_anim.export.run_reader import read_run

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


#: Runs inside Blender: argv = usd file, png, frame, camera target xyz, camera distance.
PICTURE_SCRIPT = r'''
import math, sys
import bpy
from mathutils import Vector

usd, png, frame = sys.argv[1], sys.argv[2], int(sys.argv[3])
target, distance = Vector([float(v) for v in sys.argv[4:7]]), float(sys.argv[7])
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.usd_import(filepath=usd, set_frame_range=True)
scene = bpy.context.scene
scene.frame_set(frame)
palette = [(0.90, 0.45, 0.20), (0.20, 0.55, 0.85), (0.35, 0.70, 0.35), (0.80, 0.30, 0.60)]
bodies = [o for o in bpy.data.objects if o.type == "MESH" and o.modifiers]
for o in (o for o in bpy.data.objects if o.type == "MESH"):
    material = bpy.data.materials.new(o.name)
    material.use_nodes = True
    colour = palette[bodies.index(o) % len(palette)] if o in bodies else (0.8, 0.8, 0.8)
    material.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = \
        (*colour, 1.0)
    o.data.materials.append(material)
camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
scene.collection.objects.link(camera)
camera.location = target + distance * Vector((1.0, -1.0, 0.75)).normalized()
camera.rotation_euler = (target - camera.location).to_track_quat("-Z", "Y").to_euler()
scene.camera = camera
sun = bpy.data.objects.new("sun", bpy.data.lights.new("sun", type="SUN"))
sun.data.energy = 3.0
sun.rotation_euler = (math.radians(40), math.radians(10), math.radians(30))
scene.collection.objects.link(sun)
scene.world = bpy.data.worlds.new("world")
scene.world.color = (0.8, 0.82, 0.86)
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 32
scene.render.resolution_x, scene.render.resolution_y = 640, 420
scene.render.filepath = png
bpy.ops.render.render(write_still=True)
'''


def render_picture(run_dir: Path, png: Path) -> None:
    """Render a run's USD file (``<scene>.usdc``) at its last frame in Blender (Cycles, CPU),
    the camera aimed at the bodies' centre from a distance of three times their size."""
    run = read_run(run_dir)
    last = len(run.times) - 1
    x = run.positions(last)
    target = 0.5 * (x.min(axis=0) + x.max(axis=0))
    distance = 2.2 * float(np.max(x.max(axis=0) - x.min(axis=0)))
    with open(run_dir / ".picture.py", "w") as f:
        f.write(PICTURE_SCRIPT)
    python = VENV / "bin" / "python"
    try:
        subprocess.run([str(python), str(run_dir / ".picture.py"),
                        str(run_dir / f"{run.name}.usdc"), str(Path(png).resolve()),
                        str(1 + last), *map(str, target), str(distance)], check=True)
    finally:
        (run_dir / ".picture.py").unlink()


if __name__ == "__main__":
    # The picture of docs/export.md: python tests/test_blender_roundtrip.py RUN_DIR PNG
    render_picture(Path(sys.argv[1]), Path(sys.argv[2]))
