"""Energy behaviour per run: ``fem-anim run`` reports the drift and flags numerical damping.

A 2D beam released from rest swings under gravity with no damping, so the total energy is
conserved in continuous time: Newmark keeps it (drift well under 1 % of the swing energy),
implicit Euler with a large step damps the swing away, and the run says so.
"""

import contextlib
import io
import json

import pytest

from fem_anim.cli import main as cli_main

SWING = """
name = "swing"
[mesh]
dim = 2
size = [1.0, 0.1]
element_size = 0.1
[material]
youngs_modulus = 1.0e5
[time]
dt = 0.05
steps = 20
[gravity]
acceleration = [0.0, -9.81]
[[pin]]
min = [-1e-6, -1.0]
max = [1e-6, 1.0]
[output]
render = false
"""


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("energy")
    scene = tmp / "swing.toml"
    scene.write_text(SWING)
    out = {}
    for integrator in ("newmark", "implicit_euler"):
        printed = io.StringIO()
        with contextlib.redirect_stdout(printed):  # --quiet: only a damping warning prints
            code = cli_main(["run", str(scene), "-o", str(tmp / integrator), "--quiet",
                             "--set", f"time.integrator={integrator}"])
        assert code == 0
        out[integrator] = json.loads((tmp / integrator / "summary.json").read_text())
        out[integrator]["printed"] = printed.getvalue()
    return out


def test_newmark_keeps_the_energy(runs):
    e = runs["newmark"]["energy"]
    assert e["conservative"] and not e["damped"]
    assert abs(e["drift"]) < 0.01 and e["exchanged_energy"] > 0.1


def test_implicit_euler_reports_numerical_damping(runs):
    e = runs["implicit_euler"]["energy"]
    assert e["conservative"] and e["damped"]
    assert e["drift"] < -0.3  # a third of the swing energy and more is gone
    # the exchanged energy is the same swing in both runs (to the first drop of potential)
    assert e["exchanged_energy"] > 0.3 * runs["newmark"]["energy"]["exchanged_energy"]


def test_damped_run_prints_a_warning_even_when_quiet(runs):
    assert "numerical damping: implicit_euler" in runs["implicit_euler"]["printed"]
    assert "damped away" in runs["implicit_euler"]["printed"]
    assert runs["newmark"]["printed"] == ""


def test_damped_scene_is_not_flagged(tmp_path):
    scene = tmp_path / "swing.toml"
    scene.write_text(SWING + "[damping]\nalpha = 5.0\n")
    assert cli_main(["run", str(scene), "-o", str(tmp_path / "o"), "--quiet",
                     "--set", "time.steps=6"]) == 0
    e = json.loads((tmp_path / "o" / "summary.json").read_text())["energy"]
    assert not e["conservative"] and not e["damped"] and e["drift"] < 0
