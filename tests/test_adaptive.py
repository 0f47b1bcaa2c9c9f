"""Adaptive time stepping: a failed step is retried with dt halved, then dt grows back."""

from __future__ import annotations

import csv
import json
import math

import meshio
import numpy as np
import pytest

from fem_anim.cli import main

PLATE_2D = ["--set", "mesh.dim=2", "--set", "mesh.size=[1.0, 0.2]",
            "--set", "gravity.acceleration=[0, -9.81]", "--set", "pin.0.min=[-0.001, -1]",
            "--set", "pin.0.max=[0.001, 1]", "--set", "element.degree=2",
            "--set", "output.render=false",
            # exact Newton fails at the largest swing, which the stepper must handle (auto,
            # the default Hessian mode, takes every step of this plate at the full dt)
            "--set", 'solver.hessian="exact"']


def rows(path):
    with open(path) as f:
        return [{k: float(v) for k, v in r.items()} for r in csv.DictReader(f)]


def test_large_swing_completes_by_substepping(tmp_path):
    """A 2D P2 corotated beam: at its largest swing Newton fails at dt = 1/60 s.

    With adaptive stepping the failed steps are retried with smaller dt; every frame is
    at a multiple of 1/60 s, nothing is NaN, and stats.csv records the substeps.
    """
    out = tmp_path / "adaptive"
    assert main(["run", "-o", str(out), "-q", "--set", "material.model=corotated"]
                + PLATE_2D) == 0
    stats = rows(out / "stats.csv")
    assert sum(r["retries"] for r in stats) > 0 and len(stats) > 60
    assert min(r["dt"] for r in stats) < 1 / 60 - 1e-12
    # the discarded tries' wall time: in the row after them, and in the run's stepping
    assert all((r["retry_wall_s"] > 0) == (r["retries"] > 0) for r in stats)
    summary = json.loads((out / "summary.json").read_text())
    retry_s = sum(r["retry_wall_s"] for r in stats)
    assert summary["retry_wall_s"] == pytest.approx(retry_s, rel=1e-9)
    assert summary["wall"]["stepping_s"] == \
        pytest.approx(sum(r["step_wall_s"] for r in stats) + retry_s, rel=1e-6)
    assert all(math.isfinite(r["total_energy"]) for r in stats)
    assert stats[-1]["time"] == pytest.approx(1.0, abs=1e-12)
    with meshio.xdmf.TimeSeriesReader(str(out / "trajectory.xdmf")) as reader:
        reader.read_points_cells()
        times = [reader.read_data(k)[0] for k in range(reader.num_steps)]
        last = reader.read_data(reader.num_steps - 1)[1]["displacement"]
    np.testing.assert_allclose(times, np.arange(61) / 60, atol=1e-12)
    assert np.all(np.isfinite(last))


def test_without_adaptivity_the_same_run_stops_cleanly(tmp_path, capsys):
    out = tmp_path / "fixed"
    code = main(["run", "-o", str(out), "-q", "--set", "material.model=corotated",
                 "--set", "time.adaptive=false"] + PLATE_2D)
    assert code == 2
    err = capsys.readouterr().err
    assert "did not converge" in err and f"--resume {out}" in err
    # nothing poses as a result; the staging area is kept for --resume
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".fem_anim-")) \
        == [".partial"]  # and the run directory's marker and lock (fem_anim/output/rundir.py)


def test_min_dt_floor_is_reported(tmp_path, capsys):
    code = main(["run", "-o", str(tmp_path / "o"), "-q", "--set", "material.model=corotated",
                 "--set", "time.min_dt=0.01"] + PLATE_2D)
    assert code == 2
    assert "time.min_dt = 0.01 s reached" in capsys.readouterr().err


def test_min_dt_must_not_exceed_dt(capsys):
    assert main(["run", "-q", "--set", "time.min_dt=1.0"]) == 2
    assert "time.min_dt must not exceed time.dt" in capsys.readouterr().err


@pytest.mark.parametrize("integrator", ["bdf2", "newmark", "implicit_euler"])
def test_every_integrator_substeps(tmp_path, integrator):
    out = tmp_path / integrator
    assert main(["run", "-o", str(out), "-q", "--set", "material.model=neohookean",
                 "--set", f"time.integrator={integrator}", "--set", "time.steps=40",
                 # undamped, so that every scheme meets the failing steps (damped, implicit
                 # Euler's own damping took them all at the full dt: 0 retries)
                 "--set", "damping.beta=0"] + PLATE_2D) == 0
    stats = rows(out / "stats.csv")
    assert sum(r["retries"] for r in stats) > 0  # measured: bdf2 6, newmark 6, IE 5
    assert stats[-1]["time"] == pytest.approx(40 / 60, abs=1e-12)
    assert all(math.isfinite(r["total_energy"]) for r in stats)
