"""Stability at the extremes (issue 6): expected against measured outcome, as a table.

CI tier: the fast variants (2D, element size 0.1, a few steps) of every case of
:func:`fem_anim.bench.extremes.cases` and the P1/P2 locking study; the full 3D grid is
``-m slow``. The table of each tier is printed at the end of the module (pytest's
terminal reporter) and is what ``fem-anim bench --extremes [--full]`` prints.
"""

import pytest

from fem_anim.bench.extremes import cases, format_table, locking_rows, run_case

FAST = cases(full=False)
FULL = cases(full=True)


@pytest.fixture(scope="module")
def table(request):
    rows = {"fast": [], "full": [], "locking": []}
    yield rows
    capture = request.config.pluginmanager.getplugin("capturemanager")
    for tier in ("fast", "full"):
        if rows[tier]:
            locking = rows["locking"] if tier == "fast" else []
            with capture.global_and_fixture_disabled():
                print("\n" + format_table(rows[tier], locking, tier == "full"))


def _check(case, table, tier):
    outcome = run_case(case)
    table[tier].append((case, outcome))
    assert outcome.measured == case.expected, outcome.detail
    if outcome.measured == "stops-with-message":
        assert "reduce time.dt" in outcome.detail or "min_dt" in outcome.detail, outcome.detail
    else:
        assert outcome.info["newton_its"] >= case.steps
    if case.name.startswith("thin"):
        assert outcome.info["aspect"] >= 50


@pytest.mark.parametrize("case", FAST, ids=[c.name for c in FAST])
def test_extreme_fast(case, table):
    _check(case, table, "fast")


def test_p1_locks_near_incompressibility_p2_does_not(table):
    rows = {(r["nu"], r["element"]): r for r in locking_rows(full=False)}
    table["locking"] += list(rows.values())
    # at nu = 0.3 both are within 30 % of the fine P2 deflection (P1 is stiffer: coarse)
    assert rows[0.3, "P1"]["ratio"] > 0.6 and rows[0.3, "P2"]["ratio"] > 0.95
    # at nu = 0.4999 P1 locks: it deflects less than half as much as it should
    assert rows[0.4999, "P1"]["ratio"] < 0.5 * rows[0.3, "P1"]["ratio"]
    assert rows[0.4999, "P2"]["ratio"] > 0.9
    # the fine P2 solution agrees with beam theory (plane strain) within 5 %
    for nu in (0.3, 0.4999):
        r = rows[nu, "P2"]
        assert abs(r["reference"] / r["beam_theory"] - 1) < 0.05


@pytest.mark.slow
@pytest.mark.parametrize("case", FULL, ids=[c.name for c in FULL])
def test_extreme_full(case, table):
    _check(case, table, "full")
