"""A kill at any moment of a run with a shell body leaves a resumable run (docs/resume.md).

The joint run (a cloth falling on a soft cube, :mod:`fem_anim.simulation.joint_run`) stages
three trajectories, a joint checkpoint and the final files in ``OUT/.partial``. The driver of
``tests/test_kill_resume.py`` runs ``fem-anim run`` and SIGKILLs itself at the N-th rename
into the staging area, with the write torn (half the bytes, never renamed) or just after it.
The run is then continued the way the kill left it (``--resume`` when a checkpoint was
written, else a new run) and must end with the stats (but wall times) and the frames of the
three trajectories of an uninterrupted run, to the last bit. The default suite kills at a
few points (a frame, a checkpoint, the merge at the end); ``slow`` at every one.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from test_joint_resume import DRAPE, _same_run
from test_kill_resume import drive


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    """The scene's folder, the uninterrupted run and its staged renames' files, in order."""
    root = tmp_path_factory.mktemp("joint_kill")
    (root / "drape.toml").write_text(DRAPE)
    r, renames = drive(["run", "-q", "drape.toml", "-o", "whole"], root)
    assert r.returncode == 0, r.stderr
    names = (root / "renames.names").read_text().split()
    assert len(names) == renames
    return root, names


def kill_and_continue(whole, tmp_path: Path, at: int, mode: str) -> None:
    root, _ = whole
    (tmp_path / "drape.toml").write_text(DRAPE)
    args = ["run", "-q", "drape.toml", "-o", "run"]
    r, _ = drive(args, tmp_path, at, mode)
    assert r.returncode == -9, (at, mode, r.stderr)
    out = tmp_path / "run"
    assert not any((out / name).exists() for name in
                   ("stats.csv", "final_solids.vtu", "final_shell.vtu"))  # no result posed
    if (out / ".partial" / "checkpoint.npz").exists():
        args = ["run", "-q", "drape.toml", "--resume", "run"]
    r, _ = drive(args, tmp_path)
    assert r.returncode == 0, (at, mode, r.stderr)
    assert not (out / ".partial").exists()
    _same_run(root / "whole", out)


def test_the_kill_points_fall_where_they_are_meant_to(whole):
    """Each of the three trajectories' 7 frames with its XDMF list, 2 checkpoints, the merges;
    the points of ``POINTS`` on the files they are meant to cut."""
    names = whole[1]
    for name in ("solids", "shell", "trajectory"):
        assert [n for n in names if n.startswith(f"{name}.frames/")] == \
            [f"{name}.frames/frame{k:06d}.h5" for k in range(7)]
    assert names.count("checkpoint.npz") == 2
    at = [names[k - 1] if k > 0 else names[k] for k, _ in POINTS]
    assert at[:3] == ["checkpoint.npz", "shell.frames/frame000003.h5", "checkpoint.npz"]
    assert at[3:] == ["trajectory.xdmf", "scene.json"] and names[-5] == "solids.h5", names[-8:]
    assert names[-7] == "trajectory.h5"  # the merged file: trajectory.xdmf then points to it


#: Staged writes of the scene (counted from 1; negative: from the end): the first checkpoint
#: torn (nothing to resume: a new run), frame 3's shell frame after that checkpoint (frame 3
#: of the solids is there, of the others not), the second checkpoint torn (resume from the
#: first), the end's merges after the seen surface's (its frame files gone, the solids' and
#: the shell's not merged yet), and the last write (``test_the_kill_points_fall_where_they_are_meant_to`` checks them).
POINTS = [(25, "torn"), (28, "after"), (38, "torn"), (-6, "after"), (-1, "after")]


@pytest.mark.parametrize("point", POINTS, ids=[f"{at}-{mode}" for at, mode in POINTS])
def test_kill_a_joint_run_inside_writes_then_resume(whole, tmp_path, point):
    at, mode = point
    kill_and_continue(whole, tmp_path, at if at > 0 else len(whole[1]) + 1 + at, mode)


@pytest.mark.slow
def test_kill_a_joint_run_at_every_staged_write_then_resume(whole, tmp_path):
    for at in range(1, len(whole[1]) + 1):
        for mode in ("torn", "after"):
            case = tmp_path / f"{at}_{mode}"
            case.mkdir()
            kill_and_continue(whole, case, at, mode)
