"""``solver.mode = "preview"`` and the bench against VBD.

The preview is one Newton step per time step (the linearly implicit step), solved by CG with
incomplete Cholesky, accepted unconverged: each test checks what it fills in, that explicit
keys still win, that it is visibly cheaper than the exact run, and how far it strays from it.
"""

from __future__ import annotations

import numpy as np
import pytest
import scenes
from mpi4py import MPI
from conftest import mpirun_command
from test_cli import read_stats

from fem_anim.bench.preview import main as preview_main
from fem_anim.bench.preview import tip_errors
from fem_anim.bench.worker import measure
from fem_anim.cli import main
from fem_anim.errors import SceneError
from fem_anim.scene import default_scene_text, load_scene
from fem_anim.solver.stopping import BUDGET_REASON, CONVERGED_REASONS
from fem_anim.scene.modes import SOLVER_MODES

STEPS = 20
#: The preview's tip may stray from the exact run's by this fraction of the largest tip
#: displacement: measured 1.2e-3 on this beam (20 steps of 1/60 s, where exact Newton takes
#: 3 iterations per step; the 11 520-tet beam: 9.8e-4 over 60 steps); a preview that drops
#: the step's inertia or gravity is off by O(1).
PREVIEW_TIP_TOLERANCE = 2e-2


def test_preview_fills_what_the_scene_leaves_out():
    scene = load_scene(None, ['solver.mode="preview"'])
    assert {k: scene["solver"][k] for k in SOLVER_MODES["preview"]} == SOLVER_MODES["preview"]
    exact = load_scene(None, [])["solver"]
    assert exact["mode"] == "exact" and exact["max_iterations"] is None
    assert exact["preset"] == "cholesky" and exact["on_budget"] == "fail"


def test_explicit_keys_win_over_the_preview():
    scene = load_scene(None, ['solver.mode="preview"', "solver.max_iterations=3",
                              'solver.preset="cholesky"'])
    assert scene["solver"]["max_iterations"] == 3
    assert scene["solver"]["preset"] == "cholesky"
    assert scene["solver"]["on_budget"] == "accept"
    nested = load_scene(None, ['solver.mode="preview"', "solver.petsc.ksp.rtol=1e-6"])
    assert nested["solver"]["petsc"] == {"ksp": {"rtol": 1e-6}}  # not a second ksp_rtol


def test_a_mixed_scene_keeps_its_saddle_point_preset():
    scene = load_scene(None, ['solver.mode="preview"', "element.degree=2",
                              'element.formulation="mixed"', 'solver.preset="ldlt"',
                              'material.model="neohookean"', "damping.beta=0"])
    assert scene["solver"]["preset"] == "ldlt" and scene["solver"]["max_iterations"] == 1
    assert scene["solver"]["hessian"] == "exact"  # the saddle point is never filtered
    unset = load_scene(None, ['solver.mode="preview"', "element.degree=2",
                              'element.formulation="mixed"', "damping.beta=0"])
    assert unset["solver"]["preset"] != "cg-icc"


def test_several_models_or_a_kept_hessian_keep_the_exact_hessian(tmp_path):
    """auto filters one material model's tangent; a kept Hessian is never filtered."""
    region = '\n[[region]]\nname = "half"\nmin = [0.0, -1.0, -1.0]\nmax = [0.5, 1.0, 1.0]\n'
    path = tmp_path / "regions.toml"
    path.write_text(default_scene_text() + region + 'model = "stvk"\n')
    scene = load_scene(path, ['solver.mode="preview"'])
    assert scene["solver"]["hessian"] == "exact" and scene["solver"]["max_iterations"] == 1
    path.write_text(default_scene_text() + region + "youngs_modulus = 1e6\n")
    assert load_scene(path, ['solver.mode="preview"'])["solver"]["hessian"] == "auto"
    kept = load_scene(None, ['solver.mode="preview"', 'solver.hessian_update="every_step"'])
    assert kept["solver"]["hessian"] == "exact"


def test_unknown_mode_is_one_line(capsys):
    with pytest.raises(SceneError, match="solver.mode must be one of"):
        load_scene(None, ['solver.mode="quick"'])


def test_preview_run_is_one_newton_step_per_frame_near_the_exact_run(tmp_path):
    """Same beam, exact and preview side by side: 1 Newton iteration per step, every step
    accepted at its budget or converged, and the tip within PREVIEW_TIP_TOLERANCE."""
    keys = ["mesh.element_size=0.05", "time.dt=0.016666666666666666", f"time.steps={STEPS}",
            'time.integrator="implicit_euler"', "output.render=false"]
    exact = measure(load_scene(None, keys), None, STEPS, {}, MPI.COMM_SELF, tip=True)
    preview = measure(load_scene(None, [*keys, 'solver.mode="preview"']), None, STEPS, {},
                      MPI.COMM_SELF, tip=True)
    assert all(s["newton_its"] == 1 for s in preview["steps"])
    assert min(s["newton_its"] for s in exact["steps"]) >= 2  # the preview really saves
    errors = tip_errors(np.array(preview["tip"]), np.array(exact["tip"]), 1 / 60)
    assert 0.0 < errors[-1] < PREVIEW_TIP_TOLERANCE


def test_preview_flag_on_the_command_line(tmp_path):
    out = tmp_path / "run"
    code = main(["run", "-q", "--preview", "-o", str(out), "--set", "time.steps=3",
                 "--set", "mesh.element_size=0.1", "--set", "output.render=false"])
    assert code == 0
    rows = read_stats(out / "stats.csv")
    assert [int(r["newton_its"]) for r in rows] == [1, 1, 1]
    assert all(int(r["snes_reason"]) in (BUDGET_REASON, *CONVERGED_REASONS) for r in rows)
    assert all(int(r["linear_its"]) > 1 for r in rows)  # CG, not the Cholesky default


def test_tip_errors_are_relative_to_the_reference():
    reference = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -2.0]])
    tip = reference + [[0.0, 0.1, 0.0], [0.0, 0.0, 0.5]]
    at_half, at_one, whole = tip_errors(tip, reference, dt=0.25)
    assert at_half == pytest.approx(0.25) and np.isnan(at_one) and whole == pytest.approx(0.25)


def test_preview_bench_reduced(tmp_path, capsys):
    """The bench on a tiny beam, no pbatoolkit install: a table with the reference at 0."""
    code = preview_main(["--divisions", "6,2,2", "--steps", "3", "--no-install",
                         "--sweeps", "5", "--out", str(tmp_path)])
    assert code == 0
    text = (tmp_path / "preview.md").read_text()
    reference = next(line for line in text.splitlines() if "(reference)" in line)
    assert "| 144 |" in reference and reference.count("| 0 |") >= 1  # 6 tets per cube
    assert "preview" in text
    # where the exact step's time goes: the serial row, its floor below the step's time
    split = [line.split("|")[1:-1] for line in text.split("### Where")[1].splitlines()
             if line.startswith("| fem_anim exact")]
    assert split and all(float(row[-2]) < float(row[-4]) for row in split)  # floor, ms/step
    if mpirun_command(2) is not None:  # the same configuration on 2 ranks: the serial tip
        row = next(line for line in text.splitlines()
                   if "hessian auto, mpirun -n 2" in line and "not run" not in line)
        assert float(row.split("|")[8]) < 1e-3, row  # trajectory dev.: both converged steps


def test_preview_bench_bad_arguments(tmp_path, capsys):
    assert preview_main(["--divisions", "6,2", "--out", str(tmp_path)]) == 2
    assert "--divisions needs three numbers" in capsys.readouterr().err


@pytest.mark.mpi
def test_preview_under_mpi_equals_serial(tmp_path):
    """The preview on 2 ranks (block-Jacobi ICC, auto's collective choice) is the serial run
    to CG's tolerance: one Newton step per frame on both. CG is asked for 1e-10 here (the
    preview's 1e-4 leaves differences of that size between the two preconditioners)."""
    from conftest import mpirun_command
    from test_mpi_runs import assert_same_run, run

    if mpirun_command(2) is None:
        pytest.skip("mpirun not available")
    args = ["run", "-q", "--preview", "--set", "time.steps=4", "--set", "mesh.element_size=0.1",
            "--set", "output.render=false", "--set", "solver.petsc.ksp_rtol=1e-10"]
    for n in (1, 2):
        r = run([*args, "-o", str(tmp_path / f"n{n}")], tmp_path, n)
        assert r.returncode == 0, r.stderr
    assert_same_run(tmp_path / "n1", tmp_path / "n2")
    rows = [read_stats(tmp_path / f"n{n}" / "stats.csv") for n in (1, 2)]
    assert [int(r["newton_its"]) for r in rows[0]] == [int(r["newton_its"]) for r in rows[1]] \
        == [1] * 4


def test_the_benches_against_peers_run_the_undamped_beam():
    """pbatoolkit's beam has no damping; the default scene has (beta = 1e-4): the benches
    that compare with it and with the numpy reference switch it off."""
    from fem_anim.bench.peers import SCENE_SETTINGS
    from fem_anim.bench.preview import BEAM

    assert load_scene(None, [])["damping"]["beta"] > 0
    assert not load_scene(None, BEAM).damped and not load_scene(None, SCENE_SETTINGS).damped
