"""The path a user walks: ``fem-anim run`` on the default scene, options, overrides, errors.

Runs that need a fresh process (exit codes, stderr, MPI)
start ``python -m fem_anim``; the rest call :func:`fem_anim.cli.main` in-process.
"""

from __future__ import annotations

import csv
import math
import subprocess
import tomllib
from pathlib import Path

import meshio
import numpy as np
import pytest
from conftest import ROOT, assert_rows_meet_the_test, clean_environment, fem_anim_command

from fem_anim.cli import main
from fem_anim.scene import default_scene_text, load_scene


def read_stats(path: Path) -> list[dict[str, float]]:
    with open(path) as f:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]


def run_cli(args: list[str], cwd: Path, mpi: list[str] | None = None):
    return subprocess.run((mpi or []) + fem_anim_command() + args, cwd=cwd,
                          capture_output=True, text=True, timeout=600, env=clean_environment())


@pytest.fixture(scope="module")
def default_run(tmp_path_factory) -> Path:
    """The default scene, run once for the whole module."""
    out = tmp_path_factory.mktemp("default") / "beam"
    assert main(["run", "-o", str(out), "--quiet"]) == 0
    return out


def test_default_scene_outputs(default_run):
    names = {p.name for p in default_run.iterdir()}
    assert {"trajectory.xdmf", "trajectory.h5", "stats.csv", "final.vtu", "final.png"} <= names
    assert not (default_run / ".partial").exists()
    rows = read_stats(default_run / "stats.csv")
    assert len(rows) == 60
    assert_rows_meet_the_test(rows)  # the documented default residual test, every step
    assert rows[-1]["time"] == pytest.approx(1.0)
    for row in rows:
        for key in ("kinetic", "elastic", "gravity", "total_energy", "newton_its",
                    "step_wall_s"):
            assert math.isfinite(row[key]), (row["step"], key)
        assert row["total_energy"] == pytest.approx(
            row["kinetic"] + row["elastic"] + row["gravity"], rel=1e-12, abs=1e-12)
    # energy is exchanged and (Rayleigh damping, beta = 1e-4) slowly taken away, not created:
    # the total stays at most its first value and loses a few % of the swing in 1 s
    # (measured 4.6 %; without the damping Newmark kept it within 5e-3 of the swing)
    swing = max(abs(r["gravity"]) for r in rows)
    totals = [r["total_energy"] for r in rows]
    assert max(totals) <= totals[0] + 1e-9 * swing
    assert 1e-2 * swing < -totals[-1] < 1e-1 * swing


def test_default_scene_beam_sags(default_run):
    final = meshio.read(default_run / "final.vtu")
    u = final.point_data["displacement"]
    x = final.points
    tip = np.isclose(x[:, 0], 1.0)
    root = np.isclose(x[:, 0], 0.0)
    assert tip.sum() > 0 and root.sum() > 0
    assert np.all(u[tip, 2] < -0.05)  # tip z decreased
    assert np.abs(u[root]).max() == 0.0  # pinned wall stays put


def test_final_vtu_matches_last_xdmf_frame(default_run):
    with meshio.xdmf.TimeSeriesReader(str(default_run / "trajectory.xdmf")) as reader:
        points, cells = reader.read_points_cells()
        frames = [reader.read_data(k) for k in range(reader.num_steps)]
    assert len(frames) == 61  # the rest state and 60 steps
    t, point_data, _ = frames[-1]
    assert t == pytest.approx(1.0)
    final = meshio.read(default_run / "final.vtu")
    np.testing.assert_array_equal(final.points, points)
    np.testing.assert_array_equal(point_data["displacement"], final.point_data["displacement"])
    t0, data0, _ = frames[0]
    assert t0 == 0.0 and np.abs(data0["displacement"]).max() == 0.0


def test_final_png_is_an_image(default_run):
    png = (default_run / "final.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_default_scene_file_in_demos_is_the_embedded_one():
    demo = load_scene(ROOT / "demos" / "hanging_beam.toml")
    assert demo.data == load_scene().data
    assert tomllib.loads(default_scene_text())["name"] == "hanging_beam"


def test_petsc_options_reach_the_solver(tmp_path):
    direct, cg = tmp_path / "direct", tmp_path / "cg"
    assert main(["run", "-o", str(direct), "-q", "--set", "time.steps=3"]) == 0
    assert main(["run", "-o", str(cg), "-q", "--set", "time.steps=3",
                 "-ksp_type", "cg", "-pc_type", "icc", "-ksp_rtol", "1e-10"]) == 0
    rows_direct, rows_cg = read_stats(direct / "stats.csv"), read_stats(cg / "stats.csv")
    # a direct solve is one "iteration" per Newton direction (one more when the last
    # direction's line search stopped at round-off); CG/ICC needs many
    assert all(r["newton_its"] <= r["linear_its"] <= r["newton_its"] + 1 for r in rows_direct)
    assert all(r["linear_its"] > 5 * r["newton_its"] for r in rows_cg)
    for a, b in zip(rows_direct, rows_cg):  # same steps (the total is a small difference)
        for key in ("kinetic", "elastic", "gravity"):
            assert b[key] == pytest.approx(a[key], rel=1e-6), key


def test_scene_petsc_table_and_command_line_precedence(tmp_path):
    scene = tmp_path / "scene.toml"
    scene.write_text(default_scene_text().replace(
        'mode = "exact"', 'mode = "exact"\n[solver.petsc]\nsnes_max_it = 1'))
    # the scene's snes_max_it = 1 cannot converge a Newton step from the predictor ...
    r = run_cli(["run", str(scene), "-o", str(tmp_path / "a"), "-q",
                 "--set", "time.steps=2", "--set", "time.adaptive=false"], tmp_path)
    assert r.returncode == 2 and "did not converge after 1 Newton" in r.stderr
    # ... and the command line wins over the scene file
    r = run_cli(["run", str(scene), "-o", str(tmp_path / "b"), "-q", "--set", "time.steps=2",
                 "--set", "time.adaptive=false", "-snes_max_it", "20"], tmp_path)
    assert r.returncode == 0, r.stderr


def test_set_overrides(tmp_path):
    out = tmp_path / "o"
    assert main(["run", "-o", str(out), "-q", "--set", "time.steps=2",
                 "--set", "material.youngs_modulus=2e5", "--set", "material.model=stvk"]) == 0
    assert len(read_stats(out / "stats.csv")) == 2


def test_solvers_lists_presets(capsys):
    assert main(["solvers"]) == 0
    text = capsys.readouterr().out
    assert "cholesky" in text and "-pc_type cholesky" in text


BAD_INPUT = [
    (["--set", "material.youngs_modulus=-1"], "material.youngs_modulus must be > 0, got -1"),
    (["--set", "material.youngs_modulus=0"], "material.youngs_modulus must be > 0, got 0"),
    (["--set", "material.poisson_ratio=0.5"], "material.poisson_ratio must be in (-1.0, 0.5)"),
    (["--set", "material.poisson_ratio=-1.2"], "material.poisson_ratio must be in"),
    (["--set", "material.density=0"], "material.density must be > 0"),
    (["--set", "time.dt=0"], "time.dt must be > 0, got 0"),
    (["--set", "time.dt=-0.1"], "time.dt must be > 0, got -0.1"),
    (["--set", "time.steps=0"], "time.steps must be >= 1, got 0"),
    (["--set", "time.steps=2.5"], "time.steps must be an integer, got 2.5"),
    (["--set", "time.dt=nan"], "time.dt must be finite, got nan"),
    (["--set", "time.dt=inf"], "time.dt must be finite, got inf"),
    (["--set", "material.density=1e308"], "material.density must be at most"),
    (["--set", 'material.model="rubber"'], "material.model must be one of"),
    (["--set", "material.colour=1"], "unknown key material.colour"),
    (["--set", "breeze.speed=3"], "unknown section or key 'breeze'"),
    (["--set", 'time.dt="fast"'], "time.dt must be a number, got 'fast'"),
    (["--set", "mesh.size=[1, 0.2]"], "mesh.size must have 3 entries"),
    (["--set", "pin.0.min=[2, 0, 0]"], "pin[0] (wall) is an empty box"),
    (["--set", "gravity.acceleration=[0, -9.81]"], "gravity.acceleration must have 3 entries"),
    (["--set", "element.degree=3"], "element.degree must be one of 1, 2"),
    (["--set", "element.degree=2", "--set", 'material.mass="lumped"'],
     'material.mass = "lumped" is not supported with element.degree = 2'),
    (["--set", "time.steps"], "--set expects KEY=VALUE"),
    (["--set", "time.steps=[1"], "is not valid TOML"),
    (["--solver", "gauss"], "--solver: unknown solver preset 'gauss'"),
    (["--set", 'solver.preset="gauss"'], "solver.preset: unknown solver preset 'gauss'"),
    (["--set", "pin.0.min=[0.5, 0.5, 0.5]", "--set", "pin.0.max=[0.6, 0.6, 0.6]"],
     "contains no mesh vertex"),
    (["no_such_scene.toml"], "scene file no_such_scene.toml does not exist"),
    (["--frobnicate"], "unrecognized arguments: --frobnicate"),
]


@pytest.mark.parametrize("args, message", BAD_INPUT, ids=[m[:40] for _, m in BAD_INPUT])
def test_bad_input_exits_2_with_one_message(tmp_path, args, message):
    out = tmp_path / "out"
    r = run_cli(["run", "-o", str(out), "-q"] + args, tmp_path)
    assert r.returncode == 2, r.stderr
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("fem-anim: error: ") and message in lines[0], lines[0]
    assert "Traceback" not in r.stderr
    assert not out.exists()


def test_malformed_scene_file(tmp_path):
    scene = tmp_path / "broken.toml"
    scene.write_text("[material\nmodel = 'stvk'\n")
    r = run_cli(["run", str(scene), "-o", str(tmp_path / "out")], tmp_path)
    assert r.returncode == 2
    assert "broken.toml is not valid TOML" in r.stderr and "Traceback" not in r.stderr


def test_log_view_reaches_petsc(tmp_path):
    r = run_cli(["run", "-q", "--set", "time.steps=1", "-o", str(tmp_path / "o"), "-log_view"],
                tmp_path)
    assert r.returncode == 0, r.stderr
    assert "PETSc Performance Summary" in r.stdout and "SNESSolve" in r.stdout


def test_second_run_compiles_nothing(tmp_path):
    """Compiled forms are cached: running the same scene again adds no JIT module."""
    env = clean_environment() | {"XDG_CACHE_HOME": str(tmp_path / "cache")}
    args = fem_anim_command() + ["run", "-q", "--set", "time.steps=1", "--set",
                                 "output.render=false", "--set", "mesh.element_size=0.1"]

    def compiled() -> set[str]:
        return {p.name for p in (tmp_path / "cache").rglob("*.so")}

    for run in ("first", "second"):
        r = subprocess.run(args + ["-o", str(tmp_path / run)], cwd=tmp_path, env=env,
                           capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr
        if run == "first":
            first = compiled()
            assert len(first) >= 1  # 0.5: forms, expressions, elements; 0.9: no elements
    assert compiled() == first


def test_2d_beam_survives_an_inverting_predictor(tmp_path):
    """2D neo-Hookean beam: at step 56 the Newmark predictor inverts elements (g = NaN).

    Newton then starts from the last state instead, and the run completes with finite
    energies (before that fallback it stopped with DIVERGED_FNORM_NAN at step 56).
    """
    out = tmp_path / "plate"
    assert main(["run", "-o", str(out), "-q", "--set", "mesh.dim=2",
                 "--set", "mesh.size=[1.0, 0.2]", "--set", "gravity.acceleration=[0, -9.81]",
                 "--set", "pin.0.min=[-0.001, -1]", "--set", "pin.0.max=[0.001, 1]",
                 "--set", "output.render=false"]) == 0
    rows = read_stats(out / "stats.csv")
    assert all(math.isfinite(r["total_energy"]) for r in rows)
    # every frame reached (on gmsh 4.13's mesh some steps are substepped: more rows than 60)
    ticks = [r["time"] * 60 for r in rows]
    frames = {round(t) for t in ticks if abs(t - round(t)) < 1e-9}
    assert frames == set(range(1, 61)) and rows[-1]["time"] == pytest.approx(1.0)
    final = meshio.read(out / "final.vtu")
    assert list(final.cells_dict) == ["triangle"]
    assert final.point_data["displacement"][:, 1].min() < -0.5


def test_summary_records_provenance(default_run):
    """summary.json names the stack, the merged PETSc options and the wall time split, so
    two runs (say on Debian 12 and 13) are compared by reading two files."""
    import json

    import dolfinx
    import ffcx
    import gmsh
    import ufl
    from petsc4py import PETSc

    from fem_anim.simulation.loop import solver_options

    summary = json.loads((default_run / "summary.json").read_text())
    versions = summary["versions"]
    assert versions["dolfinx"] == dolfinx.__version__
    assert versions["ufl"] == ufl.__version__ and versions["ffcx"] == ffcx.__version__
    assert versions["petsc"] == ".".join(map(str, PETSc.Sys.getVersion()))
    assert versions["gmsh"] == gmsh.__version__ and versions["mpi_ranks"] == 1
    assert versions["mumps"] and versions["mumps"][0].isdigit()  # the default preset is MUMPS
    assert versions["mpi"] and versions["python"].count(".") == 2
    commit = versions["fem_anim_commit"]
    assert commit is None or len(commit.split("+")[0]) == 40
    assert summary["petsc_options"] == solver_options(load_scene(None, []))
    wall = summary["wall"]
    phases = ("compile_s", "mesh_s", "setup_s", "stepping_s", "output_s", "render_s")
    assert all(wall[p] >= 0.0 for p in phases)
    assert wall["total_s"] == pytest.approx(sum(wall[p] for p in phases), abs=1e-5)
    rows = read_stats(default_run / "stats.csv")
    assert wall["stepping_s"] == pytest.approx(sum(r["step_wall_s"] for r in rows), rel=1e-6)
    assert wall["mesh_s"] > 0.0 and wall["render_s"] > 0.0  # the default scene renders


def test_a_bench_commands_errors_are_one_line_and_exit_2(capsys):
    """``console.exit_status``, the benches' error tail: a user's error and an OS error are
    one ``fem-anim: error:`` line and exit 2 (the OS error names the target when it names no
    file itself), a finished body's status is passed through."""
    import errno

    from fem_anim.console import exit_status
    from fem_anim.errors import FemAnimError

    def fails(err):
        def body():
            raise err
        return body

    assert exit_status(lambda: 0, lambda: "unused") == 0
    assert exit_status(fails(FemAnimError("--steps: must be between 2 and 1000")),
                       lambda: "out") == 2
    assert capsys.readouterr().err == \
        "fem-anim: error: --steps: must be between 2 and 1000\n"
    assert exit_status(fails(OSError(errno.ENOSPC, "No space left on device")),
                       lambda: "results/peers") == 2
    assert capsys.readouterr().err == \
        "fem-anim: error: results/peers: No space left on device\n"
    with pytest.raises(ZeroDivisionError):  # a bug is not the user's error: it propagates
        exit_status(fails(ZeroDivisionError()), lambda: "out")
