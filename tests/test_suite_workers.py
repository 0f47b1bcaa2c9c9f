"""How many worker processes the suite runs on (``tests/conftest.py``'s
``pytest_xdist_auto_num_workers``, asked by ``-n auto`` in pyproject's addopts): the whole
suite on min(CPUs, 4), a selection in the pytest process, the environment variable first."""

from __future__ import annotations

import os
from types import SimpleNamespace

import pytest

from conftest import MAX_WORKERS, pytest_xdist_auto_num_workers


def _config(source):
    return SimpleNamespace(args_source=source)


def test_whole_suite_runs_on_the_cores_up_to_the_cap(monkeypatch):
    monkeypatch.delenv("PYTEST_XDIST_AUTO_NUM_WORKERS", raising=False)
    for source in (pytest.Config.ArgsSource.TESTPATHS, pytest.Config.ArgsSource.INVOCATION_DIR):
        assert pytest_xdist_auto_num_workers(_config(source)) == min(
            len(os.sched_getaffinity(0)), MAX_WORKERS)


def test_a_selection_runs_in_this_process(monkeypatch):
    monkeypatch.delenv("PYTEST_XDIST_AUTO_NUM_WORKERS", raising=False)
    assert pytest_xdist_auto_num_workers(_config(pytest.Config.ArgsSource.ARGS)) == 0


def test_the_environment_variable_decides_first(monkeypatch):
    monkeypatch.setenv("PYTEST_XDIST_AUTO_NUM_WORKERS", "3")
    assert pytest_xdist_auto_num_workers(_config(pytest.Config.ArgsSource.ARGS)) == 3
    assert pytest_xdist_auto_num_workers(_config(pytest.Config.ArgsSource.TESTPATHS)) == 3


def test_the_suite_asks_for_auto_workers_one_file_per_worker(pytestconfig):
    addopts = pytestconfig.getini("addopts")
    assert "-n" in addopts and addopts[addopts.index("-n") + 1] == "auto"
    assert "--dist" in addopts and addopts[addopts.index("--dist") + 1] == "loadfile"
