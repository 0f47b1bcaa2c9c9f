"""Under ``mpirun -n 2``, the DOLFINx side gives the same comparisons with the numpy reference.

Launches ``tests/mpi/mpi_reference_check.py`` (see its docstring) on two ranks with the venv's
Python: the distributed energy, gradient, Hessian action, step objective, mass matrix and
ten-step trajectories, gathered to rank 0 in input vertex order and compared there with
:mod:`fem_anim.reference` to 1e-10 (assembly) and 1e-8 (trajectory positions). Measured on two
ranks: assembly <= 2.5e-15 relative, trajectory positions <= 1.6e-12, displacements
<= 1.1e-11 (``--full``: the same bounds over every material and integrator).

The unmarked test runs the reduced set (three materials, two trajectories, ~5 s); the full
set (every material, both mass matrices, every material with every integrator, ~15 s with
warm JIT caches) is marked ``slow``.
"""

from __future__ import annotations

import subprocess
import sys

import pytest
from conftest import ROOT, clean_environment, mpirun_command
from mpi4py import MPI

SCRIPT = ROOT / "tests" / "mpi" / "mpi_reference_check.py"

pytestmark = [
    pytest.mark.mpi,
    pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="launches mpirun itself"),
]


def run_check(tmp_path, *args: str) -> subprocess.CompletedProcess:
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    return subprocess.run(mpirun + [sys.executable, str(SCRIPT), *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=900, env=clean_environment())


def assert_passed(result: subprocess.CompletedProcess) -> None:
    report = "\n".join(line for line in result.stdout.splitlines() if not line.startswith("ok"))
    assert result.returncode == 0, f"exit {result.returncode}\n{report}\n{result.stderr[-3000:]}"
    assert "comparisons passed on 2 ranks" in result.stdout, result.stdout[-3000:]
    assert "FAIL" not in result.stdout


def test_reference_comparison_under_mpi(tmp_path):
    """Neo-Hookean, StVK and corotated assembly in 2D and 3D; two trajectories."""
    assert_passed(run_check(tmp_path))


@pytest.mark.slow
def test_reference_comparison_under_mpi_full(tmp_path):
    """Every material (and the lumped mass), every material with every integrator."""
    assert_passed(run_check(tmp_path, "--full"))
