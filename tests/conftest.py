"""Shared pytest set-up and helpers.

After each test, garbage is collected and the MPI ranks synchronise (so a collective
destructor never runs on one rank only; the heap surviving a module's start is frozen, so
that collection is cheap); the helpers start the command line and ``mpirun``
in subprocesses and check Newton's residual test on a run's statistics rows.
"""

import gc
import logging
import os
import shutil
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


#: The most worker processes the whole suite runs on (each holds DOLFINx, and many tests
#: start ``mpirun -n 2`` or a run of their own).
MAX_WORKERS = 4


def pytest_xdist_auto_num_workers(config) -> int:
    """``-n auto`` (pyproject's addopts): the whole suite on min(CPUs, 4) workers, in this process
    when paths or node ids were given (a selection: no workers to start), or as
    ``PYTEST_XDIST_AUTO_NUM_WORKERS`` says."""
    if "PYTEST_XDIST_AUTO_NUM_WORKERS" in os.environ:
        return int(os.environ["PYTEST_XDIST_AUTO_NUM_WORKERS"])
    if config.args_source == pytest.Config.ArgsSource.ARGS:
        return 0
    return min(len(os.sched_getaffinity(0)), MAX_WORKERS)


@pytest.fixture(autouse=True, scope="module")
def _heap_frozen_per_module():
    """At each test module's start: a full collection, then the surviving heap frozen.

    The per-test ``gc.collect()`` below then scans only what was made since (the imported
    libraries' millions of objects made every collection cost ~20 ms); what an earlier
    module left and later dropped is collected here, at the next module's start, at the
    same point on every rank."""
    gc.unfreeze()
    gc.collect()
    gc.freeze()
    yield


@pytest.fixture(autouse=True)
def _mpi_hygiene():
    yield
    gc.collect()
    from mpi4py import MPI

    MPI.COMM_WORLD.barrier()
    for handler in logging.getLogger().handlers:  # FFCx JIT build chatter
        handler.setLevel(logging.WARNING)


def fem_anim_command() -> list[str]:
    """How to start the command line in a subprocess.

    Returns:
        The argument list ``[python, "-m", "fem_anim"]`` with this venv's Python.
    """
    return [sys.executable, "-m", "fem_anim"]


def clean_environment() -> dict[str, str]:
    """The environment without the MPI singleton's variables, for launching mpirun.

    Returns:
        A copy of ``os.environ`` without ``OMPI_*``, ``PMIX_*`` and ``PMI_*``.
    """
    return {k: v for k, v in os.environ.items() if not k.startswith(("OMPI_", "PMIX_", "PMI_"))}


def mpirun_command(n: int) -> list[str] | None:
    """The ``mpirun`` prefix of a command.

    Args:
        n: The number of ranks.

    Returns:
        The prefix (oversubscribed; ``--allow-run-as-root`` as root), or None without mpirun.
    """
    mpirun = shutil.which("mpirun")
    if mpirun is None:
        return None
    cmd = [mpirun, "-n", str(n), "--oversubscribe"]
    if os.geteuid() == 0:
        cmd.append("--allow-run-as-root")
    return cmd


def run_file_under_mpirun(path: str | Path, ranks: int, cwd: Path) -> None:
    """Run the test file ``path`` as a script (its ``__main__`` checks, exit 0 when they hold)
    under ``mpirun -n ranks`` in ``cwd``; skip without mpirun, fail with its output."""
    import subprocess

    mpirun = mpirun_command(ranks)
    if mpirun is None:
        pytest.skip("mpirun not available")
    proc = subprocess.run([*mpirun, sys.executable, str(path)], cwd=cwd, capture_output=True,
                          text=True, timeout=600, env=clean_environment())
    assert proc.returncode == 0, proc.stdout + proc.stderr


def run_on_one_and_more_ranks(scene: Path, folder: Path, ranks: int = 2) -> dict[int, Path]:
    """``fem-anim run -q SCENE`` on one rank, then under ``mpirun -n ranks`` (the test is
    skipped without mpirun); each run must succeed.

    Args:
        scene: The scene file.
        folder: Where the output folders ``out1`` and ``out<ranks>`` go.
        ranks: The rank count of the second run.

    Returns:
        The output folder of each rank count.
    """
    import subprocess

    outs = {}
    for n in (1, ranks):
        prefix = [] if n == 1 else mpirun_command(n)
        if prefix is None:
            pytest.skip("mpirun not available")
        outs[n] = folder / f"out{n}"
        r = subprocess.run(prefix + fem_anim_command() + ["run", "-q", str(scene), "-o",
                                                          str(outs[n])],
                           capture_output=True, text=True, timeout=600,
                           env=clean_environment())
        assert r.returncode == 0, r.stderr
    return outs


def gradients_on_two_ranks_equal_serial(script: str, serial) -> None:
    """J and the gradient of each scene of ``serial()`` (scene -> ``{"J": ..., "grad": [...]}``)
    equal those of ``script`` under ``mpirun -n 2`` to 1e-8 (skipped without mpirun).

    Args:
        script: A test module whose ``__main__`` prints the same dict as JSON on rank 0
            (:func:`print_on_rank_zero`).
        serial: Computes the dict in this process.
    """
    import json
    import subprocess

    import numpy as np

    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    r = subprocess.run([*mpirun, sys.executable, script], capture_output=True, text=True,
                       timeout=900, env=clean_environment(), cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    parallel = json.loads(r.stdout.strip().splitlines()[-1])
    for scene, result in serial().items():
        assert parallel[scene]["J"] == pytest.approx(result["J"], rel=1e-8), scene
        np.testing.assert_allclose(parallel[scene]["grad"], result["grad"], rtol=1e-8,
                                   atol=1e-8 * np.abs(result["grad"]).max())


def print_on_rank_zero(result: dict) -> None:
    """``result`` as one JSON line on rank 0 (a ``__main__`` run by mpirun)."""
    import json

    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(result))


def step_taylor_remainders(problem, A, x, dx) -> tuple[list[float], list[float]]:
    """The Taylor remainders of a step objective along ``dx`` from ``x``, h = 1, 1/2, 1/4, 1/8:
    |g(x + h dx) - g(x) - h r(x).dx| and ||r(x + h dx) - r(x) - h H(x) dx|| (both fall at
    order 2 when the residual r and the Hessian H, assembled into ``A``, are g's).

    Args:
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem` (state at ``x``).
        A: The PETSc matrix its Jacobian is assembled into.
        x: The point (PETSc vector).
        dx: The direction (PETSc vector).
    """
    g0 = problem.objective(None, x)
    r0, r1 = x.duplicate(), x.duplicate()
    problem.residual(None, x, r0)
    problem.jacobian(None, x, A, A)
    Hdx = x.duplicate()
    A.mult(dx, Hdx)
    first, second = [], []
    for h in (1.0, 0.5, 0.25, 0.125):
        xh = x.copy()
        xh.axpy(h, dx)
        first.append(abs(problem.objective(None, xh) - g0 - h * r0.dot(dx)))
        problem.residual(None, xh, r1)
        r1.axpy(-1.0, r0)
        r1.axpy(-h, Hdx)
        second.append(r1.norm())
        xh.destroy()
    return first, second


def process_tree(pid: int) -> list[int]:
    """A process and all its descendants, read from /proc.

    Args:
        pid: The root process.

    Returns:
        Its pid and its descendants' pids, parents first.
    """
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:  # the process ended meanwhile
            continue
        children.setdefault(int(fields[1]), []).append(int(stat.parent.name))
    tree, todo = [], [pid]
    while todo:
        p = todo.pop(0)
        tree.append(p)
        todo.extend(children.get(p, []))
    return tree


def kill_tree(pid: int, sig: int) -> None:
    """Send ``sig`` to a process and every descendant.

    ``os.killpg`` is not enough: OpenMPI 5's launcher puts each rank in a process group of
    its own, so killing the launcher's group leaves the ranks running (and holding the
    trajectory's HDF5 file lock).

    Args:
        pid: The root process.
        sig: The signal number.
    """
    for p in process_tree(pid):
        try:
            os.kill(p, sig)
        except ProcessLookupError:
            pass


#: Newton's documented default residual test (``solver.stopping = "norm"``): rtol, atol.
README_RTOL, README_ATOL = 1e-8, 1e-12


def assert_rows_meet_the_test(rows, rtol: float = README_RTOL, atol: float = README_ATOL):
    """Assert every stats row met its residual test.

    A row passes with a converged SNES reason (2 or 3, not the polish's 6) and
    ``residual_norm <= max(atol, rtol initial_residual_norm)``.

    Args:
        rows: The run's ``stats.csv`` rows.
        rtol: The relative tolerance.
        atol: The absolute tolerance.
    """
    from fem_anim.solver.stopping import CONVERGED_REASONS

    for row in rows:
        target = max(atol, rtol * row["initial_residual_norm"])
        assert row["snes_reason"] in CONVERGED_REASONS, row
        assert row["residual_norm"] <= target, (row["step"], row["residual_norm"], target)
