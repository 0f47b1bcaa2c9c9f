"""Runs under ``mpirun``: the same results as serial, and failures that are collective.

Issue "Reliability", MPI part: ``mpirun -n 2`` and ``-n 3`` give the serial stats and final
displacement to 1e-8 relative; every failure, whichever rank detects it, ends all ranks with
exit code 2 and one ``fem-anim: error:`` line, never a hang (each run has a timeout) and
never a traceback.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

import meshio
import numpy as np
import pytest
from conftest import clean_environment, fem_anim_command, mpirun_command
from test_cli import read_stats

pytestmark = pytest.mark.mpi

PREFIX = "fem-anim: error: "
TIMEOUT = 600  # a hang fails the test instead of the whole suite


def run(args: list[str], cwd: Path, ranks: int = 1) -> subprocess.CompletedProcess:
    mpirun = [] if ranks == 1 else mpirun_command(ranks)
    if mpirun is None:
        pytest.skip("mpirun not available")
    return subprocess.run(mpirun + fem_anim_command() + args, cwd=cwd, capture_output=True,
                          text=True, timeout=TIMEOUT, env=clean_environment())


def assert_same_run(serial: Path, parallel: Path) -> None:
    """Stats energies and the final displacement agree to 1e-8 relative."""
    a, b = read_stats(serial / "stats.csv"), read_stats(parallel / "stats.csv")
    assert [r["step"] for r in a] == [r["step"] for r in b]
    for ra, rb in zip(a, b):
        assert rb["time"] == pytest.approx(ra["time"], rel=1e-12)
        for key in ("kinetic", "elastic", "gravity"):
            assert rb[key] == pytest.approx(ra[key], rel=1e-8, abs=1e-12), (ra["step"], key)
        # the total is a small difference of these: 1e-8 relative to the energy scale
        scale = abs(ra["kinetic"]) + abs(ra["elastic"]) + abs(ra["gravity"])
        assert abs(rb["total_energy"] - ra["total_energy"]) <= 1e-8 * scale, ra["step"]
    ua = meshio.read(serial / "final.vtu").point_data["displacement"]
    ub = meshio.read(parallel / "final.vtu").point_data["displacement"]
    assert np.linalg.norm(ub - ua) <= 1e-8 * np.linalg.norm(ua)


@pytest.fixture(scope="module")
def serial_default(tmp_path_factory) -> Path:
    """The default scene, 12 steps, serial: the run the parallel ones are compared with."""
    tmp = tmp_path_factory.mktemp("serial")
    r = run(["run", "-q", "--set", "time.steps=12", "--set", "output.render=false",
             "-o", str(tmp / "out")], tmp)
    assert r.returncode == 0, r.stderr
    return tmp / "out"


@pytest.mark.parametrize("ranks", [2, 3])
def test_default_scene_equals_serial(serial_default, tmp_path, ranks):
    r = run(["run", "-q", "--set", "time.steps=12", "--set", "output.render=false",
             "-o", str(tmp_path / "out")], tmp_path, ranks)
    assert r.returncode == 0, r.stderr
    assert_same_run(serial_default, tmp_path / "out")


@pytest.mark.slow
@pytest.mark.parametrize("ranks", [2, 3])
def test_full_default_scene_equals_serial(tmp_path, ranks):
    """All 60 steps of the default scene (the CI variant above runs 12)."""
    outs = {}
    for n in (1, ranks):
        outs[n] = tmp_path / f"n{n}"
        r = run(["run", "-q", "--set", "output.render=false", "-o", str(outs[n])], tmp_path, n)
        assert r.returncode == 0, r.stderr
    assert_same_run(outs[1], outs[ranks])


def _folded_mesh(tmp: Path) -> list[str]:
    """A mesh file with an inverted cell: found on the rank that reads the file."""
    from test_meshes import folded_box

    points, cells = folded_box()
    meshio.write(tmp / "folded.vtu", meshio.Mesh(points, [("tetra", cells)]))
    return ["--set", 'mesh.shape="file"', "--set", f'mesh.file="{tmp / "folded.vtu"}"']


def _not_a_run(tmp: Path) -> list[str]:
    (tmp / "empty").mkdir()
    return ["--resume", str(tmp / "empty")]


FAILURES = {
    # found while validating the scene, before dolfinx is imported (every rank alike)
    "scene key": (lambda tmp: ["--set", "material.poisson_ratio=0.5"],
                  "material.poisson_ratio"),
    # found by the rank that reads the mesh file, then broadcast
    "mesh file": (_folded_mesh, "is inverted"),
    # found inside SNES, a collective solve
    "no convergence": (lambda tmp: ["--set", "time.adaptive=false", "-snes_max_it", "1"],
                       "did not converge"),
    # found while reading the run directory to resume
    "resume": (_not_a_run, "empty"),
}


@pytest.mark.parametrize("case", list(FAILURES))
def test_failures_are_collective(tmp_path, case, ranks=3):
    """Every rank stops with exit code 2; exactly one error line, no traceback, no hang.

    Three ranks: an odd count, so no rank pairs up by accident (two ranks pass the same way).
    """
    setup, message = FAILURES[case]
    r = run(["run", "-q", "--set", "time.steps=2", "--set", "output.render=false",
             "-o", str(tmp_path / "out")] + setup(tmp_path), tmp_path, ranks)
    errors = [line for line in r.stderr.splitlines() if line.startswith(PREFIX)]
    assert r.returncode == 2, r.stderr
    assert len(errors) == 1 and message in errors[0], r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "out").exists() or case in ("no convergence", "resume")
