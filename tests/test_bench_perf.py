"""The performance bench: the phase split, the growth fit, its command line, BAIJ storage.

CI tier: a tiny beam (element size 0.1) measured in-process; the split's parts are
non-negative and sum to at most the step's wall time, the symbolic factorisation happens
once (in the first step) and is reused afterwards; the growth-exponent fit recovers known
exponents; bad arguments exit 2 with one line. Slow: the driver end to end in subprocesses,
and the pbatoolkit worker when its virtual environment exists.
"""

from __future__ import annotations

import numpy as np
import pytest
from mpi4py import MPI

from fem_anim.bench import perf
from fem_anim.bench.timing import growth_exponent
from fem_anim.bench.worker import PHASE_COLUMNS, measure
from fem_anim.errors import FemAnimError
from fem_anim.scene import load_scene

TINY = ["mesh.element_size=0.1", "output.render=false"]


@pytest.fixture(scope="module")
def tiny_scene():
    return load_scene(None, TINY)


@pytest.mark.parametrize("preset", ["cholesky", "cg-icc"])
def test_split_parts_sum_to_at_most_the_step(tiny_scene, preset):
    r = measure(tiny_scene, preset, steps=3, comm=MPI.COMM_WORLD, tip=True)
    assert r["tets"] > 0 and r["dofs"] > 0 and r["peak_mb"] > 0
    for step in r["steps"]:
        parts = [step[c] for c in PHASE_COLUMNS if c != "other"]
        assert all(p >= 0.0 for p in parts), step
        assert sum(parts) <= step["wall"] * (1 + 1e-9) + 1e-9, step
        assert step["other"] >= -1e-9
        assert step["newton_its"] >= 1
        # the Hessian is assembled and factorised (or preconditioned) in every step
        assert step["jacobian"] > 0.0 and step["factor_numeric"] + step["solve"] > 0.0
    if preset == "cholesky":
        first, later = r["steps"][0], r["steps"][1:]
        assert first["symbolic_calls"] >= 1, "the first step analyses the pattern"
        assert all(s["symbolic_calls"] == 0 for s in later), "symbolic factorisation reused"
        assert all(s["factor_calls"] >= s["newton_its"] for s in later)
    assert np.asarray(r["tip"]).shape == (3, 3)
    assert r["tip"][-1][2] < 0.0, "the tip falls under gravity"


def test_growth_exponent_recovers_known_slopes():
    n = np.array([1e3, 1e4, 1e5, 3e5])
    assert growth_exponent(n, 2.5e-6 * n**1.5) == pytest.approx(1.5, abs=1e-12)
    assert growth_exponent(n, 7.0 * n) == pytest.approx(1.0, abs=1e-12)
    rng = np.random.default_rng(1)
    noisy = 1e-4 * n**1.2 * np.exp(0.02 * rng.standard_normal(n.size))
    assert growth_exponent(n, noisy) == pytest.approx(1.2, abs=0.05)
    assert np.isnan(growth_exponent([10.0], [1.0]))


@pytest.mark.parametrize("argv, fragment", [
    (["--sizes", "abc"], "--sizes"),
    (["--sizes", "-1"], "--sizes"),
    (["--presets", "nope"], "unknown preset 'nope'"),
    (["--steps", "0"], "--steps"),
    (["--repeats", "0"], "--repeats"),
    (["--bogus"], "unrecognized arguments"),
])
def test_bad_arguments_exit_2_with_one_line(argv, fragment, capsys):
    assert perf.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("fem-anim: error: ") and fragment in err[0]


def test_baij_hessian_gives_the_same_step(tiny_scene):
    """-mat_type baij (blocked storage, faster assembly) changes nothing in the result."""
    from fem_anim.simulation.loop import Simulation

    finals = []
    for options in ({}, {"mat_type": "baij"}):
        sim = Simulation(tiny_scene, MPI.COMM_WORLD, options, preset="cg-jacobi")
        assert sim.minimiser.A.getType().endswith("baij" if options else "aij")
        state = sim.initial_state()
        for _ in range(2):
            state, _ = sim.step(state, tiny_scene["time"]["dt"])
        finals.append(state.u.copy())
        sim.minimiser.destroy()
    scale = np.abs(finals[0]).max()
    assert scale > 1e-4
    # the same iterates: measured bit for bit equal
    assert np.abs(finals[0] - finals[1]).max() <= 1e-15 * scale


def test_bad_mat_type_is_named(tiny_scene):
    from fem_anim.simulation.loop import Simulation

    with pytest.raises(FemAnimError, match="mat_type"):
        Simulation(tiny_scene, MPI.COMM_WORLD, {"mat_type": "dense"})


@pytest.mark.slow
def test_driver_end_to_end(tmp_path):
    """The sweep in subprocesses writes the csv, the table with exponents, and the plot."""
    code = perf.main(["--sizes", "0.1,0.07", "--steps", "2", "--presets", "cg-icc",
                      "--out", str(tmp_path), "--set", "output.render=false"])
    assert code == 0
    text = (tmp_path / "perf.md").read_text()
    assert "growth exponent" in text and "| cg-icc |" in text
    assert (tmp_path / "perf.png").stat().st_size > 1000
    assert len((tmp_path / "perf.csv").read_text().splitlines()) == 3


@pytest.mark.mpi
def test_mpi_section_pairs_serial_and_two_ranks(tmp_path):
    """--mpi: serial and mpirun -n 2 back to back, --repeats pairs, medians and each pair."""
    from conftest import mpirun_command

    if mpirun_command(2) is None:
        pytest.skip("mpirun not available")
    code = perf.main(["--sizes", "0.1", "--steps", "1", "--presets", "cg-icc", "--mpi",
                      "--repeats", "2", "--out", str(tmp_path), "--set", "output.render=false"])
    assert code == 0
    text = (tmp_path / "perf.md").read_text()
    section = text[text.index("## MPI"):]
    rows = [line for line in section.splitlines() if line.startswith("| cg-icc |")]
    assert [row.split("|")[2].strip() for row in rows] == ["1", "2"]
    pairs = rows[1].split("|")[11].split(",")
    assert len(pairs) == 2 and all(float(p) > 0 for p in pairs)
    assert float(rows[1].split("|")[12]) == pytest.approx(np.median([float(p) for p in pairs]),
                                                           abs=0.01)


@pytest.mark.slow
def test_pbatoolkit_worker_runs_when_installed(tmp_path):
    from fem_anim.bench.peers import compare, peer_python

    python = peer_python(install=False)
    if python is None:
        pytest.skip("pbatoolkit's virtual environment is not installed")
    rows = compare(None, [], 0.1, 3, python, log=lambda *_: None)
    names = [r[0] for r in rows]
    assert any(n.startswith("pbatoolkit Newton") for n in names)
    newton = next(r for r in rows if r[0].startswith("pbatoolkit Newton"))
    assert newton[4] < 1e-2, "same beam, same rest response: the tips agree"


@pytest.mark.slow
def test_60k_run_plain_newton_fails_fem_anim_finishes():
    """The default scene on ~60k tetrahedra (about 20 minutes on 2 shared cores).

    Plain Newton (full steps, no filter, fixed dt) meets an indefinite Hessian at the
    beam's largest swing (t = 0.583 s, step 35); fem_anim's default finishes the 60 steps.
    """
    from fem_anim.bench.hard import CONFIGS, HARD_ELEMENT_SIZE, run_case

    label, sets, petsc = CONFIGS[0]
    plain = run_case(None, [f"mesh.element_size={HARD_ELEMENT_SIZE}", *sets], petsc, "cg-icc")
    assert not plain["finished"] and "INDEFINITE" in plain["error"]
    assert 0.4 < plain["t_end"] < 0.7
    label, sets, petsc = CONFIGS[2]
    ours = run_case(None, [f"mesh.element_size={HARD_ELEMENT_SIZE}", *sets], petsc, "cg-icc")
    assert ours["finished"] and ours["steps"] >= 60 and ours["t_end"] == pytest.approx(1.0)


def test_baij_presets_fall_back_to_aij_under_another_preconditioner():
    """cg-icc stores the Hessian as BAIJ; -pc_type gamg (which rejects BAIJ) drops it."""
    from fem_anim.solver.presets import PRESETS, drop_replaced

    assert PRESETS["cg-icc"]["mat_type"] == "baij"
    assert "mat_type" not in drop_replaced(PRESETS["cg-icc"], {"pc_type": "gamg"})
    assert drop_replaced(PRESETS["cg-icc"], {"ksp_rtol": "1e-8"})["mat_type"] == "baij"
    assert "mat_type" not in PRESETS["cholesky"]
