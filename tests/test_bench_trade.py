"""The trade study (``fem-anim bench``): Pareto front, sweep validation and a real study.

CI tier: a 2D beam of 50 triangles, three time steps; the error against a reference that
differs only in its time step must fall as dt falls (Newmark is second order).
"""

import csv

import numpy as np
import pytest

from fem_anim.bench import trade
from fem_anim.bench.pareto import pareto_front
from fem_anim.bench.sweep import expand_study, split_values
from fem_anim.cli import main as cli_main

TINY = """
name = "tiny_beam"
[mesh]
dim = 2
size = [1.0, 0.2]
element_size = 0.1
[material]
youngs_modulus = 2.0e4
[time]
dt = 0.1
steps = 4
[gravity]
acceleration = [0.0, -9.81]
[[pin]]
min = [-1e-6, -1.0]
max = [1e-6, 1.0]
"""


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "tiny.toml"
    path.write_text(TINY)
    return path


def test_pareto_front_on_a_constructed_example():
    cost = [1.0, 2.0, 3.0, 2.5, 4.0, 1.0, np.nan, 5.0, 2.0]
    error = [1.0, 0.5, 0.2, 0.6, 0.2, 1.5, 0.01, 0.1, 0.5]
    # 0: cheapest with error 1; 5 dominated by 0; 1: better; 8 duplicates 1 (dropped);
    # 3 dominated by 1; 2; 4 as accurate as 2 but dearer; 6 NaN; 7 most accurate
    assert np.flatnonzero(pareto_front(cost, error)).tolist() == [0, 1, 2, 7]


def test_sweep_values_split_outside_brackets():
    assert split_values("[1,2],[3, 4] ,5") == ["[1,2]", "[3, 4]", "5"]


@pytest.mark.parametrize("sweep, needle", [
    ("time.dtt=0.1,0.05", "time.dtt"),
    ("time.dt=0.1,0.03", "does not divide"),
    ("element.degree=1,3", "element.degree"),
    ("time.steps=4,8", "time.steps"),
    ("time.dt", "--sweep expects"),
    ("solver.preset=cholesky,nonesuch", "nonesuch"),
])
def test_bad_sweep_exits_2_with_one_line(tiny, capsys, sweep, needle):
    assert cli_main(["bench", str(tiny), "--sweep", sweep]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fem-anim: error:") and needle in err[0], err


def test_forbidden_combination_is_skipped_not_an_error(tiny):
    study = expand_study(str(tiny), [], ["element.degree=1,2", "material.mass=consistent,lumped"],
                         [])
    skipped = [c.label for c in study.configurations if c.skipped]
    assert skipped == ["degree=2 mass=lumped"]
    assert all(c.scene["time"]["steps"] == 4 for c in study.configurations if c.scene)


def test_study_error_falls_with_dt(tiny, tmp_path):
    out = tmp_path / "study"
    code = trade.main([str(tiny), "--sweep", "time.dt=0.1,0.05,0.025", "--repeats", "2",
                       "--reference", "element.degree=1", "-o", str(out), "--quiet"])
    assert code == 0
    with open(out / "trade_study.csv") as f:
        rows = list(csv.DictReader(f))
    assert set(trade.COLUMNS) <= set(rows[0]) and "time.dt" in rows[0]
    assert [r["status"] for r in rows] == ["ok"] * 3
    err = [float(r["error_l2"]) for r in rows]
    # Newmark is second order: halving dt divides the error by about 4
    assert err[0] > 2.5 * err[1] > 2.5 ** 2 * err[2] > 0, err
    assert all(float(r["wall_per_sim_s"]) > 0 and float(r["compile_s"]) > 0 for r in rows)
    assert all(int(r["newton_its"]) >= int(r["steps"]) for r in rows)
    assert [int(r["steps"]) for r in rows] == [4, 8, 16]
    assert (out / "trade_study.png").stat().st_size > 10_000
    table = (out / "trade_study.md").read_text()
    on_front = [r["label"] for r in rows if r["pareto"] == "True"]
    assert on_front and all(f"| {r['time.dt']} |" in table for r in rows if r["pareto"] == "True")


@pytest.mark.mpi
@pytest.mark.slow
def test_study_under_mpi_equals_serial(tiny, tmp_path):
    import subprocess

    from conftest import clean_environment, fem_anim_command, mpirun_command

    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    args = ["bench", str(tiny), "--sweep", "time.dt=0.1,0.05", "--sweep", "element.degree=1,2",
            "--repeats", "1", "-q"]
    subprocess.run([*mpirun, *fem_anim_command(), *args, "-o", str(tmp_path / "mpi")],
                   check=True, env=clean_environment(), capture_output=True)
    assert trade.main([*args[1:], "-o", str(tmp_path / "serial")]) == 0
    tables = []
    for name in ("mpi", "serial"):
        with open(tmp_path / name / "trade_study.csv") as f:
            tables.append([[float(r[k]) for k in ("error_l2", "error_probe", "energy_drift")]
                           for r in csv.DictReader(f)])
    np.testing.assert_allclose(tables[0], tables[1], rtol=1e-6)
