"""Nothing a user has is ever lost, and every message is true.

Everything here is the real thing: real signals to a real ``fem-anim run`` process, two
real concurrent runs, a real full file system (a 300 kB tmpfs) and a real read-only one
(a tmpfs remounted read-only; chmod does not stop root), checkpoints altered byte by
byte, real PETSc monitors. Scenes are the default beam, coarse (0.1 m), not rendered.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shlex
import signal
import subprocess
import time
from pathlib import Path

import meshio
import numpy as np
import pytest
from conftest import clean_environment, fem_anim_command, mpirun_command, process_tree

from fem_anim.cli import main
from fem_anim.output.rundir import LOCK, MARKER, install, read_manifest, write_manifest

COARSE = ["--set", "mesh.element_size=0.1", "--set", "output.render=false"]
PREFIX = "fem-anim: error: "


def fem_anim(args: list[str], cwd=None, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(fem_anim_command() + args, env=clean_environment(), cwd=cwd,
                          capture_output=True, text=True, timeout=timeout)


def start(args: list[str], command: list[str] | None = None) -> subprocess.Popen:
    return subprocess.Popen((command or []) + fem_anim_command() + args,
                            env=clean_environment(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


def wait_for_rows(out: Path, rows: int, proc: subprocess.Popen, timeout: float = 120) -> None:
    """Until ``out/.partial/stats.csv`` holds ``rows`` steps (the run is in its time loop)."""
    stats = out / ".partial" / "stats.csv"
    deadline = time.time() + timeout
    while time.time() < deadline:
        if stats.exists() and len(stats.read_text().splitlines()) > rows:
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.01)
    raise AssertionError("the run did not reach its time loop")


def one_error_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(PREFIX), stderr
    assert "Traceback" not in stderr
    return lines[0]


def checkpoint_meta(path: Path) -> dict:
    with np.load(path) as npz:
        return json.loads(npz["meta"].tobytes().decode())


def frames(xdmf: Path) -> int:
    with meshio.xdmf.TimeSeriesReader(str(xdmf)) as reader:
        reader.read_points_cells()
        return reader.num_steps


def tree(path: Path) -> dict[str, bytes]:
    return {str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*"))
            if p.is_file() and p.name != LOCK}


# -- 2. interruptions keep everything and say how to resume ------------------------------------
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP],
                         ids=lambda s: signal.Signals(s).name)
def test_signal_keeps_the_run_and_prints_the_resume_command(tmp_path, sig):
    out = tmp_path / "run"
    args = ["run", "-q", *COARSE, "--set", "time.steps=120", "--set",
            "output.checkpoint_every=1000", "-o", str(out)]
    proc = start(args)
    wait_for_rows(out, 5, proc)
    proc.send_signal(sig)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 128 + sig, stderr
    line = one_error_line(stderr)
    name = signal.Signals(sig).name
    assert f"interrupted by {name} at frame" in line
    frame = int(re.search(r"at frame (\d+) of 120", line).group(1))
    # no periodic checkpoint was due (every 1000 frames): the interruption wrote this one
    meta = checkpoint_meta(out / ".partial" / "checkpoint.npz")
    assert meta["frame"] == frame and meta["frames_written"] == frame + 1
    assert frames(out / ".partial" / "trajectory.xdmf") == frame + 1
    assert len((out / ".partial" / "stats.csv").read_text().splitlines()) == meta["step"] + 1
    command = re.search(r"continue with `([^`]+)`", line).group(1)
    assert shlex.split(command)[:2] == ["fem-anim", "run"] and f"--resume {out}" in command
    if sig != signal.SIGINT:
        return
    # the printed command, interrupted again: the state it started from is kept
    resumed = start(shlex.split(command)[1:])
    wait_for_rows(out, meta["step"] + 5, resumed)
    resumed.send_signal(signal.SIGINT)
    _, stderr = resumed.communicate(timeout=120)
    assert resumed.returncode == 130, stderr
    later = checkpoint_meta(out / ".partial" / "checkpoint.npz")
    assert later["frame"] > frame and later["rows"][: meta["step"]] == meta["rows"]
    done = fem_anim(shlex.split(command)[1:])
    assert done.returncode == 0, done.stderr
    assert not (out / ".partial").exists()
    assert frames(out / "trajectory.xdmf") == 121
    steps = [int(r.split(",")[0]) for r in (out / "stats.csv").read_text().splitlines()[1:]]
    assert steps == list(range(1, len(steps) + 1))


def assert_resumes_to_the_end(out: Path, steps: int) -> None:
    """A serial ``--resume`` of the interrupted MPI run in ``out`` writes all its frames."""
    done = fem_anim(["run", "-q", *COARSE, "--set", f"time.steps={steps}", "--set",
                     "output.checkpoint_every=1000", "--resume", str(out)])
    assert done.returncode == 0, done.stderr
    assert frames(out / "trajectory.xdmf") == steps + 1


@pytest.mark.mpi
def test_ranks_checkpoint_and_stop_when_the_launcher_is_killed(tmp_path):
    """mpirun killed with SIGKILL forwards nothing (and OpenMPI 5 puts each rank in its own
    process group): the ranks see their parent change, stop at the same frame with a
    checkpoint (none is due on their own here) and leave no process behind."""
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    out = tmp_path / "run"
    args = ["run", "-q", *COARSE, "--set", "time.steps=400", "--set",
            "output.checkpoint_every=1000", "-o", str(out)]
    proc = start(args, mpirun)
    wait_for_rows(out, 5, proc)
    commands = {p: Path(f"/proc/{p}/cmdline").read_bytes() for p in process_tree(proc.pid)[1:]}
    ranks = [p for p, command in commands.items()  # each rank's signal watcher is no rank
             if b"fem_anim" in command and not command.startswith(b"signal-watch")]
    assert len(ranks) == 2
    os.kill(proc.pid, signal.SIGKILL)  # the launcher alone
    proc.communicate()

    def running(pid: int) -> bool:
        try:
            return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
        except OSError:
            return False

    deadline = time.time() + 60
    while any(running(p) for p in ranks) and time.time() < deadline:
        time.sleep(0.05)
    assert not any(running(p) for p in ranks)
    assert 5 <= checkpoint_meta(out / ".partial" / "checkpoint.npz")["frame"] < 400
    assert_resumes_to_the_end(out, 400)


@pytest.mark.mpi
@pytest.mark.slow
def test_interrupted_mpi_run_leaves_a_resumable_directory(tmp_path):
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    out = tmp_path / "run"
    args = ["run", "-q", *COARSE, "--set", "time.steps=300", "--set",
            "output.checkpoint_every=1000", "-o", str(out)]
    proc = start(args, mpirun)
    wait_for_rows(out, 5, proc)
    os.killpg(proc.pid, signal.SIGINT)  # as Ctrl-C does: mpirun and every rank
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode != 0
    assert "Traceback" not in stderr
    assert 1 <= checkpoint_meta(out / ".partial" / "checkpoint.npz")["frame"] < 300
    assert_resumes_to_the_end(out, 300)


# -- 3. one run per directory -------------------------------------------------------------------
def test_second_concurrent_run_is_refused_and_a_stale_lock_recovered(tmp_path):
    out = tmp_path / "run"
    args = ["run", "-q", *COARSE, "--set", "time.steps=40", "--set",
            "output.checkpoint_every=5", "-o", str(out)]
    first = start(args)
    wait_for_rows(out, 12, first)
    # stopped (not ended) while it holds the lock: however slow the second's start-up on a
    # loaded machine, the first cannot finish and release the directory before it
    os.killpg(first.pid, signal.SIGSTOP)
    try:
        second = fem_anim(args)
        assert second.returncode == 2
        line = one_error_line(second.stderr)
        assert f"{out} is in use by another fem-anim run (pid {first.pid})" in line
        assert first.poll() is None and (out / ".partial" / "stats.csv").exists()
    finally:
        os.killpg(first.pid, signal.SIGKILL)  # dies holding the lock
        first.wait()
    assert (out / LOCK).read_text() == f"{first.pid}\n"  # a stale lock file
    resumed = start(["run", "-q", *COARSE, "--set", "time.steps=40", "--set",
                     "output.checkpoint_every=5", "--resume", str(out)])
    stdout, stderr = resumed.communicate(timeout=300)
    assert resumed.returncode == 0, stderr
    assert (out / LOCK).read_text() == f"{resumed.pid}\n"  # the stale pid replaced
    assert frames(out / "trajectory.xdmf") == 41


# -- 1. only fem_anim's own files ------------------------------------------------------------
def test_render_refuses_a_directory_a_run_holds(tmp_path, capsys):
    from fem_anim.output.rundir import claim

    out = tmp_path / "run"
    assert main(["run", "-q", *COARSE, "--set", "time.steps=1", "-o", str(out)]) == 0
    fd = claim(out)  # as a running fem-anim holds it
    try:
        assert main(["render", str(out), "-q"]) == 2
        line = one_error_line(capsys.readouterr().err)
        assert f"in use by a running fem-anim run (pid {os.getpid()})" in line
    finally:
        os.close(fd)


def test_users_folder_is_never_written_into(tmp_path, capsys):
    folder = tmp_path / "mine"
    (folder / "frames").mkdir(parents=True)
    (folder / "frames" / "holiday.png").write_bytes(b"\x89PNG user")
    (folder / "animation.gif").write_bytes(b"GIF89a user")
    before = tree(folder)
    assert main(["run", "-q", *COARSE, "--set", "time.steps=1", "-o", str(folder)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"output directory {folder} is not empty and is not a fem-anim run directory" in line
    assert tree(folder) == before and sorted(os.listdir(folder)) == ["animation.gif", "frames"]


def test_rerun_replaces_only_its_own_files(tmp_path):
    out = tmp_path / "run"
    args = ["run", "-q", *COARSE, "--set", "time.steps=2", "-o", str(out)]
    assert main(args) == 0
    # pictures of an older rendering (in the manifest), and the user's own files
    (out / "frames").mkdir()
    (out / "frames" / "frame_0009.png").write_bytes(b"old picture")
    (out / "frames" / "notes.txt").write_text("mine")
    (out / "mine.txt").write_text("mine too")
    write_manifest(out, read_manifest(out) | {"frames/frame_0009.png"})
    old_stats = (out / "stats.csv").read_text()
    assert main(args + ["--set", "time.dt=0.01"]) == 0
    assert (out / "frames" / "notes.txt").read_text() == "mine"
    assert (out / "mine.txt").read_text() == "mine too"
    assert not (out / "frames" / "frame_0009.png").exists()  # no picture outlives its data
    assert (out / "stats.csv").read_text() != old_stats
    assert "mine.txt" not in read_manifest(out) and "stats.csv" in read_manifest(out)


def test_install_merges_directories_and_keeps_unlisted_files(tmp_path):
    run, staging = tmp_path / "run", tmp_path / "run" / ".rendering"
    (run / "frames").mkdir(parents=True)
    write_manifest(run, {"frames/frame_1.png", "frames/frame_2.png", "final.png"})
    for name in ("frames/frame_1.png", "frames/frame_2.png", "final.png", "frames/mine.png"):
        (run / name).write_text("old")
    (staging / "frames").mkdir(parents=True)
    (staging / "frames" / "frame_1.png").write_text("new")
    install(staging, run, replaces={"frames/frame_1.png", "frames/frame_2.png"})
    assert (run / "frames" / "frame_1.png").read_text() == "new"
    assert not (run / "frames" / "frame_2.png").exists()
    assert (run / "frames" / "mine.png").read_text() == "old"  # not fem_anim's
    assert (run / "final.png").read_text() == "old"  # not replaced by this install
    assert not staging.exists()
    assert read_manifest(run) == {"frames/frame_1.png", "final.png"}
    assert json.loads((run / MARKER).read_text())["fem_anim"] == "run directory"


def test_fresh_run_does_not_replace_a_resumable_one(tmp_path):
    out = tmp_path / "run"
    args = ["run", "-q", *COARSE, "--set", "time.steps=300", "--set",
            "output.checkpoint_every=1000", "-o", str(out)]
    proc = start(args)
    wait_for_rows(out, 3, proc)
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=120)
    before = tree(out)
    again = fem_anim(args)
    assert again.returncode == 2
    line = one_error_line(again.stderr)
    assert "holds an unfinished run with a checkpoint" in line and "--resume" in line
    assert tree(out) == before


# -- 4. OS errors: one line naming the file, exit 2, nothing deleted ---------------------------
@contextlib.contextmanager
def tmpfs(path: Path, size: str):
    """A small tmpfs at ``path`` (root only), unmounted afterwards."""
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    path.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs: {r.stderr.strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


def test_disk_full_is_one_line_and_keeps_the_run(tmp_path):
    with tmpfs(tmp_path / "small", "300k") as small:
        out = small / "run"
        r = fem_anim(["run", "-q", *COARSE, "--set", "time.steps=200", "--set",
                      "output.checkpoint_every=5", "-o", str(out)])
        assert r.returncode == 2, r.stderr
        line = one_error_line(r.stderr)
        assert "No space left on device" in line and f"{out}/.partial/" in line, line
        assert "nothing was deleted" in line
        kept = sorted(p.name for p in (out / ".partial").iterdir())
        assert "checkpoint.npz" in kept and "stats.csv" in kept and "trajectory.h5" in kept
        meta = checkpoint_meta(out / ".partial" / "checkpoint.npz")  # complete, readable
        assert meta["frame"] >= 5


def test_read_only_file_system(interrupted, tmp_path):
    source, _ = interrupted
    args = ["run", "-q", *COARSE, "--set", "time.steps=300", "--set",
            "output.checkpoint_every=1000"]
    with tmpfs(tmp_path / "ro", "2m") as ro:
        out = ro / "run"
        subprocess.run(["cp", "-a", str(source), str(out)], check=True)
        before = tree(out)
        subprocess.run(["mount", "-o", "remount,ro", str(ro)], check=True)
        for extra in (["-o", str(ro / "new")], ["--resume", str(out)]):
            r = fem_anim(args + extra)
            assert r.returncode == 2, r.stderr
            line = one_error_line(r.stderr)
            assert "Read-only file system" in line and str(ro) in line, line
        assert tree(out) == before


def test_truncated_trajectory_under_partial_is_refused(interrupted, tmp_path):
    source, _ = interrupted
    out = tmp_path / "run"
    subprocess.run(["cp", "-a", str(source), str(out)], check=True)
    h5 = out / ".partial" / "trajectory.h5"
    h5.write_bytes(h5.read_bytes()[: h5.stat().st_size // 2])
    before = tree(out)
    r = fem_anim(["run", "-q", *COARSE, "--set", "time.steps=300", "--set",
                  "output.checkpoint_every=1000", "--resume", str(out)])
    assert r.returncode == 2
    line = one_error_line(r.stderr)
    assert str(h5) in line and "truncated" in line, line
    assert tree(out) == before and not (out / "stats.csv").exists()


def test_file_name_too_long_is_one_line(tmp_path, capsys):
    long = tmp_path / ("x" * 300)
    assert main(["run", "-q", *COARSE, "--set", "time.steps=1", "-o", str(long)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "File name too long" in line


# -- 5. checkpoints validated before resuming ---------------------------------------------------
@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    """A run interrupted at a checkpoint: its directory and the checkpoint's bytes."""
    out = tmp_path_factory.mktemp("ck") / "run"
    proc = start(["run", "-q", *COARSE, "--set", "time.steps=300", "--set",
                  "output.checkpoint_every=1000", "-o", str(out)])
    wait_for_rows(out, 3, proc)
    proc.send_signal(signal.SIGINT)
    proc.communicate(timeout=120)
    return out, (out / ".partial" / "checkpoint.npz").read_bytes()


def _rewrite(data: bytes, change) -> bytes:
    with np.load(io.BytesIO(data)) as npz:
        arrays = {k: npz[k] for k in npz.files}
    meta = json.loads(arrays.pop("meta").tobytes().decode())
    change(meta, arrays)
    buffer = io.BytesIO()
    np.savez(buffer, meta=np.frombuffer(json.dumps(meta).encode(), np.uint8), **arrays)
    return buffer.getvalue()


def _set(key, value):
    return lambda meta, arrays: meta.__setitem__(key, value)


def _nan_u(meta, arrays):
    arrays["u"][3, 1] = np.nan


def _short_u(meta, arrays):
    arrays["u"] = arrays["u"][:-1]


EDITS = {
    "impossible-frame": (_set("frame", 10**6), "frame 1000000 is outside 1..299"),
    "frame-zero": (_set("frame", 0), "frame 0 is outside"),
    "time-off": (lambda m, a: m.__setitem__("time", m["time"] + 0.5), "is not frame"),
    "rows-lost": (lambda m, a: m["rows"].pop(), "stats rows"),
    "frames-written": (_set("frames_written", 10**4), "trajectory frames cannot"),
    "nan-state": (_nan_u, "array u holds non-finite values"),
    "short-state": (_short_u, "array u has shape"),
    "zero-dt": (_set("stepper", {"dt": 0.0, "last_dt": 0.0}), "are not in (0, time.dt]"),
    "other-scene": (_set("scene", "0" * 64), "written for a different scene"),
}


@pytest.mark.parametrize("edit", list(EDITS))
def test_edited_checkpoint_is_refused_and_nothing_committed(interrupted, tmp_path, edit):
    source, original = interrupted
    out = tmp_path / "run"
    subprocess.run(["cp", "-a", str(source), str(out)], check=True)
    change, message = EDITS[edit]
    (out / ".partial" / "checkpoint.npz").write_bytes(_rewrite(original, change))
    before = tree(out)
    code = main(["run", "-q", *COARSE, "--set", "time.steps=300", "--set",
                 "output.checkpoint_every=1000", "--resume", str(out)])
    assert code == 2
    assert tree(out) == before and not (out / "stats.csv").exists()


def test_checkpoint_altered_byte_by_byte(interrupted, capsys):
    """Every altered byte (a spread of positions): refused, or read exactly as written."""
    from fem_anim.simulation.checkpoint import load_checkpoint
    from fem_anim.scene import load_scene
    from fem_anim.simulation.loop import Simulation

    out, original = interrupted
    scene = load_scene(None, COARSE[1::2] + ["time.steps=300", "output.checkpoint_every=1000"])
    sim = Simulation(scene)
    good = load_checkpoint(out / ".partial" / "checkpoint.npz", sim)
    path = out.parent / "altered.npz"
    refused = 0
    for position in np.linspace(0, len(original) - 1, 150).astype(int):
        data = bytearray(original)
        data[position] ^= 0x5A
        path.write_bytes(bytes(data))
        try:
            ck = load_checkpoint(path, sim)
        except Exception as err:  # noqa: BLE001
            assert type(err).__name__ == "FemAnimError", (position, err)
            assert "checkpoint" in str(err)
            refused += 1
            continue
        assert ck.frame == good.frame and ck.rows == good.rows
        np.testing.assert_array_equal(ck.state.u, good.state.u)
    assert refused >= 140, refused  # zip CRCs and the validation catch nearly every byte
    print(f"{refused} of 150 altered checkpoints refused")


def test_resume_with_another_output_directory_is_refused(interrupted, tmp_path, capsys):
    out, _ = interrupted
    code = main(["run", "-q", *COARSE, "--resume", str(out), "-o", str(tmp_path / "other")])
    assert code == 2
    line = one_error_line(capsys.readouterr().err)
    assert "name different directories" in line and not (tmp_path / "other").exists()


# -- 6. command-line PETSc options ------------------------------------------------------------
def test_misspelt_petsc_options_are_an_error(tmp_path):
    typos = ["-ksp_tpye", "-snes_linesearch_tpye", "-pc_factor_mat_solver_tpye"]
    r = fem_anim(["run", "-q", *COARSE, "--set", "time.steps=2", "-o", str(tmp_path / "o"),
                  typos[0], "cg", typos[1], "bt", typos[2], "mumps", "-ksp_type", "preonly"])
    assert r.returncode == 2
    line = one_error_line(r.stderr)
    assert f"PETSc option {', '.join(sorted(typos))} was read by no solver object" in line
    assert "-ksp_type" not in line.replace("-ksp_tpye", "")


def test_monitors_reasons_views_and_log_view_print_what_petsc_prints(tmp_path):
    log = tmp_path / "log.txt"
    r = fem_anim(["run", "-q", *COARSE, "--set", "time.steps=1", "-o", str(tmp_path / "o"),
                  "-snes_monitor", "-snes_converged_reason", "-ksp_converged_reason",
                  "-snes_view", "-log_view", f":{log}"])
    assert r.returncode == 0, r.stderr
    assert re.search(r"0 SNES Function norm", r.stdout)
    assert "Nonlinear fem_anim_ solve converged due to" in r.stdout
    assert "Linear fem_anim_ solve converged due to" in r.stdout
    assert "SNES Object: (fem_anim_)" in r.stdout
    assert "PETSc Performance Summary" in log.read_text()


# -- 8. the energy report says only true things -------------------------------------------------
def run_summary(tmp_path, *overrides, name="o") -> tuple[dict, str]:
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["run", *COARSE, "-o", str(tmp_path / name), *overrides]) == 0
    return json.loads((tmp_path / name / "summary.json").read_text())["energy"], \
        printed.getvalue()


def test_body_at_rest_gets_no_relative_figure(tmp_path):
    e, printed = run_summary(tmp_path, "--set", "time.steps=3", "--set",
                             "gravity.acceleration=[0, 0, 0]")
    assert e["drift"] is None and not e["flagged"]
    assert "%" not in printed and "stayed at rest" in printed


def test_newmark_is_never_told_to_use_newmark():
    from fem_anim.simulation.energy_report import describe_energy
    from fem_anim.scene import load_scene

    report = {"drift": -0.2, "max_excursion": 0.2, "exchanged_energy": 1.0,
              "conservative": True, "damped": True, "gained": False, "flagged": True}
    for integrator in ("newmark", "implicit_euler"):
        scene = load_scene(None, [f"time.integrator={integrator}"])
        line = describe_energy(report, scene)
        assert ("use newmark" in line) == (integrator != "newmark"), line
    gained = report | {"drift": 0.2, "damped": False, "gained": True}
    line = describe_energy(gained, load_scene(None, []))
    assert "energy GAINED 20 %" in line and "newmark" not in line


def test_no_pin_is_blamed_when_no_pin_moves(tmp_path, capsys):
    """A huge step overflows the step objective at every start: blamed on the step, not on
    pins that do not move (with a moving pin, the pins are named)."""
    args = ["run", "-q", *COARSE, "--set", "time.steps=2", "--set", "time.dt=1e100",
            "--set", "time.adaptive=false"]
    assert main(args + ["-o", str(tmp_path / "o")]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "no start for Newton" in line and "predicted over one step" in line
    assert "pins move" not in line
    assert main(args + ["-o", str(tmp_path / "p"), "--set", "pin.0.velocity=[0, 0, 1]"]) == 2
    assert "the pins move too far" in one_error_line(capsys.readouterr().err)


# -- 9. small things -------------------------------------------------------------------------
def test_quiet_run_prints_nothing_and_no_bar_off_a_terminal(tmp_path):
    r = fem_anim(["run", "-q", *COARSE, "--set", "time.steps=2", "-o", str(tmp_path / "q")])
    assert r.returncode == 0 and r.stdout == "" and r.stderr == ""
    r = fem_anim(["run", *COARSE, "--set", "time.steps=2", "-o", str(tmp_path / "v")])
    assert r.returncode == 0 and "stored energy" in r.stdout
    assert "\r" not in r.stderr and "step/s" not in r.stderr  # stderr is a pipe: no bar


def test_readme_2d_shape_names_are_scene_names():
    from fem_anim.scene.schema import MESH_SHAPES

    readme = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    row = next(line for line in readme.splitlines() if line.startswith("| `mesh.shape`"))
    named = set(re.findall(r'`"(\w+)"`', row))
    assert named == set(MESH_SHAPES)


def test_demos_write_no_tracked_file():
    demos = Path(__file__).resolve().parents[1] / "demos"
    for demo in demos.glob("*.py"):
        text = demo.read_text()
        assert not re.search(r"HERE / \"[\w.]+\.(png|gif|csv|md)\"", text), demo.name
        assert "savefig(HERE" not in text, demo.name


def test_an_interruption_between_ffcx_lock_and_compile_leaves_no_lock(tmp_path):
    """The race behind a rare failure of the test below (SIGTERM, machine loaded): FFCx creates
    its lock ``<module>.c`` and only then enters the ``try`` that renames it on an Exception;
    a signal's Interrupted (an Exception) raised in between left the lock, and every later
    compile of that module timed out. Reproduced deterministically: a lock taken inside the
    block through FFCx's own ``get_cached_module``, then Interrupted. A finished module
    (``.c.cached``), an older lock, and a lock another process made meanwhile (it may still be
    compiling: renaming it would poison its module) stay."""
    import ffcx.codegeneration.jit as ffcx_codegen  # get_cached_module: same in FFCx 0.5 and 0.9

    from fem_anim import compat
    from fem_anim.errors import Interrupted

    cache = tmp_path / "cache"
    cache.mkdir()
    old = cache / "libffcx_forms_old.c"
    old.touch()
    os.utime(old, (time.time() - 3600, time.time() - 3600))  # another run's, long ago
    done = cache / "libffcx_forms_done.c"
    other = cache / "libffcx_forms_other.c"
    with pytest.raises(Interrupted):
        with compat.jit_locks_released({"cache_dir": str(cache)}):
            assert ffcx_codegen.get_cached_module("libffcx_forms_new", [], cache, 1) == (None, None)
            open(other, "x").close()  # another process's get_cached_module, still compiling
            done.touch()
            done.with_suffix(".c.cached").touch()
            raise Interrupted("interrupted by SIGTERM while setting up", signal.SIGTERM)
    assert not (cache / "libffcx_forms_new.c").exists()
    assert (cache / "libffcx_forms_new.c.failed").exists()
    assert done.exists() and old.exists() and other.exists()


def _small_module(cache):
    """A function compiling one small functional (int x dx over the unit square, 0.5) into
    the JIT cache ``cache`` through ``compat.compile_forms_together``; it returns the Forms."""
    import ufl
    from dolfinx import mesh
    from mpi4py import MPI

    from fem_anim import compat

    domain = mesh.create_unit_square(MPI.COMM_SELF, 2, 2)
    functional = ufl.SpatialCoordinate(domain)[0] * ufl.dx(domain=domain)
    return lambda: compat.compile_forms_together({"b": functional}, {"cache_dir": str(cache)})


def test_a_module_ready_without_its_lock_loads_instead_of_failing(tmp_path):
    """A module whose lock was renamed while it compiled ends with ``.c.cached`` and no ``.c``:
    FFCx alone then recompiles it and fails on the existing ``.c.cached``
    (``FileExistsError``, seen on Debian 13's CI), every time. The lock is put back and the
    ready module loads."""
    from dolfinx import fem

    cache = tmp_path / "cache"
    compile_once = _small_module(cache)
    compile_once()
    lock, = cache.glob("libffcx_forms_*.c")
    assert lock.with_suffix(".c.cached").exists()
    lock.unlink()  # renamed away by another process while this module compiled
    form = compile_once()["b"]
    assert lock.exists()
    assert abs(fem.assemble_scalar(form) - 0.5) < 1e-12


def test_a_compile_waits_for_another_process_compiling_the_same_module(tmp_path, monkeypatch,
                                                                        capsys):
    """Two processes compiling one module on a cold cache (two runs started together, two
    test workers): the second finds the first's lock and waits for ``.c.cached``. FFCx and
    DOLFINx give up after 10 s ("JIT compilation timed out"), and a large module compiles
    for minutes; the wait is now ``compat.JIT_WAIT_S``, announced in one line. The other
    process is simulated: the module compiled, its ``.c.cached`` held back, and FFCx's
    one-second sleeps counted (no real waiting) until the 30th puts it back."""
    import ffcx.codegeneration.jit as ffcx_codegen
    from dolfinx import fem

    from fem_anim import compat

    cache = tmp_path / "cache"
    compile_once = _small_module(cache)
    compile_once()
    lock, = cache.glob("libffcx_forms_*.c")
    ready = lock.with_suffix(".c.cached")
    held = ready.rename(tmp_path / "held")  # "still compiling": a lock, no .c.cached
    sleeps = []

    def other_process_compiling(seconds):
        sleeps.append(seconds)
        if len(sleeps) == 30:
            held.rename(ready)

    monkeypatch.setattr(ffcx_codegen.time, "sleep", other_process_compiling)
    form = compile_once()["b"]
    assert len(sleeps) == 30
    assert abs(fem.assemble_scalar(form) - 0.5) < 1e-12
    assert f"waiting up to {compat.JIT_WAIT_S} s for another process compiling " \
        f"{lock.name}" in capsys.readouterr().err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_while_compiling_leaves_no_jit_lock(tmp_path, sig):
    """Stopped while FFCx compiles the forms (a fresh cache), the run ends with one line and
    the next run compiles and finishes: FFCx's lock file (``<module>.c`` without
    ``.c.cached``) is not left behind to make every later run time out."""
    env = clean_environment() | {"XDG_CACHE_HOME": str(tmp_path / "cache")}
    args = fem_anim_command() + ["run", "-q", *COARSE, "--set", "time.steps=2"]
    proc = subprocess.Popen(args + ["-o", str(tmp_path / "first")], env=env, cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 120
    while time.time() < deadline:
        locks = [c for c in (tmp_path / "cache").rglob("libffcx_forms_*.c")
                 if not c.with_suffix(".c.cached").exists()]
        if locks or proc.poll() is not None:
            break
        time.sleep(0.005)
    assert locks, "the run compiled nothing"
    proc.send_signal(sig)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode != 0
    assert "Traceback" not in stderr
    assert not [c for c in (tmp_path / "cache").rglob("libffcx_*.c")
                if not c.with_suffix(".c.cached").exists()]
    again = subprocess.run(args + ["-o", str(tmp_path / "second")], env=env, cwd=tmp_path,
                           capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
