"""Every contact scene ends: it finishes, or stops at once with one line and exit code 2.

Parallel faces and edges (axis-aligned boxes face to face, a box stacked on a box) are the
worst case of tight-inclusion CCD: its intervals never shrink to an inclusion, so each pair
uses the whole bisection cap (ipctk's default 1e7 made one CCD call of the face-to-face cubes
take 35 s). Contact settings outside what the barrier can represent, and handles driving held
vertices into each other, are refused when the scene is read. A second signal inside a long
library call stops the run within seconds (the watcher process of
:mod:`fem_anim.simulation.signal_watch`).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from fem_anim.cli import main
from fem_anim.errors import SceneError
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation

pytestmark = pytest.mark.serial

#: Two axis-aligned cubes thrown face to face (6 tetrahedra each; parallel faces and edges).
FACE_TO_FACE = """
name = "face_to_face"
[time]
dt = 0.01
steps = 6
integrator = "implicit_euler"
[contact]
dhat = 0.005
[[body]]
name = "left"
offset = [-0.11, 0, 0]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.1 }
initial = { velocity = [2.0, 0, 0] }
[[body]]
name = "right"
offset = [0.01, 0.0, 0]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.1 }
initial = { velocity = [-2.0, 0, 0] }
"""

#: A box dropped flat onto a box on the ground (parallel faces at rest).
STACKED = """
name = "stacked"
[time]
dt = 0.02
steps = 8
integrator = "implicit_euler"
[gravity]
acceleration = [0, 0, -9.81]
[contact]
dhat = 0.001
[[obstacle]]
type = "plane"
normal = [0, 0, 1]
dhat = 0.001
[[body]]
name = "bottom"
offset = [0, 0, 0.002]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.1 }
[[body]]
name = "top"
offset = [0, 0, 0.104]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.1 }
initial = { velocity = [0, 0, -0.5] }
"""

#: Two cubes each held whole by a handle, driven into each other.
HANDLES = """
name = "handles"
[time]
dt = 0.01
steps = 20
[contact]
dhat = 0.005
[[body]]
name = "left"
offset = [-0.11, 0, 0]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.1 }
[[body.pin]]
min = [-1, -1, -1]
max = [1, 1, 1]
velocity = [VL, 0, 0]
[[body]]
name = "right"
offset = [0.01, 0, 0]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.1 }
[[body.pin]]
min = [-1, -1, -1]
max = [1, 1, 1]
velocity = [VR, 0, 0]
"""



def _throw(n: int, steps: int) -> str:
    """``n`` axis-aligned 2 cm cubes on a grid, thrown at the grid's centre."""
    lines = [f'name = "throw{n}"', "[time]", "dt = 0.01", f"steps = {steps}",
             'integrator = "implicit_euler"', "[contact]", "dhat = 0.001"]
    cells = [(i, j, k) for i in range(5) for j in range(4) for k in range(3)][:n]
    for b, (i, j, k) in enumerate(cells):
        x, y, z = 0.05 * (i - 2), 0.05 * (j - 1.5), 0.05 * (k - 1)
        lines += ["[[body]]", f'name = "b{b}"', f"offset = [{x}, {y}, {z}]",
                  'mesh = { shape = "box", size = [0.02, 0.02, 0.02], element_size = 0.02 }',
                  f"initial = {{ velocity = [{-12 * x}, {-12 * y}, {-12 * z}] }}"]
    return "\n".join(lines) + "\n"


def _run_in_time(tmp_path: Path, text: str, seconds: float) -> Simulation:
    path = tmp_path / "scene.toml"
    path.write_text(text)
    sim = Simulation(load_scene(path, ["output.render=false"]))
    start = time.perf_counter()
    result = sim.run(tmp_path / "out", quiet=True)
    wall = time.perf_counter() - start
    ipc = sum(row["contact_s"] for row in result.rows)  # ipctk's time, failed tries included
    print(f"{len(result.rows)} steps in {wall:.2f} s, ipctk {ipc:.3f} s")
    assert len(result.rows) >= sim.scene["time"]["steps"]
    assert result.rows[-1]["time"] == pytest.approx(
        sim.scene["time"]["dt"] * sim.scene["time"]["steps"])
    assert ipc < 0.5 * seconds, "the contact library's work is not bounded"
    assert max(row["contact_pairs"] for row in result.rows) > 0  # the bodies did meet
    assert wall < seconds
    return sim


def test_face_to_face_cubes_finish(tmp_path):
    """Measured: 0.6 s (one CCD call took 35 s with ipctk's default cap of 1e7)."""
    _run_in_time(tmp_path, FACE_TO_FACE, 20.0)


def test_stacked_boxes_finish(tmp_path):
    _run_in_time(tmp_path, STACKED, 30.0)


def test_throw_of_12_bodies_finishes(tmp_path):
    """The reduced variant of the 60-body throw: 12 cubes meeting at the centre."""
    _run_in_time(tmp_path, _throw(12, 8), 60.0)


@pytest.mark.slow
def test_throw_of_60_bodies_finishes(tmp_path):
    """Measured: 6 frames in about 15 minutes on a shared machine (dt halved to 1.6e-4 s at
    the impacts, up to 7,000 pairs; the time is Newton's, not the CCD's)."""
    _run_in_time(tmp_path, _throw(60, 6), 2400.0)


@pytest.mark.parametrize("key, value, says", [
    ("contact.stiffness", "1e150", "contact.stiffness must be at most"),
    ("contact.stiffness", "1e-150", "contact.stiffness must be at least"),
    ("contact.dhat", "1e-150", "contact.dhat must be at least"),
    ("contact.dhat", "0.2", "contact.dhat must be smaller than every body"),
    ("contact.friction", "1e100", "contact.friction must be at most"),
    ("obstacle", '[{type = "plane", normal = [0, 0, 1], point = [0, 0, -1], '
     'stiffness = 1e150}]', "obstacle[0].stiffness must be at most"),
])
def test_hostile_contact_settings_give_one_line_and_exit_2(tmp_path, capsys, key, value,
                                                           says):
    path = tmp_path / "scene.toml"
    path.write_text(FACE_TO_FACE)
    code = main(["run", str(path), "-o", str(tmp_path / "out"), "--set", f"{key}={value}"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("fem-anim: error:"), err
    assert says in err[0], err[0]
    assert not (tmp_path / "out").exists()


def test_sane_contact_settings_are_accepted():
    """The bounds refuse only the extremes: the demos' and tests' settings pass."""
    for override in ("contact.stiffness=1e5", "contact.stiffness=10.0", "contact.friction=2.0",
                     "contact.dhat=1e-6"):
        load_scene_text(FACE_TO_FACE, [override])


def load_scene_text(text: str, overrides: list[str]):
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "scene.toml"
        path.write_text(text)
        return load_scene(path, overrides)


def test_dhat_above_the_element_size_is_refused():
    fine = FACE_TO_FACE.replace("element_size = 0.1", "element_size = 0.05")
    load_scene_text(fine, ["contact.dhat=0.04"])
    with pytest.raises(SceneError, match=r"contact.dhat must be smaller than the smallest "
                                         r"element size \(0.05 m\), got 0.07"):
        load_scene_text(fine, ["contact.dhat=0.07"])


def test_handles_driven_into_each_other_are_refused():
    with pytest.raises(SceneError, match=r"drive held vertices into each other .* t = 0\.0075 s"):
        load_scene_text(HANDLES.replace("VL", "1.0").replace("VR", "-1.0"), [])
    # one still, one driven into it: also contradictory
    with pytest.raises(SceneError, match="drive held vertices into each other"):
        load_scene_text(HANDLES.replace("VL", "0.0").replace("VR", "-1.0"), [])
    # apart, together, or stopping in time: fine
    load_scene_text(HANDLES.replace("VL", "-1.0").replace("VR", "1.0"), [])
    load_scene_text(HANDLES.replace("VL", "1.0").replace("VR", "1.0"), [])
    stop = HANDLES.replace("VL", "0.0").replace("VR", "-1.0") + "until = 0.01\n"
    load_scene_text(stop, [])


def test_handle_driven_into_the_ground_is_refused():
    text = HANDLES.replace("VL", "0.0").replace("VR", "0.0").replace(
        "velocity = [0.0, 0, 0]\n[[body]]", "velocity = [0, 0, -1.0]\n[[body]]", 1) + \
        '[[obstacle]]\ntype = "plane"\nnormal = [0, 0, 1]\npoint = [0, 0, -0.1]\n'
    with pytest.raises(SceneError, match=r"body\[0\]\.pin\[0\].*drives held vertices into "
                                         r"obstacle\[0\]"):
        load_scene_text(text, [])


SLOW_CCD = """
import hashlib, sys
from pathlib import Path
import ipctk
from fem_anim.cli import main

def slow(*args, **kwargs):  # a long call of compiled code, deaf to Python's handlers
    Path(sys.argv[1]).write_text("in the CCD")
    hashlib.pbkdf2_hmac("sha256", b"fem", b"anim", 2 ** 31 - 1)
    raise AssertionError("not stopped")

ipctk.compute_collision_free_stepsize = slow
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_second_signal_stops_a_run_inside_a_library_call(tmp_path, signum):
    """The run is inside a 'CCD' that never returns: the first signal is noted, the second
    ends the run within seconds with one line; its directory stays resumable."""
    path = tmp_path / "scene.toml"
    path.write_text(FACE_TO_FACE)
    marker = tmp_path / "marker"
    script = tmp_path / "slow.py"
    script.write_text(SLOW_CCD)
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, str(script), str(marker), "run", str(path),
                             "-o", str(out), "--set", "output.render=false"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, env=os.environ | {"OMP_NUM_THREADS": "1"})
    try:
        deadline = time.time() + 300
        while not marker.exists():
            assert proc.poll() is None and time.time() < deadline, proc.communicate()
            time.sleep(0.05)
        time.sleep(0.5)
        proc.send_signal(signum)
        time.sleep(0.5)
        assert proc.poll() is None  # the first signal waits for the end of the frame
        sent = time.time()
        proc.send_signal(signum)
        _, stderr = proc.communicate(timeout=30)
        took = time.time() - sent
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    print(f"stopped {took:.2f} s after the second signal: {stderr!r}")
    assert took < 10
    lines = [line for line in stderr.splitlines()  # past the first line naming the integrator
             if line.strip() and not line.startswith("fem-anim: contact scene:")]
    assert len(lines) == 1 and lines[0].startswith("fem-anim: error: interrupted by "
                                                   f"{signum.name} (twice)"), stderr
    assert (out / ".partial").is_dir()  # kept: nothing deleted


@pytest.mark.parametrize("error", [MemoryError(), RuntimeError("PETSc error code 55\ndetail")])
def test_library_error_is_one_line_and_exit_2(tmp_path, capsys, monkeypatch, error):
    """An exception of a compiled library inside the run is one line, not a traceback."""
    import ipctk

    def fail(*args, **kwargs):
        raise error

    monkeypatch.setattr(ipctk, "compute_collision_free_stepsize", fail)
    path = tmp_path / "scene.toml"
    path.write_text(FACE_TO_FACE)
    code = main(["run", str(path), "-o", str(tmp_path / "out"), "--set",
                 "output.render=false", "-q"])  # -q: no first line naming the integrator
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("fem-anim: error:"), err
    assert ("out of memory" in err[0]) == isinstance(error, MemoryError), err[0]
    assert "PETSc error code 55" in err[0] or isinstance(error, MemoryError)
