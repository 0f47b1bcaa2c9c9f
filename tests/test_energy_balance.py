"""The energy line's balance (issue 33 point 6): stored energy, the handles' work, and what
damping, friction and the time step took, each recomputable from the run's files.

A bar held at x = 0 and pulled at x = 1 by a handle: each step's ``handle_work`` in
``stats.csv`` is recomputed with the numpy oracle from the written displacement and
velocity (implicit Euler: the pin's force at the step's end is
M (u_{n+1} - u_n - h v_n) / h^2 + grad E(u_{n+1}) on the pinned vertices, times their
motion); ``summary.json``'s balance and the printed line follow from those columns. A body
resting on the ground in contact says nothing alarming.
"""

from __future__ import annotations

import csv
import json

import h5py
import numpy as np
import pytest
from mpi4py import MPI
from scenes import bar, make_scene, merge, wall_pin

from fem_anim.cli import main
from fem_anim.reference.assembly import elastic_gradient
from fem_anim.reference.mass import mass_matrix
from fem_anim.reference.materials import lame_parameters

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: one run per process")

H, E, NU, RHO = 0.02, 2e4, 0.3, 1000.0
HANDLE = {"name": "handle", "min": [1.0 - 1e-6, -1.0, -1.0], "max": [1.0 + 1e-6, 1.0, 1.0],
          "velocity": [0.05, 0.0, 0.02]}


def test_handle_work_recomputed_from_the_written_fields(tmp_path, capsys):
    scene = bar("pulled", pin=[wall_pin(), HANDLE],
                material={"model": "stvk", "youngs_modulus": E, "poisson_ratio": NU,
                          "density": RHO},
                time={"dt": H, "steps": 5, "integrator": "implicit_euler"},
                output={"render": False, "fields": ["velocity"]},
                solver={"petsc": {"snes_rtol": 1e-12}})
    make_scene(tmp_path, scene)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "pulled.toml"), "-o", str(out)]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    rows = list(csv.DictReader(open(out / "stats.csv")))
    assert len(rows) == 5
    with h5py.File(out / "trajectory.h5", "r") as h5:
        points, cells = h5["data0"][()], h5["data1"][()]
        u = [h5[f"data{k + 2}"][()] for k in range(6)]
        v = [h5[f"velocity_dofs{k}"][()] for k in range(6)]
        nodes = h5["velocity_nodes"][()]
    assert np.array_equal(nodes[:, 0], np.arange(points.shape[0]))  # P1: the vertices
    mu, lmbda = lame_parameters(E, NU)
    M = mass_matrix(points, cells, RHO)
    pinned = (np.abs(points[:, 0]) < 1e-6) | (np.abs(points[:, 0] - 1.0) < 1e-6)
    works = []
    for n in range(5):
        inertia = M @ (u[n + 1] - u[n] - H * v[n]).ravel() / H**2
        force = (inertia + elastic_gradient(points, cells, "stvk", mu, lmbda,
                                            (points + u[n + 1]).ravel())).reshape(-1, 3)
        works.append(float(np.sum(force[pinned] * (u[n + 1] - u[n])[pinned])))
    recorded = [float(r["handle_work"]) for r in rows]
    assert max(works) > 0.0  # the handle pulled
    np.testing.assert_allclose(recorded, works, rtol=0, atol=1e-7 * max(map(abs, works)))
    # the balance of summary.json and the line: W, D = E_0 + W - E_end, from the columns
    energy = json.loads((out / "summary.json").read_text())["energy"]
    work = sum(recorded)
    assert energy["handle_work"] == pytest.approx(work, rel=1e-12)
    dissipated = energy["initial_energy"] + work - float(rows[-1]["total_energy"])
    assert energy["dissipated"] == pytest.approx(dissipated, rel=1e-9, abs=1e-15)
    assert 0.0 <= dissipated < 0.5 * work  # implicit Euler takes some, never gives
    assert f"handles did {work:+.4g} J of work" in line, line
    assert f"took {dissipated:.4g} J" in line, line
    assert "%" not in line and "GAINED" not in line, line


def test_a_gain_beyond_the_handles_work_is_flagged(tmp_path):
    """Rows whose stored energy rose by more than the handles' work: flagged, and said."""
    from fem_anim.simulation.energy_report import describe_energy, energy_report

    s = make_scene(tmp_path, bar("pulled", pin=[wall_pin(), HANDLE]))
    initial = {"kinetic": 0.0, "elastic": 0.0, "gravity": 0.0, "total_energy": 0.0,
               "roundoff": 1e-12}
    rows = [{"step": k, "kinetic": 0.1, "elastic": 1.0 * k, "gravity": 0.0,
             "contact": 0.0, "total_energy": 1.0 * k + 0.1, "handle_work": work}
            for k, work in ((1, 1.2), (2, 0.9))]
    honest = energy_report(rows, initial, s)
    assert honest["dissipated"] == pytest.approx(2.1 - 2.1) and not honest["flagged"]
    rows[1]["handle_work"] = 0.5  # the stored energy rose 2.1 J for 1.7 J of work
    report = energy_report(rows, initial, s)
    assert report["dissipated"] == pytest.approx(-0.4)
    assert report["gained"] and report["flagged"]
    assert "GAINED" in describe_energy(report, s)


def test_a_body_at_rest_on_the_ground_says_nothing_alarming(tmp_path, capsys):
    """A cube dropped 1 mm onto a plane, settled by implicit Euler: the line gives the
    stored energy and what the step took, no percentage, no advice, no flag."""
    scene = merge(bar("resting", pin=[]), mesh={"size": [0.1, 0.1, 0.1], "element_size": 0.05},
                  gravity={"acceleration": [0.0, 0.0, -9.81]},
                  material={"youngs_modulus": 1e5},
                  time={"dt": 0.02, "steps": 25, "integrator": "implicit_euler"},
                  output={"render": False})
    scene["obstacle"] = [{"type": "plane", "point": [0.0, 0.0, -0.051],
                          "normal": [0.0, 0.0, 1.0], "dhat": 0.002}]
    make_scene(tmp_path, scene)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "resting.toml"), "-o", str(out)]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    energy = json.loads((out / "summary.json").read_text())["energy"]
    assert energy["came_to_rest"] and not energy["flagged"]
    assert "%" not in line.split("at most")[0] and "GAINED" not in line, line
    assert "numerical damping" not in line and "use " not in line, line
    assert "came to rest" in line, line
