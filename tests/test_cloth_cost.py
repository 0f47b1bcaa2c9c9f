"""The cloth cost bench (:mod:`fem_anim.bench.cloth_cost`) on a tiny sheet: its table is its
JSON, its split adds up to the step, the one-step rows take one Newton step and differ from
the exact run, and bad arguments are one line with exit code 2."""

from __future__ import annotations

import json

import pytest


def test_cloth_cost_table_adds_up(tmp_path, capsys):
    """225 vertices, 5 steps (the sheet reaches the ball): each row's time per step is
    assembly + factor and solve + the rest (stats.csv's split of the step's wall time); the
    exact cloth iterates Newton, the
    one-step run takes exactly one step per step and ends away from the exact run (a
    positive error), and the markdown table shows the JSON's numbers."""
    from fem_anim.bench.cloth_cost import CASES, main

    assert main(["--vertices", "225", "--steps", "5", "--out", str(tmp_path)]) == 0
    rows = json.loads((tmp_path / "cloth_cost.json").read_text())
    table = (tmp_path / "cloth_cost.md").read_text()
    assert [r["case"] for r in rows] == list(CASES)
    for r in rows:
        assert r["step_s"] == pytest.approx(r["assembly_s"] + r["solve_s"] + r["other_s"],
                                            rel=1e-9)
        assert r["steps"] == 5 and r["substeps"] >= 5
        assert f"| {r['case']} | {r['vertices']} | {r['cells']} | {r['step_s']:.3f} |" in table
    exact, one, solid = rows
    assert exact["vertices"] == one["vertices"] == 225 and abs(solid["vertices"] - 225) < 120
    assert exact["newton_its_max"] > 1 and one["newton_its_max"] == 1
    assert one["error"] > 1e-6 and f"{one['error']:.2e}" in table
    forms = exact["forms"]
    assert min(forms.values()) > 0 and f"| {forms['bending_s']:.4f} |" in table


def test_cloth_cost_bad_arguments_are_one_line(tmp_path, capsys):
    from fem_anim.bench.cloth_cost import main

    assert main(["--vertices", "ten", "--out", str(tmp_path)]) == 2
    assert main(["--vertices", "50", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all(line.startswith("fem-anim: error:") for line in err), err


def test_cloth_cost_refuses_a_users_file_before_measuring(tmp_path, capsys, monkeypatch):
    """A cloth_cost.md that fem_anim did not write is refused (one line, exit 2) before any
    run starts, and left as it was."""
    from fem_anim.bench import cloth_cost

    def never(*args, **kwargs):
        raise AssertionError("measured before checking the output folder")

    monkeypatch.setattr(cloth_cost, "cost_table", never)
    (tmp_path / "cloth_cost.md").write_text("the user's own")
    assert cloth_cost.main(["--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "was not written by fem-anim" in err[0], err
    assert (tmp_path / "cloth_cost.md").read_text() == "the user's own"
