"""A kill at any moment leaves a resumable run, and the resumed run is the uninterrupted one.

A driver runs ``fem-anim run`` with ``os.replace`` wrapped: at its N-th call on a file of
the staging area (a trajectory frame, the XDMF file, a checkpoint, the merged HDF5 file,
stats and final files) the process SIGKILLs itself, either with the write torn (the
temporary file cut to half its bytes, not renamed: a kill inside the write) or just after
the rename (a kill between two files). Every such run is then continued the way its
message says (``--resume`` when a checkpoint was written, else a new run) and must end with
the stats, trajectory and final state of an uninterrupted run, to the last bit (serial,
direct solver). The default suite kills at a few points; ``slow`` at every one.
"""

from __future__ import annotations

import csv
import os
import subprocess
import sys
from pathlib import Path

import meshio
import numpy as np
import pytest
from conftest import clean_environment

SCENE = """
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
checkpoint_every = 2
"""
TIMING = {"assembly_s", "factor_s", "linear_solve_s", "other_s", "solve_wall_s", "step_wall_s",
          "contact_s"}

#: Runs the command line; kills itself at the KILL_AT-th rename into the staging area.
DRIVER = r"""
import os, signal, sys
at, mode, count_file = int(os.environ["KILL_AT"]), os.environ["KILL_MODE"], os.environ["COUNT"]
rename, calls = os.replace, [0]

def replace(src, dst, *args, **kwargs):
    if "/.partial/" in str(dst):
        calls[0] += 1
        with open(count_file, "w") as f:
            f.write(str(calls[0]))
        with open(count_file + ".names", "a") as f:  # the staged files, in order
            f.write(str(dst).split("/.partial/")[1] + "\n")
        if calls[0] == at:
            if mode == "torn":  # killed inside the write: half the bytes, never renamed
                os.truncate(src, os.path.getsize(src) // 2)
            else:
                rename(src, dst, *args, **kwargs)
            os.kill(os.getpid(), signal.SIGKILL)
    return rename(src, dst, *args, **kwargs)

os.replace = replace
from fem_anim.cli import main
sys.exit(main(sys.argv[1:]))
"""


def drive(args: list[str], cwd: Path, at: int = 0, mode: str = "after"):
    env = clean_environment() | {"KILL_AT": str(at), "KILL_MODE": mode,
                                 "COUNT": str(cwd / "renames")}
    r = subprocess.run([sys.executable, "-c", DRIVER, *args], env=env, cwd=cwd,
                       capture_output=True, text=True, timeout=300)
    return r, int((cwd / "renames").read_text()) if (cwd / "renames").exists() else 0


def outputs(out: Path):
    with open(out / "stats.csv") as f:
        rows = [{k: v for k, v in row.items() if k not in TIMING} for row in csv.DictReader(f)]
    with meshio.xdmf.TimeSeriesReader(str(out / "trajectory.xdmf")) as reader:
        reader.read_points_cells()
        frames = [reader.read_data(k) for k in range(reader.num_steps)]
    final = meshio.read(out / "final.vtu").point_data["displacement"]
    return rows, frames, final


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The scene, the outputs of a run nobody killed, and its number of staged renames."""
    root = tmp_path_factory.mktemp("kill")
    (root / "tiny.toml").write_text(SCENE)
    r, renames = drive(["run", "-q", "tiny.toml", "-o", "whole"], root)
    assert r.returncode == 0, r.stderr
    return root, outputs(root / "whole"), renames


def kill_and_continue(uninterrupted, tmp_path, at: int, mode: str) -> None:
    root, (rows, frames, final), _ = uninterrupted
    (tmp_path / "tiny.toml").write_text(SCENE)
    args = ["run", "-q", "tiny.toml", "-o", "run"]
    r, _ = drive(args, tmp_path, at, mode)
    assert r.returncode == -9, (at, mode, r.stderr)
    out = tmp_path / "run"
    assert not (out / "final.vtu").exists()  # nothing poses as a result
    if (out / ".partial" / "checkpoint.npz").exists():
        args = ["run", "-q", "tiny.toml", "--resume", "run"]
    r, _ = drive(args, tmp_path)
    assert r.returncode == 0, (at, mode, r.stderr)
    assert not (out / ".partial").exists()
    rows_b, frames_b, final_b = outputs(out)
    assert rows_b == rows
    assert len(frames_b) == len(frames) == 7
    for (ta, pa, ca), (tb, pb, cb) in zip(frames, frames_b):
        assert ta == tb
        np.testing.assert_array_equal(pb["displacement"], pa["displacement"])
        np.testing.assert_array_equal(cb["energy_density"][0], ca["energy_density"][0])
    np.testing.assert_array_equal(final_b, final)


def test_the_driver_counts_every_staged_write(uninterrupted):
    """7 frames, their XDMF rewrites, 2 checkpoints, the merge: the points to kill at."""
    *_, renames = uninterrupted
    assert renames >= 7 * 2 + 2 + 2, renames


#: (rename, mode). Renames: trajectory.h5 (the mesh), XDMF, then per frame its file and
#: the XDMF, a checkpoint after frames 2 and 4; at the end the merged trajectory.h5, the
#: XDMF, scene.json. The 10th is frame 3's file (after the first checkpoint); the last is
#: scene.json, after the frame folder was merged and removed.
POINTS = {"frame-write-torn": (10, "torn"), "merge-torn": (-3, "torn"),
          "after-merge": (-1, "after")}


@pytest.mark.parametrize("point", list(POINTS))
def test_kill_inside_writes_then_resume(uninterrupted, tmp_path, point):
    *_, renames = uninterrupted
    at, mode = POINTS[point]
    kill_and_continue(uninterrupted, tmp_path, at if at > 0 else renames + 1 + at, mode)


@pytest.mark.slow
def test_kill_at_every_staged_write_then_resume(uninterrupted, tmp_path):
    *_, renames = uninterrupted
    for at in range(1, renames + 1):
        for mode in ("torn", "after"):
            case = tmp_path / f"{at}-{mode}"
            case.mkdir()
            kill_and_continue(uninterrupted, case, at, mode)
