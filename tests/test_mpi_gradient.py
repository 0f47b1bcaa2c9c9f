"""The residual SNES solves with is the gradient of the objective it minimises, on 2 ranks
(``tests/mpi/mpi_gradient_check.py``: a moving press, pinned dofs owned by both ranks)."""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import ROOT, clean_environment, mpirun_command

SCRIPT = ROOT / "tests" / "mpi" / "mpi_gradient_check.py"


@pytest.mark.mpi
def test_residual_is_the_objectives_gradient_under_mpi():
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    r = subprocess.run([*mpirun, sys.executable, str(SCRIPT)], capture_output=True, text=True,
                       timeout=600, env=clean_environment(), cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "largest relative difference" in r.stdout
