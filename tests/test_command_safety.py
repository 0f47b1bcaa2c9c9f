"""Every command keeps ``run``'s promise: it never replaces what fem_anim did not write.

``render``, the trade study (``bench -o``), the perf bench (``--out``) and the extremes
table (``-o FILE``) are attacked the way ``tests/test_safety.py`` attacks ``run``: a
folder holding the user's own files of the names they write, a read-only file system (a
read-only bind mount in a private mount namespace: chmod does not stop root), a full one
(a 600 kB tmpfs there), a write failing with ENOSPC, and SIGINT while rendering. Each
refusal is one ``fem-anim: error:`` line with exit code 2 and leaves every byte as it was;
an interrupted rendering leaves no half-written picture under a product's name. Also the
lock file: it holds exactly the pid of the run holding it.
"""

from __future__ import annotations

import errno
import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import clean_environment, fem_anim_command

from fem_anim.cli import main
from fem_anim.output.products import STAGING_PREFIX, check_may_write, staged_products
from fem_anim.output.rundir import LOCK, MARKER, claim, install, read_manifest, write_manifest
from fem_anim.render.animation import read_run

COARSE = ["--set", "mesh.element_size=0.1", "--set", "output.render=false"]
PREFIX = "fem-anim: error: "
RUN_FILES = ("trajectory.xdmf", "trajectory.h5", "stats.csv", "scene.json")
FAST = ["--set", "render.outputs=[]"]  # final.png and the two plots only

TINY = """
name = "tiny_beam"
[mesh]
dim = 2
size = [1.0, 0.2]
element_size = 0.1
[material]
youngs_modulus = 2.0e4
[time]
dt = 0.1
steps = 2
[gravity]
acceleration = [0.0, -9.81]
[[pin]]
min = [-1e-6, -1.0]
max = [1e-6, 1.0]
"""


def one_error_line(stderr: str) -> str:
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith(PREFIX), stderr
    assert "Traceback" not in stderr
    return lines[0]


def tree(path: Path) -> dict[str, bytes]:
    """Every file below ``path`` (hidden ones too) with its bytes, but the lock."""
    return {p.relative_to(path).as_posix(): p.read_bytes() for p in sorted(path.rglob("*"))
            if p.is_file() and p.name != LOCK}


def fem_anim(args: list[str], timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(fem_anim_command() + args, env=clean_environment(),
                          capture_output=True, text=True, timeout=timeout)


def in_private_mounts(script: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run a shell script in a private mount namespace (its mounts vanish with it)."""
    if os.geteuid() != 0 or shutil.which("unshare") is None:
        pytest.skip("mounting needs root and unshare")
    probe = subprocess.run(["unshare", "-m", "true"], capture_output=True)
    if probe.returncode != 0:
        pytest.skip("no private mount namespace here")
    return subprocess.run(["unshare", "-m", "--propagation", "private", "sh", "-c", script],
                          env=clean_environment(), capture_output=True, text=True,
                          timeout=timeout)


def read_only(path: Path, command: list[str]) -> subprocess.CompletedProcess:
    """``command`` with ``path`` bind-mounted read-only over itself."""
    p = shlex.quote(str(path))
    return in_private_mounts(f"mount --bind {p} {p} && mount -o remount,bind,ro {p} && "
                             f"exec {shlex.join(command)}")


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished, unrendered coarse run of the default beam (3 steps)."""
    out = tmp_path_factory.mktemp("command_safety") / "run"
    assert main(["run", "-q", *COARSE, "--set", "time.steps=3", "-o", str(out)]) == 0
    return out


@pytest.fixture
def run_copy(finished_run, tmp_path) -> Path:
    out = tmp_path / "run"
    shutil.copytree(finished_run, out)
    return out


@pytest.fixture
def foreign(finished_run, tmp_path) -> Path:
    """A user's folder holding a trajectory (copied from a run) but no marker."""
    folder = tmp_path / "mine"
    folder.mkdir()
    for name in RUN_FILES:
        shutil.copy(finished_run / name, folder / name)
    return folder


# -- the lock ---------------------------------------------------------------------------------
def test_lock_holds_exactly_the_current_pid(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    write_manifest(out, set())
    (out / LOCK).write_text("4194304999999\n")  # a longer pid of a dead run
    fd = claim(out)
    try:
        assert (out / LOCK).read_text() == f"{os.getpid()}\n"
    finally:
        os.close(fd)


# -- the shared rule ---------------------------------------------------------------------------
def test_check_may_write_refuses_only_unlisted_files_of_its_names(tmp_path):
    folder = tmp_path / "d"
    check_may_write(folder, ["a.md"])  # missing: fine
    folder.mkdir()
    (folder / "a.md").write_text("mine")
    (folder / "b.md").write_text("mine")
    check_may_write(folder, ["c.md", "sub/d.md"])  # other names: fine
    with pytest.raises(Exception, match=f"{folder / 'a.md'} was not written by fem-anim"):
        check_may_write(folder, ["c.md", "a.md"])
    write_manifest(folder, {"a.md"})
    check_may_write(folder, ["a.md"])  # fem_anim's own: fine
    with pytest.raises(Exception, match="b.md was not written"):
        check_may_write(folder, ["a.md", "b.md"])
    (folder / "link.md").symlink_to(folder / "nowhere")  # a dangling link is a user's too
    with pytest.raises(Exception, match="link.md was not written"):
        check_may_write(folder, ["link.md"])


def test_install_refuses_to_replace_an_unlisted_file(tmp_path):
    run, staging = tmp_path / "run", tmp_path / "run" / ".staging"
    staging.mkdir(parents=True)
    write_manifest(run, {"final.png"})
    (run / "final.png").write_text("old")
    (run / "animation.gif").write_text("the user's")
    (staging / "final.png").write_text("new")
    (staging / "animation.gif").write_text("new")
    before = tree(run)
    with pytest.raises(FileExistsError) as info:
        install(staging, run)
    assert info.value.filename == str(run / "animation.gif")
    assert tree(run) == before  # checked before anything moved


def test_staged_products_leave_nothing_when_a_write_fails(tmp_path):
    folder = tmp_path / "d"
    folder.mkdir()
    write_manifest(folder, {"a.csv", "a.md"})
    (folder / "a.csv").write_text("old csv")
    (folder / "a.md").write_text("old md")
    before = tree(folder)
    with pytest.raises(OSError) as info:
        with staged_products(folder, ["a.csv", "a.md"]) as staging:
            (staging / "a.csv").write_text("new, half")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(staging / "a.md"))
    assert info.value.errno == errno.ENOSPC
    assert tree(folder) == before and \
        not any(name.startswith(STAGING_PREFIX) for name in os.listdir(folder))
    with staged_products(folder, ["a.csv", "a.md"]) as staging:  # a study that made less
        (staging / "a.csv").write_text("new csv")
    assert (folder / "a.csv").read_text() == "new csv" and not (folder / "a.md").exists()
    assert read_manifest(folder) == {"a.csv"}


@pytest.mark.parametrize("where", ["this thread", "another thread"])
def test_a_signal_during_the_install_comes_after_it(tmp_path, monkeypatch, where):
    """SIGINT while the products are being renamed into place (seen under load: the render
    had staged everything when the signal came) is delivered once all of them are: the new
    files are complete, the manifest lists them, no staging folder stays, and the folder is
    named by installed_by_this_process. Delivered to another thread (VTK's or a BLAS pool's,
    which the main thread's mask does not cover), Python runs the handler in the main thread
    at once: the install must still not be cut in half."""
    import threading

    from fem_anim.output import products, rundir

    folder = tmp_path / "d"
    folder.mkdir()
    write_manifest(folder, {"a.csv", "b.csv"})
    for name in ("a.csv", "b.csv"):
        (folder / name).write_text("old")
    other = threading.Thread(target=threading.Event().wait, args=(5.0,), daemon=True)
    other.start()
    real_install = rundir.install

    def install_signalled(staging, target, replaces=()):
        if where == "this thread":
            os.kill(os.getpid(), signal.SIGINT)
        else:
            signal.pthread_kill(other.ident, signal.SIGINT)
        time.sleep(0.05)  # the handler has had its chance to run
        for name in ("a.csv", "b.csv"):  # one rename at a time, Python between them
            time.sleep(0.01)
            assert (staging / name).exists()
        return real_install(staging, target, replaces=replaces)

    monkeypatch.setattr(products, "install", install_signalled)
    # Python's own Ctrl-C handler, whatever this process inherited: started in the background
    # by a non-interactive shell, SIGINT may be ignored, or left at the default, which would
    # end the test process when the held signal is raised again
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            with staged_products(folder, ["a.csv", "b.csv"]) as staging:
                for name in ("a.csv", "b.csv"):
                    (staging / name).write_text("new")
    finally:
        signal.signal(signal.SIGINT, previous)
    assert {n: (folder / n).read_text() for n in ("a.csv", "b.csv")} == \
        {"a.csv": "new", "b.csv": "new"}
    assert read_manifest(folder) == {"a.csv", "b.csv"}
    assert not any(name.startswith(STAGING_PREFIX) for name in os.listdir(folder))
    assert folder in products.installed_by_this_process()


# -- render ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["animation.gif", "final.png", "energies.png",
                                  "frames/frame_0000.png"])
def test_render_refuses_a_users_folder_holding_a_trajectory(foreign, name, capsys):
    (foreign / name).parent.mkdir(exist_ok=True)
    (foreign / name).write_bytes(b"the user's own picture")
    (foreign / ".rendering").mkdir()
    (foreign / ".rendering" / "notes.txt").write_text("the user's")
    before = tree(foreign)
    assert main(["render", str(foreign), "-q"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"{foreign / name} was not written by fem-anim" in line, line
    assert tree(foreign) == before


def test_render_into_a_users_folder_writes_only_its_own_names(foreign):
    (foreign / ".rendering").mkdir()
    (foreign / ".rendering" / "notes.txt").write_text("the user's")
    (foreign / "frames").mkdir()
    (foreign / "frames" / "holiday.png").write_bytes(b"the user's")
    before = tree(foreign)
    assert main(["render", str(foreign), "-q", *FAST]) == 0
    after = tree(foreign)
    assert {k: after[k] for k in before} == before  # nothing of the user's changed
    made = set(after) - set(before) - {MARKER}
    assert made == {"final.png", "energies.png", "newton.png"}
    assert read_manifest(foreign) == made  # the trajectory is still the user's
    assert not any(n.startswith(STAGING_PREFIX) for n in os.listdir(foreign))
    assert main(["render", str(foreign), "-q", *FAST]) == 0  # its own: replaced


def test_a_run_into_a_folder_render_wrote_keeps_the_users_trajectory(foreign, capsys):
    assert main(["render", str(foreign), "-q", *FAST]) == 0  # now marked, by render
    users = {name: (foreign / name).read_bytes() for name in RUN_FILES}
    assert main(["run", "-q", *COARSE, "--set", "time.steps=1", "-o", str(foreign)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "exists and was not written by fem-anim" in line, line
    assert {name: (foreign / name).read_bytes() for name in RUN_FILES} == users


def test_render_on_a_read_only_file_system_is_one_line(run_copy):
    before = tree(run_copy)
    r = read_only(run_copy, fem_anim_command() + ["render", str(run_copy)])
    assert r.returncode == 2, r.stderr
    line = one_error_line(r.stderr)
    assert "Read-only file system" in line and str(run_copy) in line, line
    assert "cannot write the pictures" in line, line  # the renderer's own line
    assert tree(run_copy) == before


def test_the_renderers_own_error_line_is_taken_after_ffmpegs(monkeypatch):
    """The renderer's stderr may begin with ffmpeg's complaints: its own message is the last
    line, and that is the one the user gets."""
    from fem_anim.errors import FemAnimError
    from fem_anim.render import process

    class Child:
        args, returncode = ["render"], 2

        def __init__(self, *args, **kwargs):
            pass

        def communicate(self, timeout=None):
            return "", ("[libx264 @ 0x1] error: disk full\nav_interleaved_write_frame(): "
                        "failed\nfem-anim: error: cannot write the pictures of /r: No space "
                        "left on device; nothing was replaced\n")

    monkeypatch.setattr(process.subprocess, "Popen", Child)
    with pytest.raises(FemAnimError) as info:
        process.render_run(Path("/r"), {})
    assert str(info.value) == ("cannot write the pictures of /r: No space left on device; "
                               "nothing was replaced")


def test_a_signal_after_the_renderers_install_says_the_pictures_are_complete(
        tmp_path, monkeypatch, capsys):
    """A signal that reaches the renderer after its pictures were installed (while it removes
    its staging folder, prints its summary or exits: seen in CI under load) must not be
    reported as "nothing was installed": the new pictures are in place and complete."""
    from fem_anim.render import process

    def render_then_signalled(path, settings):
        with staged_products(path, ["final.png"]) as staging:
            (staging / "final.png").write_bytes(b"new")
        os.kill(os.getpid(), signal.SIGINT)  # after the install, before the renderer returns
        time.sleep(1.0)  # the handler raises here

    monkeypatch.setattr(process, "render_directory", render_then_signalled)
    handlers = {sig: signal.getsignal(sig) for sig in process.STOP_SIGNALS}
    try:
        status = process.main(["--run", str(tmp_path)])
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    assert status == 128 + signal.SIGINT
    assert one_error_line(capsys.readouterr().err) == \
        f"{PREFIX}{process.INSTALLED_THEN_STOPPED}"
    assert (tmp_path / "final.png").read_bytes() == b"new"


def test_a_signal_to_the_command_after_its_renderer_finished_says_so(run_copy, monkeypatch):
    """Ctrl-C reaches the whole process group: the command may take it after its renderer
    has finished and installed everything (exit 0, nothing on stderr). It then says that the
    new pictures are complete, not that nothing was installed."""
    from fem_anim.errors import Interrupted
    from fem_anim.render import process

    class InterruptedOnce(subprocess.Popen):
        taken = False

        def communicate(self, *args, **kwargs):
            if not InterruptedOnce.taken:
                InterruptedOnce.taken = True
                self.wait()  # the renderer finishes, then the command is interrupted
                raise KeyboardInterrupt
            return super().communicate(*args, **kwargs)

    monkeypatch.setattr(process.subprocess, "Popen", InterruptedOnce)
    with pytest.raises(Interrupted) as info:
        process.render_run(run_copy, {"outputs": []})
    assert str(info.value) == process.INSTALLED_THEN_STOPPED
    assert "final.png" in read_manifest(run_copy) and (run_copy / "final.png").is_file()


def test_render_on_a_full_disk_is_one_line_and_installs_nothing(finished_run, tmp_path):
    """A 600 kB tmpfs holding the run (about 60 kB): the GIF, MP4 and frames do not fit."""
    mnt = tmp_path / "small"
    mnt.mkdir()
    listing = (f"{shlex.quote(sys.executable)} -c \"import json, os, sys; "
               "print(json.dumps(sorted(os.listdir(sys.argv[1]))))\"")
    m, run = shlex.quote(str(mnt)), shlex.quote(str(mnt / "run"))
    r = in_private_mounts(
        f"mount -t tmpfs -o size=600k tmpfs {m} && cp -a {shlex.quote(str(finished_run))} "
        f"{run} && {shlex.join(fem_anim_command())} render {run} "
        f"--set render.window_size=[1600,1200]; echo \"rc=$?\"; {listing} {run}")
    assert "rc=2" in r.stdout, (r.stdout, r.stderr)
    line = one_error_line(r.stderr)
    assert "No space left on device" in line and "nothing was replaced" in line, line
    left = json.loads(r.stdout.splitlines()[-1])
    assert sorted(left) == sorted(os.listdir(finished_run)), left  # no product, no staging


def _start_render(out: Path, extra: list[str]) -> subprocess.Popen:
    return subprocess.Popen(fem_anim_command() + ["render", str(out), *extra],
                            env=clean_environment(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_signal_while_rendering_leaves_the_old_pictures(tmp_path, sig):
    out = tmp_path / "run"
    assert main(["run", "-q", *COARSE, "--set", "time.steps=40", "-o", str(out)]) == 0
    assert main(["render", str(out), "-q", *FAST]) == 0  # the previous rendering
    before = tree(out)
    proc = _start_render(out, ["--set", 'render.outputs=["frames","gif"]'])
    deadline = time.time() + 120
    staged = []
    while time.time() < deadline and proc.poll() is None:  # until frames are being written
        staged = [p for p in out.glob(f"{STAGING_PREFIX}*/frames/*.png")]
        if len(staged) >= 2:
            break
        time.sleep(0.02)
    assert len(staged) >= 2, proc.communicate()
    os.killpg(proc.pid, sig)
    _, stderr = proc.communicate(timeout=120)
    if proc.returncode == 0:  # a starved test process: the command had ended before the signal
        assert (out / "frames").exists() and stderr == ""
    elif sig == signal.SIGINT:
        assert proc.returncode == 128 + signal.SIGINT, stderr
        assert "interrupted" in one_error_line(stderr)
    else:  # the command dies at once; its renderer cleans up on its own
        assert proc.returncode == -signal.SIGTERM, stderr
        deadline = time.time() + 60
        while list(out.glob(f"{STAGING_PREFIX}*")) and time.time() < deadline:
            time.sleep(0.05)
    after = tree(out)
    assert not any(name.startswith(STAGING_PREFIX) for name in os.listdir(out))
    installed = (out / "frames").exists()
    if sig == signal.SIGINT and proc.returncode:  # it says which (SIGTERM ends it at once)
        assert installed == ("new pictures were installed" in stderr), stderr
    if installed:
        # a starved test process sent the signal while or after the finished pictures were
        # renamed into place (the rename holds it): all of them are new, complete and
        # listed - one PNG per trajectory frame
        manifest = read_manifest(out)
        frames = sorted(name for name in after if name.startswith("frames/"))
        assert len(frames) == read_run(out).times.size
        assert set(frames) <= manifest
        assert all(after[name].startswith(b"\x89PNG") for name in frames)
        assert "animation.gif" in manifest and "animation.gif" in after
        assert after["final.png"] != before["final.png"]
    else:
        assert after == before  # no frame, no GIF, no staging folder


# -- bench -----------------------------------------------------------------------------------
@pytest.fixture
def tiny(tmp_path) -> Path:
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


@pytest.mark.parametrize("name", ["trade_study.md", "trade_study.csv", "trade_study.png"])
def test_trade_study_refuses_a_users_file_before_measuring(tiny, tmp_path, name, capsys):
    out = tmp_path / "study"
    out.mkdir()
    (out / name).write_text("the user's own")
    (out / "other.txt").write_text("the user's own")
    before = tree(out)
    assert main(["bench", str(tiny), "--sweep", "time.dt=0.1", "--repeats", "1",
                 "-o", str(out)]) == 2
    captured = capsys.readouterr()
    line = one_error_line(captured.err)
    assert f"{out / name} was not written by fem-anim" in line, line
    assert captured.out == ""  # refused before the reference run
    assert tree(out) == before


def test_trade_study_writes_beside_users_files_and_replaces_its_own(tiny, tmp_path,
                                                                    monkeypatch, capsys):
    from fem_anim.bench import trade

    out = tmp_path / "study"
    out.mkdir()
    (out / "notes.md").write_text("the user's own")
    args = ["bench", str(tiny), "--sweep", "time.dt=0.1", "--repeats", "1", "-q",
            "-o", str(out)]
    assert main(args) == 0
    assert (out / "notes.md").read_text() == "the user's own"
    assert read_manifest(out) == set(trade.PRODUCTS)
    before = tree(out)

    real = trade._write_outputs

    def disk_fills(staging, *rest):  # the csv is written, then the disk is full
        real(staging, *rest)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(staging / "trade_study.md"))

    monkeypatch.setattr(trade, "_write_outputs", disk_fills)
    capsys.readouterr()
    assert main(args) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "No space left on device" in line and "nothing was replaced" in line, line
    assert tree(out) == before  # the previous study, whole


def test_trade_study_on_a_read_only_file_system_is_one_line(tiny, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    r = read_only(ro, fem_anim_command() + ["bench", str(tiny), "--sweep", "time.dt=0.1",
                                            "--repeats", "1", "-o", str(ro / "study")])
    assert r.returncode == 2, r.stderr
    line = one_error_line(r.stderr)
    assert "Read-only file system" in line and str(ro / "study") in line, line
    assert os.listdir(ro) == []


def never(*args, **kwargs):
    raise AssertionError("measured before the output folder was checked")


def test_perf_bench_refuses_a_users_file_before_the_sweep(tmp_path, capsys, monkeypatch):
    from fem_anim.bench import perf

    monkeypatch.setattr(perf, "sweep", never)
    (tmp_path / "perf.md").write_text("the user's own")
    before = tree(tmp_path)
    assert perf.main(["--sizes", "0.1", "--steps", "2", "--presets", "cg-icc",
                      "--out", str(tmp_path)]) == 2
    captured = capsys.readouterr()
    assert f"{tmp_path / 'perf.md'} was not written by fem-anim" in one_error_line(captured.err)
    assert "perf sweep" not in captured.out
    assert tree(tmp_path) == before


def test_extremes_refuses_a_users_file_before_the_cases(tmp_path, capsys, monkeypatch):
    from fem_anim.bench import extremes

    monkeypatch.setattr(extremes, "run_case", never)
    table = tmp_path / "table.md"
    table.write_text("the user's own")
    assert main(["bench", "--extremes", "-o", str(table)]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"{table} was not written by fem-anim" in line, line
    assert table.read_text() == "the user's own"


@pytest.mark.parametrize("module, work, args, name", [
    ("peers", "peer_table", [], "peers.md"),
    ("preview", "preview_table", ["--no-install"], "preview.md"),
    ("contact_cost", "_measure", [], "contact_bench.csv"),
    ("hard", "hard_run", ["--plain"], "plain_newton.md"),
])
def test_other_benches_refuse_a_users_file_before_measuring(module, work, args, name,
                                                            tmp_path, capsys, monkeypatch):
    import importlib

    bench = importlib.import_module(f"fem_anim.bench.{module}")
    monkeypatch.setattr(bench, work, never)
    (tmp_path / name).write_text("the user's own")
    argv = [*args, "--out", str(tmp_path)]
    code = main(["bench", "--hard", *argv]) if module == "hard" else bench.main(argv)
    assert code == 2
    line = one_error_line(capsys.readouterr().err)
    assert f"{tmp_path / name} was not written by fem-anim" in line, line
    assert (tmp_path / name).read_text() == "the user's own"
