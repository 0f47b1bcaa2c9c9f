"""``python -m fem_anim.bench.contact_cost --baseline``: the pile against the plain IPC step.

A reduced run (coarse boxes, 2 steps, seconds): every number of the printed table is
recomputed from the CSVs it wrote (fem_anim's s/step with its discarded tries, both runs'
Newton iterations per step, the ratio, the centre-of-mass check); no step's ipctk time
exceeds its wall time (the set-up's is no step's); the baseline starts from the scene's
initial velocities, so both runs' bodies stay within
:data:`~fem_anim.bench.contact_set.COM_TOLERANCE`; a try fem_anim discards is in the
step's wall time and in its ``retries`` and ``retry_s``; ``--baseline`` with ``--ranks``
is one error line and exit 2.
"""

from __future__ import annotations

import csv
import re
import time

import pytest
from mpi4py import MPI

from fem_anim.bench import contact_cost as cc
from fem_anim.bench.ipc_baseline import MAX_NEWTON
from fem_anim.bench.contact_set import COM_TOLERANCE

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial bench")

H, STEPS = 0.05, 2


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """The reduced bench, with fem_anim's first try of step 2 failing after real work."""
    from fem_anim.errors import ConvergenceError
    from fem_anim.simulation.loop import Simulation

    out = tmp_path_factory.mktemp("contact_cost")
    original = Simulation.timed_step
    calls = []  # each try's own wall time (s)
    ipc_at_start = []  # ipctk's time already on its clock as each try starts (s)

    def failing_once(self, state, dt):
        start = time.perf_counter()
        ipc_at_start.append(sum(self.problem.ipc.timers.values()))
        try:
            if len(calls) == 1:  # step 2's first try: a whole step's work, then discarded
                original(self, state, dt)
                time.sleep(0.05)
                raise ConvergenceError("planted failure")
            return original(self, state, dt)
        finally:
            calls.append(time.perf_counter() - start)

    Simulation.timed_step = failing_once
    try:
        code = cc.main(["--element-size", str(H), "--steps", str(STEPS), "--baseline",
                        "--out", str(out)])
    finally:
        Simulation.timed_step = original
    assert code == 0
    assert ipc_at_start[0] == 0.0  # the set-up's ipctk time is not step 1's
    return out, (out / "contact_bench.md").read_text(), calls


def test_printed_numbers_recompute_from_the_csvs(bench):
    out, table, _ = bench
    fa, bl = _rows(out / "contact_bench.csv"), _rows(out / "contact_bench_baseline.csv")
    assert len(fa) == len(bl) == STEPS
    fa_s = sum(float(r["wall_s"]) for r in fa) / STEPS
    bl_s = sum(float(r["wall_s"]) for r in bl) / STEPS
    fa_its = sum(int(r["newton_its"]) for r in fa) / STEPS
    bl_its = sum(int(r["newton_its"]) for r in bl) / STEPS
    fa_cpu = sum(float(r["cpu_s"]) for r in fa) / STEPS
    bl_cpu = sum(float(r["cpu_s"]) for r in bl) / STEPS
    assert f"| fem_anim | {fa_s:.3f} | {fa_cpu:.3f} | {fa_its:.1f} |" in table
    assert f"| ipctk + scipy baseline | {bl_s:.3f} | {bl_cpu:.3f} | {bl_its:.1f} |" in table
    assert f"to the baseline's: {fa_s / bl_s:.2f} (" in table
    assert f"by CPU time {fa_cpu / bl_cpu:.2f});" in table
    assert all(float(r["cpu_s"]) > 0.0 for r in fa + bl)
    unconverged = sum(1 - int(r["converged"]) for r in bl)
    assert f"in {MAX_NEWTON} iterations: {unconverged};" in table
    heights = _rows(out / "contact_bench_com_heights.csv")
    assert len(heights) == (STEPS + 1) * 4
    diff = max(abs(float(r["fem_anim_m"]) - float(r["baseline_m"])) for r in heights)
    assert f"between the runs: {1e3 * diff:.2f} mm" in table
    # the per-step part of the table: wall and ipctk split from the same CSV
    assert re.search(rf"\| wall_s \| {fa_s:.3f} \| 100 % \|", table)
    for r in fa:
        timers = [float(r[k]) for k in ("detection_s", "barrier_s", "ccd_s")]
        assert float(r["contact_s"]) >= sum(timers) - 1e-12
        assert 0.0 < float(r["contact_s"]) <= float(r["wall_s"])


def test_baseline_follows_the_same_bodies(bench):
    out, _, _ = bench
    heights = _rows(out / "contact_bench_com_heights.csv")
    start = [r for r in heights if r["step"] == "0"]
    assert all(float(r["fem_anim_m"]) == float(r["baseline_m"]) for r in start)
    # the thrown boxes fall at 0.5 m/s: from rest, the baseline would lag ~5 mm a step
    for r in heights:
        assert abs(float(r["fem_anim_m"]) - float(r["baseline_m"])) < COM_TOLERANCE, r


def test_discarded_try_is_in_the_wall_time(bench):
    out, table, calls = bench
    fa = _rows(out / "contact_bench.csv")
    assert [int(r["retries"]) for r in fa] == [0, 1]
    assert len(calls) == 4  # step 1; step 2: the discarded try, then two half steps
    assert float(fa[0]["retry_s"]) == 0.0
    assert calls[1] <= float(fa[1]["retry_s"]) < float(fa[1]["wall_s"])
    assert float(fa[1]["wall_s"]) >= sum(calls[1:])
    retry = sum(float(r["retry_s"]) for r in fa)
    assert f"({retry:.1f}) |" in table


def test_baseline_refuses_ranks(tmp_path, capsys):
    code = cc.main(["--baseline", "--ranks", "2", "--out", str(tmp_path)])
    assert code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--baseline runs serially" in err[0], err
    assert not any(tmp_path.iterdir())
