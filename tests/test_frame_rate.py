"""Frames at the animator's rate: ``output.fps`` and ``output.start_frame``
(:mod:`fem_anim.simulation.frame_clock`).

Frame k is the converged state at t = k/fps, reached by equal substeps no longer than
``time.dt`` (never an interpolation across a step); the run covers ``steps * dt`` up to the
next whole frame; the pictures play at the frame rate (real time).
"""

from __future__ import annotations

import numpy as np
import pytest

import fem_anim
from fem_anim.errors import SceneError
from fem_anim.scene.constraints import MAX_STEPS
from fem_anim.simulation.frame_clock import frame_clock

#: A 2D cantilever of 8 triangles under gravity, dt = 0.01 s, which does not divide 1/24 s.
CANTILEVER = {"name": "frames", "mesh": {"dim": 2, "size": [1.0, 0.2], "divisions": [4, 1]},
              "time": {"dt": 0.01, "steps": 10}, "output": {"render": False, "fps": 24},
              "material": {"youngs_modulus": 2.0e4},
              "gravity": {"acceleration": [0.0, -9.81]},
              "pin": [{"name": "wall", "min": [-0.01, -1.0], "max": [0.01, 1.0]}]}


def _scene(**changes):
    data = {k: dict(v) if isinstance(v, dict) else v for k, v in CANTILEVER.items()}
    for key, value in changes.items():
        section, name = key.split("__")
        data[section][name] = value
    return fem_anim.Scene.from_dict(data)


@pytest.mark.parametrize("dt, steps, fps, substeps, count", [
    (1 / 60, 60, 24, 3, 24),   # the default dt: 1/24 s in 3 steps of 1/72 s
    (1 / 60, 60, 30, 2, 30),   # the default dt divides 1/30 s: the steps of dt
    (0.01, 100, 25, 4, 25),    # 0.04 s in 4 steps of dt
    (0.1, 3, 30, 1, 9),        # 3 * 0.1 * 30 is 9.000000000000002 in floating point: 9
    (0.01, 10, 24, 5, 3),      # 0.1 s is 2.4 frames: up to the next whole frame
    (0.1, 3, 24, 1, 8),        # dt longer than a frame: one step per frame
    (0.001, 3, 24, 42, 1),     # shorter than a frame: one frame
    (1e100, 2, 1e-100, 1, 2),  # one huge step per frame
    (1e-9, 1, 1e-3, 10**12, 1),  # more than MAX_STEPS steps: refused
])
def test_frame_clock(dt, steps, fps, substeps, count):
    scene = _scene(time__dt=dt, time__steps=steps, output__fps=fps)
    if substeps * count > MAX_STEPS:
        with pytest.raises(SceneError, match="more than 1000000000 steps"):
            frame_clock(scene)
        return
    clock = frame_clock(scene)
    assert (clock.substeps, clock.count) == (substeps, count)
    assert clock.step <= dt * (1 + 1e-12) and clock.step * substeps == pytest.approx(1 / fps)
    assert clock.end >= steps * dt * (1 - 1e-9) and clock.end - 1 / fps < steps * dt


def test_default_frame_rate_and_start_frame():
    """Without output.fps a run keeps the step clock: frame k is step k at exactly k dt."""
    scene = fem_anim.Scene.from_dict({"name": "defaults", "time": {"dt": 0.1, "steps": 7}})
    clock = frame_clock(scene)
    assert (clock.start_frame, clock.number(0), clock.substeps, clock.count) == (1, 1, 1, 7)
    assert clock.step == 0.1 and [clock.time(k) for k in range(8)] == [k * 0.1 for k in range(8)]


def test_frames_are_converged_states_at_the_frame_times(tmp_path):
    """Each written frame equals a hand-driven loop of equal steps h = (1/24)/5 at its time,
    and each frame time is the end of an accepted, converged step."""
    scene = _scene()
    with fem_anim.run(scene, tmp_path / "out") as run:
        times, frames = run.times, [run.displacement(k) for k in range(len(run.times))]
        rows = run.stats
    assert np.array_equal(times, np.arange(4) / 24.0)
    ends = np.array([r["time"] for r in rows])
    assert len(rows) == 15 and np.allclose(np.diff(np.r_[0.0, ends]), 1 / 120, rtol=1e-9)
    assert all(np.isclose(ends, t, rtol=0, atol=1e-12).any() for t in times[1:])
    sim = fem_anim.Simulation(scene)
    state = sim.initial_state()
    for k in range(1, 4):
        for _ in range(5):
            state, _stats = sim.step(state, 1 / 120)
        expected, _psi = sim.frame_fields(state)
        np.testing.assert_allclose(frames[k], expected, rtol=0, atol=1e-10)
    assert np.abs(frames[3]).max() > 1e-3  # it moved


def test_output_every_keeps_frame_times(tmp_path):
    scene = _scene(output__every=2)
    with fem_anim.run(scene, tmp_path / "out") as run:
        assert np.array_equal(run.times, np.array([0.0, 2.0, 3.0]) / 24.0)


def test_pictures_play_at_the_frame_rate(tmp_path):
    """The render's default rate is real time: the frame rate of the trajectory."""
    from fem_anim.render.animation import _frame_rate

    with fem_anim.run(_scene(output__fps=30), tmp_path / "out") as run:
        assert _frame_rate({"fps": None}, run.times) == pytest.approx(30.0, rel=1e-12)


def test_interrupted_and_resumed_run_is_the_uninterrupted_one(tmp_path):
    """Frames at 1/24 s from 1/120 s steps (dt = 0.01 s): a run stopped by SIGINT after a
    few frames and resumed writes the same frames and stats as one run straight through.

    (Needs the checkpoint's validation to use the frame clock: frame k at k/fps.)"""
    import signal
    import subprocess
    import time

    from conftest import clean_environment, fem_anim_command

    args = ["run", "-q", "--set", "mesh.element_size=0.1", "--set", "time.dt=0.01",
            "--set", "time.steps=40", "--set", "output.fps=24",
            "--set", "output.checkpoint_every=2", "--set", "output.render=false"]
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    r = subprocess.run(fem_anim_command() + args + ["-o", str(whole)], capture_output=True,
                       text=True, env=clean_environment(), cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr
    proc = subprocess.Popen(fem_anim_command() + args + ["-o", str(cut)], cwd=tmp_path,
                            env=clean_environment(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True)
    partial = cut / ".partial" / "stats.csv"
    deadline = time.time() + 300
    while time.time() < deadline and proc.poll() is None:
        if partial.exists() and len(partial.read_text().splitlines()) > 12:
            proc.send_signal(signal.SIGINT)
            break
        time.sleep(0.005)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 130 and "interrupted by SIGINT at frame" in err, err
    r = subprocess.run(fem_anim_command() + args + ["--resume", str(cut)], capture_output=True,
                       text=True, env=clean_environment(), cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr
    a, b = fem_anim.open_run(whole), fem_anim.open_run(cut)
    assert np.array_equal(a.times, np.arange(11) / 24.0) and np.array_equal(a.times, b.times)
    assert [r["time"] for r in a.stats] == [r["time"] for r in b.stats]
    for k in range(len(a.times)):
        np.testing.assert_allclose(b.displacement(k), a.displacement(k), rtol=0, atol=1e-12)
