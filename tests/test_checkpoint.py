"""Long runs survive interruption: SIGKILL mid-run, ``--resume``, and the same results.

The resumed run's stats (all but wall-clock columns) and final displacement equal an
uninterrupted run's to 1e-12 relative (direct solver); the trajectory killed between
frames stays readable, and after resuming holds every frame once.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
import os
import signal
import subprocess
import time

import meshio
import numpy as np
import pytest
from conftest import clean_environment, fem_anim_command, kill_tree, mpirun_command

ARGS = ["run", "-q", "--set", "time.steps=150", "--set", "mesh.element_size=0.1",
        "--set", "output.checkpoint_every=10", "--set", "output.render=false",
        "--set", "material.model=stvk"]
TIMING = {"assembly_s", "factor_s", "linear_solve_s", "other_s", "solve_wall_s", "step_wall_s"}


def stats(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def frames(xdmf):
    with meshio.xdmf.TimeSeriesReader(str(xdmf)) as reader:
        reader.read_points_cells()
        return [reader.read_data(k)[:2] for k in range(reader.num_steps)]


def fem_anim(args: list[str], cwd) -> subprocess.CompletedProcess:
    """``python -m fem_anim ARGS`` in a fresh process, outside the test's MPI job."""
    return subprocess.run(fem_anim_command() + args, env=clean_environment(), cwd=cwd,
                          capture_output=True, text=True, timeout=600)


def kill_midway(command: list[str], out, cwd) -> None:
    """Start ``command -o out`` and SIGKILL it (and its children) after ~45 stats rows."""
    proc = subprocess.Popen(command + ["-o", str(out)], env=clean_environment(), cwd=cwd,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    partial_stats = out / ".partial" / "stats.csv"
    deadline = time.time() + 300
    while time.time() < deadline:
        if partial_stats.exists() and len(partial_stats.read_text().splitlines()) > 45:
            break
        time.sleep(0.005)
    kill_tree(proc.pid, signal.SIGKILL)
    proc.wait()
    assert proc.returncode == -signal.SIGKILL, "the run finished before it could be killed"


def test_kill_and_resume_equals_an_uninterrupted_run(tmp_path):
    whole = tmp_path / "whole"
    r = fem_anim(ARGS + ["-o", str(whole)], tmp_path)
    assert r.returncode == 0, r.stderr

    killed = tmp_path / "killed"
    kill_midway(fem_anim_command() + ARGS, killed, tmp_path)
    # nothing poses as a result; the staged trajectory is readable up to its last frame
    assert not (killed / "stats.csv").exists() and not (killed / "final.vtu").exists()
    staged = frames(killed / ".partial" / "trajectory.xdmf")
    assert 40 <= len(staged) < 151

    r = fem_anim(ARGS + ["--resume", str(killed)], tmp_path)
    assert r.returncode == 0, r.stderr
    a, b = stats(whole / "stats.csv"), stats(killed / "stats.csv")
    assert len(a) == len(b) >= 150  # adaptive substeps included
    for ra, rb in zip(a, b):
        for key in ra:
            if key in TIMING:
                continue
            x, y = float(ra[key]), float(rb[key])
            assert y == pytest.approx(x, rel=1e-12, abs=1e-300) or (np.isnan(x) and np.isnan(y)), \
                (ra["step"], key)
    ua = meshio.read(whole / "final.vtu").point_data["displacement"]
    ub = meshio.read(killed / "final.vtu").point_data["displacement"]
    assert np.linalg.norm(ub - ua) <= 1e-12 * np.linalg.norm(ua)
    fa, fb = frames(whole / "trajectory.xdmf"), frames(killed / "trajectory.xdmf")
    assert [t for t, _ in fa] == [t for t, _ in fb] and len(fa) == 151
    for (_, da), (_, db) in zip(fa, fb):
        np.testing.assert_allclose(db["displacement"], da["displacement"], rtol=0,
                                   atol=1e-12 * np.abs(ua).max())
    assert not (killed / ".partial").exists()


def test_resume_without_an_unfinished_run_is_a_clear_error(tmp_path):
    r = fem_anim(ARGS + ["--resume", str(tmp_path / "nothing")], tmp_path)
    assert r.returncode == 2 and "nothing to resume" in r.stderr and "Traceback" not in r.stderr


@pytest.mark.mpi
def test_kill_under_mpi_and_resume_on_another_process_count(tmp_path):
    """Killed under mpirun -n 2, resumed serially: the same run (to 1e-8, as MPI = serial).

    Checkpoints key dofs by their coordinates, not by the partition-dependent numbering.
    """
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    # neo-Hookean: no substeps here (StVK substeps, and round-off decides which steps
    # fail, so serial and parallel take different adaptive paths)
    args = ARGS[:-1] + ["material.model=neohookean"]
    whole = tmp_path / "whole"
    r = fem_anim(args + ["-o", str(whole)], tmp_path)
    assert r.returncode == 0, r.stderr
    killed = tmp_path / "killed"
    kill_midway(mpirun + fem_anim_command() + args, killed, tmp_path)
    r = fem_anim(args + ["--resume", str(killed)], tmp_path)
    assert r.returncode == 0, r.stderr
    a, b = stats(whole / "stats.csv"), stats(killed / "stats.csv")
    assert len(a) == len(b) == 150
    for ra, rb in zip(a, b):
        for key in ("kinetic", "elastic", "gravity"):
            assert float(rb[key]) == pytest.approx(float(ra[key]), rel=1e-8), (ra["step"], key)
    ua = meshio.read(whole / "final.vtu").point_data["displacement"]
    ub = meshio.read(killed / "final.vtu").point_data["displacement"]
    assert np.linalg.norm(ub - ua) <= 1e-8 * np.linalg.norm(ua)


# -- resume semantics: every integrator, contact, mixed u-p, any extent, solver changes -------
TINY = """
name = "tiny"
[mesh]
dim = 2
size = [1.0, 0.2]
element_size = 0.1
[gravity]
acceleration = [0.0, -9.81]
[[pin]]
name = "wall"
min = [-1e-6, -1.0]
max = [1e-6, 1.0]
[time]
dt = 0.02
steps = 6
[output]
render = false
checkpoint_every = 1000
"""

#: Two soft cubes thrown at each other with friction: the resume falls inside the impact.
CUBES = """
name = "cubes"
[time]
dt = 0.01
steps = 7
integrator = "implicit_euler"
[solver.petsc]
snes_atol = 1e-11
snes_rtol = 1e-14
[output]
render = false
checkpoint_every = 1000
[contact]
dhat = 0.005
friction = 0.3
[[body]]
name = "left"
offset = [-0.11, 0, 0]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.05 }
material = { youngs_modulus = 1e5, density = 1000 }
initial = { velocity = [1.0, 0.2, 0] }
[[body]]
name = "right"
offset = [0.03, 0.0, 0]
rotation = [0, 0, 10]
mesh = { shape = "box", size = [0.1, 0.1, 0.1], element_size = 0.05 }
material = { youngs_modulus = 2e5, density = 800 }
initial = { velocity = [-1.0, 0, 0] }
"""


def _scene(tmp_path, text: str, overrides: list[str] = ()):
    from fem_anim.scene import load_scene

    path = tmp_path / "scene.toml"
    path.write_text(text)
    return load_scene(str(path), list(overrides))


def _interrupt_at(sim, step: int) -> None:
    """SIGINT this process once the run has taken ``step`` steps (it stops at that frame)."""
    take = sim.timed_step

    def timed_step(state, dt):
        new, row = take(state, dt)
        if new.step == step:
            os.kill(os.getpid(), signal.SIGINT)
        return new, row

    sim.timed_step = timed_step


def resumed_equals_uninterrupted(tmp_path, scene, stop: int, probe=None, seen=None):
    """Run ``scene`` whole; again, interrupted after ``stop`` steps and resumed (in this
    process, each run its own Simulation). Returns both results. With ``probe``, append
    ``probe(sim)`` to ``seen`` for the interrupted Simulation once it stopped and for the
    resumed one before its first step."""
    from fem_anim.errors import Interrupted
    from fem_anim.simulation.loop import Simulation

    whole = Simulation(scene).run(tmp_path / "whole", quiet=True)
    cut = Simulation(scene)
    _interrupt_at(cut, stop)
    with pytest.raises(Interrupted):
        cut.run(tmp_path / "cut", quiet=True)
    sim = Simulation(scene)
    if probe is not None:
        seen.append(probe(cut))
        take = sim.timed_step

        def timed_step(state, dt):
            if len(seen) == 1:
                seen.append(probe(sim))
            return take(state, dt)

        sim.timed_step = timed_step
    resumed = sim.run(tmp_path / "cut", quiet=True, resume=True)
    return whole, resumed


def assert_same_run(whole, resumed, rel: float = 0.0) -> None:
    """Every stats row (but wall times; residuals at the round-off floor only with ``rel``
    > 0) and the final state, to the last bit or to ``rel``."""
    assert len(whole.rows) == len(resumed.rows)
    floor = {"residual_norm", "residual_ratio", "newton_decrement"} if rel else set()
    for a, b in zip(whole.rows, resumed.rows):
        assert a.keys() == b.keys()
        energy = max(abs(a[k]) for k in ("kinetic", "elastic", "gravity", "contact"))
        for key in a.keys() - TIMING - floor - {"contact_s"}:
            scale = energy if key == "total_energy" else 0.0  # a sum that cancels
            assert b[key] == pytest.approx(a[key], rel=rel, abs=rel * scale, nan_ok=True), \
                (a["step"], key, a[key], b[key])
    for name in ("u", "v"):
        x, y = getattr(whole.state, name), getattr(resumed.state, name)
        assert np.linalg.norm(y - x) <= rel * np.linalg.norm(x), name


@pytest.mark.parametrize("integrator", ["newmark", "implicit_euler", "bdf2"])
def test_resume_equals_uninterrupted_for_every_integrator(tmp_path, integrator):
    """BDF2 continues from its two previous states, Newmark from its acceleration."""
    scene = _scene(tmp_path, TINY, [f'time.integrator="{integrator}"'])
    assert_same_run(*resumed_equals_uninterrupted(tmp_path, scene, stop=3))


def test_contact_resume_inside_an_impact_is_bit_for_bit(tmp_path):
    """IPC's adaptive stiffness, the friction lagged at the step start and the Hessian's
    pattern grown by the contact pairs met so far continue as they were."""
    scene = _scene(tmp_path, CUBES)
    floors = []  # IPC's floor of the adaptive kappa: when stopped, and when resumed
    whole, resumed = resumed_equals_uninterrupted(
        tmp_path, scene, stop=3, probe=lambda sim: sim.problem.ipc.kappa_floor, seen=floors)
    assert int(whole.rows[2]["contact_pairs"]) > 0 and int(whole.rows[3]["contact_pairs"]) > 0
    assert floors[0] > 0.0 and floors[1] == floors[0]
    assert_same_run(whole, resumed)


def test_mixed_resume_keeps_the_pressure(tmp_path):
    """The mixed (u, p) formulation starts each Newton solve from the last pressure. To
    round-off only: MUMPS's analysis of a symmetric indefinite matrix (its pivot order)
    depends on the values of the first matrix it factors, step 1's or the resumed step's."""
    scene = _scene(tmp_path, TINY, ["element.degree=2", 'element.formulation="mixed"',
                                    "material.poisson_ratio=0.5",
                                    'material.model="stable_neohookean"',
                                    'solver.preset="ldlt"'])
    assert_same_run(*resumed_equals_uninterrupted(tmp_path, scene, stop=3), rel=1e-12)


def test_resume_at_any_scene_extent(tmp_path):
    """A second body 1e8 m away: dofs are keyed by their input vertex, not their position
    (quantised to 1e-9 of the extent, 0.1 m here, neighbouring vertices would collide)."""
    far = CUBES.replace("offset = [0.03, 0.0, 0]", "offset = [1e8, 0.0, 0]") + \
        "[gravity]\nacceleration = [0.0, 0.0, -9.81]\n"
    scene = _scene(tmp_path, far, ["time.steps=4"])
    assert_same_run(*resumed_equals_uninterrupted(tmp_path, scene, stop=2))


def test_identity_keys_name_each_dof_once_and_follow_the_vertices(tmp_path):
    """P2 keys: one per dof; a vertex dof's key is its input row's, an edge dof's lies
    between its vertices (dof coordinates = the mean of the keyed vertices' points)."""
    from fem_anim.simulation.checkpoint import dof_identity
    from fem_anim.simulation.loop import Simulation

    sim = Simulation(_scene(tmp_path, TINY, ["element.degree=2"]))
    V, domain = sim.problem.V, sim.domain
    keys = dof_identity(V, domain)
    assert np.unique(keys).size == keys.size and keys.min() >= 0
    base = int(domain.input_index.max()) + 1
    i, j = keys // base, keys % base
    vertex = i * (base + 1) == keys
    i[vertex], j[vertex] = keys[vertex] // (base + 1), keys[vertex] // (base + 1)
    points = domain.points  # serial: the input points
    expected = 0.5 * (points[i] + points[j])
    np.testing.assert_allclose(V.tabulate_dof_coordinates()[:, :2], expected, atol=1e-12)


def _cli_interrupted(tmp_path, monkeypatch, stop: int = 3) -> Path:
    """``fem-anim run TINY -o cut`` stopped by SIGINT after ``stop`` steps (exit 130)."""
    from fem_anim.cli import main
    from fem_anim.simulation.loop import Simulation

    (tmp_path / "tiny.toml").write_text(TINY)
    take = Simulation.timed_step

    def timed_step(self, state, dt):
        new, row = take(self, state, dt)
        if new.step == stop:
            os.kill(os.getpid(), signal.SIGINT)
        return new, row

    with monkeypatch.context() as m:
        m.setattr(Simulation, "timed_step", timed_step)
        assert main(["run", "-q", str(tmp_path / "tiny.toml"), "-o",
                     str(tmp_path / "cut")]) == 130
    return tmp_path / "cut"


def test_solver_change_on_resume_is_accepted_and_said(tmp_path, monkeypatch, capsys):
    """A solver setting does not change the physics: the resumed run says what it continues
    with, and ends where the uninterrupted run does (to the solver tolerance)."""
    from fem_anim.cli import main

    out = _cli_interrupted(tmp_path, monkeypatch)
    capsys.readouterr()
    was = json.loads(np.load(out / ".partial" / "checkpoint.npz")["meta"].tobytes())
    scene = str(tmp_path / "tiny.toml")
    assert main(["run", "-q", scene, "--set", 'solver.hessian="shift"', "--resume",
                 str(out)]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"fem-anim: resuming {out} at frame 3 of 6"), err
    assert f'with changed solver settings: solver.hessian = "shift" (was ' \
           f'"{was["solver"]["solver"]["hessian"]}")' in err[0], err[0]
    assert main(["run", "-q", scene, "-o", str(tmp_path / "whole")]) == 0
    ua = meshio.read(tmp_path / "whole" / "final.vtu").point_data["displacement"]
    ub = meshio.read(out / "final.vtu").point_data["displacement"]
    assert np.linalg.norm(ub - ua) <= 1e-8 * np.linalg.norm(ua)


def test_unchanged_resume_says_so_unless_quiet(tmp_path, monkeypatch, capsys):
    from fem_anim.cli import main

    out = _cli_interrupted(tmp_path, monkeypatch)
    capsys.readouterr()
    assert main(["run", str(tmp_path / "tiny.toml"), "--resume", str(out)]) == 0
    err = capsys.readouterr().err
    assert f"fem-anim: resuming {out} at frame 3 of 6 (t = 0.06 s) with the same solver " \
           "settings" in err


def test_physics_change_on_resume_is_refused_naming_the_key(tmp_path, monkeypatch, capsys):
    from fem_anim.cli import main

    out = _cli_interrupted(tmp_path, monkeypatch)
    capsys.readouterr()
    before = sorted((p.name, p.stat().st_mtime_ns) for p in (out / ".partial").rglob("*"))
    assert main(["run", "-q", str(tmp_path / "tiny.toml"), "--set",
                 "material.youngs_modulus=2e5", "--resume", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fem-anim: error: "), err
    assert "physics changed: material.youngs_modulus = 200000.0 (was" in err[0], err[0]
    assert sorted((p.name, p.stat().st_mtime_ns) for p in (out / ".partial").rglob("*")) == \
        before
