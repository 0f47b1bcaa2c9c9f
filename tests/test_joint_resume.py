"""A run with a shell body beside solids survives interruption (docs/resume.md).

``fem-anim run`` of a cloth falling on a soft cube, stopped by SIGINT or SIGTERM at a frame
(the signal sent from inside the run, after a given step, as the one-body tests do), says in
one line how to continue, and ``--resume`` continues it: stats (all but wall times), the three
trajectories' frames and the final states equal an uninterrupted run's to the last bit. The
interruption falls where the cloth touches the cube, so the joint barrier's adaptive
stiffness (:meth:`fem_anim.contact.ipc.IPCContact.state`) and the Hessian's pattern grown by
the contact pairs are part of what is resumed. A second signal stops the run at once; the
last periodic checkpoint continues it. A changed physics key is refused in one line naming
it, exit 2, nothing touched. Under ``mpirun``: a 2-rank run interrupted and resumed on 1 and
on 2 ranks, and a serial one resumed on 2, end where the serial uninterrupted run does, to
1e-8.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import os
import signal
import subprocess
import sys

import h5py
import numpy as np
import pytest

from fem_anim.cli import main
from fem_anim.simulation.joint_loop import JointSimulation
from test_shell_solid import DRAPE_SOFT

#: The cloth reaches the cube in step 2 (contact pairs from then on); 6 steps.
DRAPE = (DRAPE_SOFT.replace('name = "drape_soft"', 'name = "drape_resume"')
         .replace('integrator = "implicit_euler"', 'integrator = "bdf2"')
         .replace("render = false\n", "render = false\ncheckpoint_every = 2\n")
         .replace("offset = [0.0, 0.0, 0.103]", "offset = [0.0, 0.0, 0.1025]"))

#: Wall-time columns: the only ones allowed to differ.
TIMING = {"assembly_s", "factor_s", "linear_solve_s", "other_s", "solve_wall_s",
          "step_wall_s", "contact_s", "retry_wall_s"}
TRAJECTORIES = ("solids", "shell", "trajectory")


def _cli(*args) -> tuple[int, list[str]]:
    """``fem-anim ARGS`` in this process: (exit code, stderr lines)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main(list(args))
    return code, [line for line in err.getvalue().splitlines() if line.strip()]


def _signal_after(monkeypatch, steps: dict[int, int]) -> None:
    """Send this process signal ``steps[k]`` right after step k (every joint run)."""
    take = JointSimulation.timed_step

    def timed_step(self, state, dt):
        new, row = take(self, state, dt)
        if new.step in steps:
            os.kill(os.getpid(), steps[new.step])
        return new, row

    monkeypatch.setattr(JointSimulation, "timed_step", timed_step)


def _stats(out) -> list[dict]:
    with open(out / "stats.csv") as f:
        return [{k: v for k, v in row.items() if k not in TIMING} for row in csv.DictReader(f)]


def _frames(path) -> list[np.ndarray]:
    with h5py.File(path, "r") as h5:
        return [np.asarray(h5[f"data{k + 2}"]) for k in range(len(h5.attrs["times"]))]


def _same_run(a, b) -> None:
    """Stats (but wall times) and every frame of the three trajectories, bit for bit."""
    sa, sb = _stats(a), _stats(b)
    assert len(sa) == len(sb) == 6
    for x, y in zip(sa, sb):
        assert x == y, {k: (x[k], y[k]) for k in x if x[k] != y.get(k)}
    for name in TRAJECTORIES:
        fa, fb = _frames(a / f"{name}.h5"), _frames(b / f"{name}.h5")
        assert len(fa) == len(fb) == 7, name
        assert all(np.array_equal(x, y) for x, y in zip(fa, fb)), name


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """The uninterrupted run."""
    folder = tmp_path_factory.mktemp("whole")
    (folder / "drape.toml").write_text(DRAPE)
    code, err = _cli("run", "-q", str(folder / "drape.toml"), "-o", str(folder / "out"))
    assert code == 0, err
    stats = _stats(folder / "out")
    assert int(stats[0]["contact_pairs"]) == 0 < int(stats[2]["contact_pairs"])
    return folder / "out"


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_interrupted_joint_run_resumes_bit_for_bit(tmp_path, monkeypatch, whole, signum):
    """Stopped after step 3 (in contact, off the checkpoint_every = 2 beat: the signal
    writes the checkpoint), continued as its one line says: the same run to the last bit."""
    scene = tmp_path / "drape.toml"
    scene.write_text(DRAPE)
    out = tmp_path / "cut"
    with monkeypatch.context() as m:
        _signal_after(m, {3: signum})
        code, err = _cli("run", "-q", str(scene), "-o", str(out))
    assert code == 128 + signum
    assert len(err) == 1 and err[0].startswith(
        f"fem-anim: error: interrupted by {signum.name} at frame 3 of 6"), err
    assert f"continue with `fem-anim run -q {scene} --resume {out}`" in err[0], err[0]
    assert not (out / "stats.csv").exists()  # nothing posing as a result
    assert len(_stats(out / ".partial")) == 3
    stopped = json.loads(np.load(out / ".partial" / "checkpoint.npz")["meta"].tobytes())
    seen = []  # the joint barrier's state when the resumed run takes its first step
    take = JointSimulation.timed_step

    def timed_step(self, state, dt):
        if not seen:
            seen.append(self.problem.ipc.state())
        return take(self, state, dt)

    with monkeypatch.context() as m:
        m.setattr(JointSimulation, "timed_step", timed_step)
        code, err = _cli("run", str(scene), "--resume", str(out))
    assert code == 0, err
    assert err == [f"fem-anim: resuming {out} at frame 3 of 6 (t = 0.03 s) with the same "
                   "solver settings"], err
    # the stiffness floor balanced in contact continues (here it is ipctk's minimum
    # stiffness, which the motion alone would not tell from a recomputed one)
    assert stopped["contact"]["kappa_floor"] > 0.0 and stopped["contact"]["kappa_balanced"]
    assert seen == [stopped["contact"]]
    _same_run(whole, out)


def test_second_signal_stops_at_once_and_the_last_checkpoint_resumes(tmp_path, monkeypatch,
                                                                     whole):
    """SIGINT before step 3, again after it, before frame 3 ends: the run stops at once,
    keeps frame 2's checkpoint (checkpoint_every = 2) and resumes from it."""
    scene = tmp_path / "drape.toml"
    scene.write_text(DRAPE)
    out = tmp_path / "cut"
    with monkeypatch.context() as m:
        take = JointSimulation.timed_step

        def timed_step(self, state, dt):
            if state.step != 2:
                return take(self, state, dt)
            os.kill(os.getpid(), signal.SIGINT)  # noted: the run would stop at frame 3's end
            new, row = take(self, state, dt)
            os.kill(os.getpid(), signal.SIGINT)  # raises here, inside the frame
            raise AssertionError("the second signal did not stop the run")

        m.setattr(JointSimulation, "timed_step", timed_step)
        code, err = _cli("run", "-q", str(scene), "-o", str(out))
    assert code == 130
    assert len(err) == 1 and err[0].startswith("fem-anim: error: interrupted by SIGINT "
                                               "(twice)"), err
    assert "continue with" in err[0], err[0]
    code, err = _cli("run", str(scene), "--resume", str(out))
    assert code == 0, err
    assert err[0].startswith(f"fem-anim: resuming {out} at frame 2 of 6"), err
    _same_run(whole, out)


def test_physics_change_on_resume_is_refused_naming_the_key(tmp_path, monkeypatch):
    scene = tmp_path / "drape.toml"
    scene.write_text(DRAPE)
    out = tmp_path / "cut"
    with monkeypatch.context() as m:
        _signal_after(m, {3: signal.SIGINT})
        assert _cli("run", "-q", str(scene), "-o", str(out))[0] == 130
    before = sorted((p.name, p.stat().st_mtime_ns) for p in (out / ".partial").rglob("*"))
    code, err = _cli("run", "-q", str(scene), "--set", "body.1.material.youngs_modulus=2e5",
                     "--resume", str(out))
    assert code == 2
    assert len(err) == 1 and err[0].startswith("fem-anim: error: "), err
    assert "physics changed: body.1.material.youngs_modulus = 200000.0 (was 100000.0)" \
        in err[0], err[0]
    assert sorted((p.name, p.stat().st_mtime_ns) for p in (out / ".partial").rglob("*")) == \
        before


@pytest.mark.mpi
def test_resume_on_another_rank_count(tmp_path, monkeypatch, whole):
    """Interrupted under ``mpirun -n 2`` after step 3 (tests/mpi/mpi_joint_interrupt.py),
    resumed on 2 ranks and, from a copy, on 1; interrupted on 1 rank, resumed on 2: each
    ends where the serial uninterrupted run does, every frame and every step's total energy
    to 1e-8."""
    import shutil

    from conftest import ROOT, clean_environment, fem_anim_command, mpirun_command

    prefix = mpirun_command(2)
    if prefix is None:
        pytest.skip("mpirun not available")
    scene = tmp_path / "drape.toml"
    scene.write_text(DRAPE)
    out = tmp_path / "cut2"
    script = ROOT / "tests" / "mpi" / "mpi_joint_interrupt.py"
    r = subprocess.run([*prefix, sys.executable, str(script), "3", "run", "-q", str(scene),
                        "-o", str(out)], capture_output=True, text=True, timeout=900,
                       env=clean_environment(), cwd=ROOT)
    assert r.returncode == 130, r.stdout + r.stderr
    shutil.copytree(out, tmp_path / "cut1")
    with monkeypatch.context() as m:  # 1 -> 2: stopped in this process
        _signal_after(m, {3: signal.SIGINT})
        assert _cli("run", "-q", str(scene), "-o", str(tmp_path / "serial"))[0] == 130
    for ranks, folder in ((2, out), (1, tmp_path / "cut1"), (2, tmp_path / "serial")):
        command = (prefix if ranks == 2 else []) + fem_anim_command() + \
            ["run", "-q", str(scene), "--resume", str(folder)]
        r = subprocess.run(command, capture_output=True, text=True, timeout=900,
                           env=clean_environment(), cwd=ROOT)
        assert r.returncode == 0, r.stdout + r.stderr
        a, b = _stats(whole), _stats(folder)
        assert len(a) == len(b) == 6
        energy = np.array([[float(row["total_energy"]) for row in rows] for rows in (a, b)])
        print(f"{folder.name} resumed on {ranks}: total energy to "
              f"{np.max(np.abs(energy[1] / energy[0] - 1.0)):.2g} relative")
        assert np.allclose(energy[1], energy[0], rtol=1e-8, atol=0.0), ranks
        for name in TRAJECTORIES:
            fa, fb = _frames(whole / f"{name}.h5"), _frames(folder / f"{name}.h5")
            scale = np.abs(fa[-1]).max()
            assert len(fa) == len(fb) == 7
            gap = max(np.abs(x - y).max() for x, y in zip(fa, fb)) / scale
            print(f"{folder.name} resumed on {ranks}: {name} frames to {gap:.2g} of the "
                  "last frame's largest entry")
            assert gap <= 1e-8, (folder.name, ranks, name)
