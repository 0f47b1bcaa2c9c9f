"""Every demo runs, reduced and off screen, and asserts its own physics."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import ROOT, clean_environment, mpirun_command

#: Every literate demo script in demos/ must be listed here (test_every_demo_is_registered).
DEMOS = ["materials.py", "optimisation_basics.py", "harmonic_oscillator.py", "twisted_bar.py",
         "two_material_bar.py", "plate_2d.py", "imported_mesh.py", "jelly_cube.py",
         "incompressible_ball.py", "pile.py", "fit_material.py", "drape.py", "flag.py",
         "throw_ball.py", "drape_soft.py"]


def test_every_demo_is_registered():
    found = sorted(p.name for p in (ROOT / "demos").glob("*.py"))
    assert found == sorted(DEMOS), "register new demos in tests/test_demos.py"


def run_demo(name: str, tmp_path, mpi: list[str] | None = None):
    env = clean_environment() | {"FEM_ANIM_DEMO_REDUCED": "1",
                                 "FEM_ANIM_DEMO_OUT": str(tmp_path)}
    return subprocess.run((mpi or []) + [sys.executable, str(ROOT / "demos" / name)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=900)


@pytest.mark.parametrize("name", DEMOS)
def test_demo_runs(name, tmp_path):
    r = run_demo(name, tmp_path)
    assert r.returncode == 0, r.stdout + r.stderr


@pytest.mark.slow
@pytest.mark.mpi
@pytest.mark.parametrize("name", DEMOS)
def test_demo_runs_in_parallel(name, tmp_path):
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    r = run_demo(name, tmp_path, mpi=mpirun)
    assert r.returncode == 0, r.stdout + r.stderr
