"""The Python API: scenes from a file, a string or a dict, validated like a file; ``run``,
``open_run`` and ``Run``; a quiet JIT; and the examples in their docstrings, run as doctests."""

from __future__ import annotations

import doctest
import importlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fem_anim import compat

import fem_anim
from scenes import to_toml

from fem_anim.errors import FemAnimError, SceneError
from fem_anim.scene import load_scene, scene_keys

ROOT = Path(__file__).resolve().parents[1]
#: A two-step 2D cantilever of 8 triangles: the smallest run with every output.
TINY = {"name": "tiny", "mesh": {"dim": 2, "size": [1.0, 0.2], "divisions": [4, 1]},
        "time": {"steps": 2}, "output": {"render": False},
        "gravity": {"acceleration": [0.0, -9.81]},
        "pin": [{"name": "wall", "min": [-0.01, -1.0], "max": [0.01, 1.0]}]}
TINY_TOML = """name = "tiny"
[mesh]
dim = 2
size = [1.0, 0.2]
divisions = [4, 1]
[time]
steps = 2
[output]
render = false
[gravity]
acceleration = [0.0, -9.81]
[[pin]]
name = "wall"
min = [-0.01, -1.0]
max = [0.01, 1.0]
"""


@pytest.mark.parametrize("module", ["fem_anim.scene.loading", "fem_anim.scene.schema",
                                    "fem_anim.runs"])
def test_docstring_examples_run(module, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS)
    assert result.attempted > 0 and result.failed == 0, result


def test_import_fem_anim_loads_no_dolfinx():
    code = ("import sys, fem_anim; fem_anim.Scene; fem_anim.SceneError; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in "
            "('dolfinx', 'petsc4py', 'ufl', 'ffcx')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


def test_public_names():
    assert {"Scene", "run", "open_run", "Run", "Simulation", "SceneError", "FemAnimError",
            "ConvergenceError", "Interrupted", "__version__"} <= set(fem_anim.__all__)
    assert callable(fem_anim.run) and fem_anim.open_run is not None


@pytest.mark.parametrize("content", [
    {"mesh": {"shape": "banana"}},
    {"material": {"poisson_ratio": 0.5}},
    {"time": {"steps": 0}},
    {"pin": [{"min": [0, 0, 0]}]},
    {"body": [{"name": "a"}], "mesh": {"dim": 2}},
    {"bogus": 1},
])
def test_a_dict_fails_with_the_message_of_the_file(content, tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("".join(f"{key} = {to_toml(value)}\n" for key, value in content.items()))
    with pytest.raises(SceneError) as from_file:
        load_scene(path)
    with pytest.raises(SceneError) as from_dict:
        fem_anim.Scene.from_dict(content)
    with pytest.raises(SceneError) as from_text:
        fem_anim.Scene.from_toml(path.read_text())
    with pytest.raises(SceneError) as constructed:
        fem_anim.Scene(content)
    message = str(from_file.value).removeprefix(f"{path}: ")
    assert "\n" not in message and message != str(from_file.value)
    assert str(from_dict.value) == f"<dict>: {message}"
    assert str(from_text.value) == f"<string>: {message}"
    assert str(constructed.value) == f"<dict>: {message}"


def test_the_banana_of_the_issue():
    with pytest.raises(SceneError, match=r"^<dict>: mesh.shape must be one of box, sphere, "
                                         r"cylinder, torus, capsule, file, sheet, got 'banana'$"):
        fem_anim.Scene.from_dict({"mesh": {"shape": "banana"}})


def test_every_way_in_gives_the_same_scene(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY_TOML)
    original = json.dumps(TINY)
    scenes = [load_scene(path), fem_anim.Scene.load(path), fem_anim.Scene.from_toml(TINY_TOML),
              fem_anim.Scene.from_dict(TINY), fem_anim.Scene(TINY)]
    assert json.dumps(TINY) == original  # the caller's dict is not changed
    assert all(s.data == scenes[0].data for s in scenes)
    assert scenes[0]["solver"]["preset"] == "cholesky"  # complete: no KeyError downstream
    changed = fem_anim.Scene.from_dict(TINY, ["time.steps=5", "pin.0.name=clamp"])
    assert changed["time"]["steps"] == 5 and changed["pin"][0]["name"] == "clamp"
    assert fem_anim.Scene.load(None).name == "hanging_beam"


@pytest.mark.parametrize("bad, message", [
    ({}, "scene <dict> is empty (no keys)"),
    ([1], "<dict>: a scene is a table of sections (a dict), got [1]"),
])
def test_a_dict_that_is_no_scene(bad, message):
    with pytest.raises(SceneError) as err:
        fem_anim.Scene.from_dict(bad)
    assert str(err.value) == message


def test_scene_keys_cover_the_schema():
    keys = list(scene_keys())
    paths = {k.path for k in keys}
    for path in ("name", "element.formulation", "material.mooney_ratio", "body[i].offset",
                 "contact.stiffness", "region[i].youngs_modulus", "render.color_by",
                 "solver.mode", "pin[i].min", "obstacle[i].dhat"):
        assert path in paths, path
    assert all(k.doc and k.type and k.table is not None for k in keys)
    assert "mooney_rivlin" in next(k for k in keys if k.path == "material.model").choices
    assert "body" in next(k for k in keys if k.path == "render.color_by").choices
    assert next(k for k in keys if k.path == "time.dt").unit == "s"


def test_run_and_open_run_read_the_same_files(tmp_path):
    scene = fem_anim.Scene.from_dict(TINY)
    out = tmp_path / "out"
    result = fem_anim.run(scene, out)
    assert result.outdir == out and (out / "summary.json").is_file()
    again = fem_anim.open_run(out)
    assert np.array_equal(again.times, result.times) and len(result.times) == 3
    assert len(result.stats) == result.summary["steps"] == 2
    assert result.stats[-1]["newton_its"] >= 1
    assert np.array_equal(result.energy["total"], [r["total_energy"] for r in result.stats])
    assert result.points.shape == (10, 2) and result.cells.shape == (8, 3)
    assert not result.displacement(0).any()
    tip = result.displacement(2)[np.argmax(result.points[:, 0])]
    assert tip[1] < 0  # gravity pulls the free end down
    assert np.array_equal(result.displacement(-1), again.displacement(2))
    with pytest.raises(IndexError):
        result.displacement(3)
    result.close()
    assert out.is_dir()  # a directory the caller named is kept


def test_a_temporary_run_is_deleted_when_closed(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with fem_anim.run(fem_anim.Scene.from_dict(TINY)) as result:
        outdir = result.outdir
        assert (outdir / "stats.csv").is_file()
    assert not outdir.exists() and not outdir.parent.exists()
    assert list(tmp_path.iterdir()) == []  # nothing written into the working directory


def _signal_at_frame(monkeypatch, frame: int) -> None:
    """SIGINT to this process while frame ``frame`` is written (the first signal: the run
    stops at that frame's end with a checkpoint there)."""
    import signal

    from fem_anim.simulation.loop import Simulation

    fields, calls = Simulation.frame_fields, []

    def frame_fields(self, state):
        calls.append(state.time)
        if len(calls) == frame + 1:
            os.kill(os.getpid(), signal.SIGINT)
        return fields(self, state)

    monkeypatch.setattr(Simulation, "frame_fields", frame_fields)


def test_a_run_stopped_by_a_signal_resumes_from_python(tmp_path, monkeypatch):
    """``fem_anim.run(scene, outdir, resume=True)`` continues a run a signal stopped, as
    ``fem-anim run --resume`` does, and ends where the run nobody stopped ends; the stop's
    message says how (docs/python_api.md)."""
    scene = fem_anim.Scene.from_dict(TINY, ["time.steps=8", "output.checkpoint_every=1"])
    with fem_anim.run(scene) as whole:
        expected, stats = whole.displacement(-1), whole.stats
    out = tmp_path / "out"
    with monkeypatch.context() as m:
        _signal_at_frame(m, 3)
        with pytest.raises(fem_anim.Interrupted) as stop:
            fem_anim.run(scene, out)
    message = str(stop.value)
    assert f"fem_anim.run(scene, {str(out)!r}, resume=True)" in message, message
    assert "\n" not in message and not (out / "stats.csv").exists()
    from fem_anim.simulation.loop import Simulation

    steps, step = [], Simulation.timed_step
    monkeypatch.setattr(Simulation, "timed_step",
                        lambda self, *a: steps.append(1) or step(self, *a))
    resumed = fem_anim.run(scene, out, resume=True)
    assert len(steps) == 8 - 3  # from the checkpoint at frame 3, not from the start
    assert len(resumed.times) == 9
    assert np.array_equal(resumed.displacement(-1), expected)
    assert [r["newton_its"] for r in resumed.stats] == [r["newton_its"] for r in stats]


@pytest.mark.mpi
def test_a_run_stopped_under_mpirun_resumes_from_python(tmp_path):
    """The same under ``mpirun -n 2`` (tests/mpi/mpi_api_resume.py): every rank stops at
    frame 3, the resume takes the 5 steps left and ends where the whole run ends."""
    from conftest import ROOT, clean_environment, mpirun_command

    prefix = mpirun_command(2)
    if prefix is None:
        pytest.skip("mpirun not available")
    out = tmp_path / "out"
    r = subprocess.run([*prefix, sys.executable, str(ROOT / "tests" / "mpi" /
                                                     "mpi_api_resume.py"), str(out)],
                       capture_output=True, text=True, timeout=600, env=clean_environment(),
                       cwd=tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr
    lines = dict(line.split(" ", 1) for line in r.stdout.splitlines() if " " in line)
    assert "resume=True" in lines["STOP"] and "frame 3 of 8" in lines["STOP"], r.stdout
    taken, frames, gap = lines["RESUMED"].split()
    assert (int(taken), int(frames)) == (5, 9) and float(gap) <= 1e-12, r.stdout


def test_resume_needs_the_stopped_runs_directory(tmp_path, monkeypatch):
    """``resume=True`` without ``outdir`` or with no checkpoint there is refused in one line;
    a temporary run that a signal stops leaves no temporary folder behind."""
    import tempfile

    from fem_anim.errors import Interrupted

    scene = fem_anim.Scene.from_dict(TINY, ["time.steps=6", "output.checkpoint_every=1"])
    with pytest.raises(FemAnimError, match="give outdir"):
        fem_anim.run(scene, resume=True)
    with pytest.raises(FemAnimError, match="resume"):
        fem_anim.run(scene, tmp_path / "never_ran", resume=True)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    _signal_at_frame(monkeypatch, 2)
    with pytest.raises(Interrupted) as stop:
        fem_anim.run(scene)
    assert "resume=True" not in str(stop.value)
    assert list((tmp_path / "tmp").iterdir()) == []


def test_run_takes_a_scene():
    with pytest.raises(TypeError, match="fem_anim.Scene"):
        fem_anim.run(TINY)


def test_open_run_names_what_is_wrong(tmp_path):
    (tmp_path / "file").write_text("x")
    (tmp_path / "half" / ".partial").mkdir(parents=True)
    (tmp_path / "empty").mkdir()
    cases = {"nothing": "it does not exist", "file": "it is a file",
             "half": "it is unfinished", "empty": "no trajectory.h5, stats.csv, summary.json"}
    for name, why in cases.items():
        with pytest.raises(FemAnimError) as err:
            fem_anim.open_run(tmp_path / name)
        assert str(err.value).startswith(f"{tmp_path / name} is not a finished fem-anim run: "
                                         f"{why}")


JIT_SCRIPT = """
import logging, sys
import fem_anim
if sys.argv[1] == "asked":
    logging.getLogger().setLevel(logging.INFO)
scene = fem_anim.Scene.from_dict({"mesh": {"dim": 2, "size": [1.0, 0.2],
                                  "divisions": [2, 1]}, "time": {"steps": 1},
                                  "output": {"render": False}})
with fem_anim.run(scene):
    pass
root = logging.getLogger()
print(root.level, [h.level for h in root.handlers],
      root.filters + [f for h in root.handlers for f in h.filters])
"""


@pytest.mark.skipif(not compat.LEGACY, reason="FFCx 0.9's JIT logged no build_ext line here, "
                    "even when asked (measured on Debian 13): nothing to quiet")
@pytest.mark.parametrize("asked", [False, True])
def test_the_jit_is_quiet_unless_asked(asked, tmp_path):
    cache = tmp_path / "cache"  # a fresh FFCx cache: every form is really compiled
    env = dict(os.environ, XDG_CACHE_HOME=str(cache))
    out = subprocess.run([sys.executable, "-c", JIT_SCRIPT, "asked" if asked else "quiet"],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert out.returncode == 0, out.stderr
    assert list(cache.rglob("*.so")), "the JIT did not run"
    assert ("running build_ext" in out.stderr) == asked, out.stderr
    level = 20 if asked else 30  # the root logger is as the program left it, unfiltered
    assert out.stdout.split() == [str(level), "[0]", "[]"]
