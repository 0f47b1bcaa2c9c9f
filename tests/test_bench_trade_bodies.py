"""The trade study on a multi-body contact scene: the project's own pile of four bodies.

Reduced: two steps of 20 ms against steps of 10 ms, the reference at 2.5 ms. The scene has
``[contact]``, whose P2 surface is the P1 one refined, so the reference keeps the scene's degree (a finer
step and a tight Newton tolerance) instead of the P2 it takes elsewhere; the bodies' regions
are their own (the mesh is the union of the ``[[body]]`` meshes).
"""

import csv
from pathlib import Path

import pytest

from fem_anim.bench import trade
from fem_anim.bench.sweep import expand_study

PILE = Path(__file__).resolve().parents[1] / "demos" / "pile.toml"
REDUCED = ["time.dt=0.02", "time.steps=2"]


def test_reference_of_a_contact_scene_is_one_the_scene_allows():
    study = expand_study(str(PILE), REDUCED, ["time.dt=0.02,0.01"], [])
    assert "element.degree=2" not in study.reference.overrides
    assert study.reference.scene["element"]["degree"] == 1
    assert study.reference.scene["time"]["dt"] == pytest.approx(0.0025)
    assert [c.scene is not None for c in study.configurations] == [True, True]


def test_trade_study_runs_on_the_pile(tmp_path, capsys):
    out = tmp_path / "trade"
    argv = [str(PILE), *(f"--set={o}" for o in REDUCED), "--sweep", "time.dt=0.02,0.01",
            "--repeats", "1", "-q", "-o", str(out)]
    assert trade.main(argv) == 0, capsys.readouterr().err
    with open(out / "trade_study.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["status"] for r in rows] == ["ok", "ok"]
    errors = [float(r["error_l2"]) for r in rows]
    assert 0.0 < errors[1] < errors[0], errors  # a smaller step is closer to the reference
    text = (out / "trade_study.md").read_text()
    assert "time.dt=0.0025" in text and "element.degree" not in text
