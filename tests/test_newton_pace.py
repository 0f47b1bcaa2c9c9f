"""Contact at animation pace, what a step records about its contact: the smallest distance
of ``stats.csv`` is a distance (m), measured here against the geometry of the pairs."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from test_contact_pace import STACK

from fem_anim.scene.loading import Scene
from fem_anim.simulation.loop import Simulation


def _point_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    t = np.clip((p - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
    return float(np.linalg.norm(p - a - t * (b - a)))


def _segment_segment(a, b, c, d) -> float:
    best = min(_point_segment(a, c, d), _point_segment(b, c, d), _point_segment(c, a, b),
               _point_segment(d, a, b))
    u, v, w = b - a, d - c, a - c
    A, B, C, D, E = u @ u, u @ v, v @ v, u @ w, v @ w
    den = A * C - B * B
    if den > 1e-12 * A * C:  # not parallel: the interior closest points, if inside
        s, t = (B * E - C * D) / den, (A * E - B * D) / den
        if 0.0 <= s <= 1.0 and 0.0 <= t <= 1.0:
            best = min(best, float(np.linalg.norm(w + s * u - t * v)))
    return best


def _point_triangle(p, a, b, c) -> float:
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n)
    q = p - ((p - a) @ n) * n
    inside = all(np.cross(e1 - e0, q - e0) @ n >= 0.0 for e0, e1 in ((a, b), (b, c), (c, a)))
    if inside:
        return float(abs((p - a) @ n))
    return min(_point_segment(p, a, b), _point_segment(p, b, c), _point_segment(p, c, a))


def _pair_distance(kind: str, p: np.ndarray) -> float:
    """The distance of one ipctk pair from its vertices by plain geometry (no ipctk)."""
    if kind.startswith("FaceVertex"):  # vertex p[0], triangle p[1:4]
        return _point_triangle(*p)
    if kind.startswith("EdgeEdge"):  # edges p[0]p[1], p[2]p[3]
        return _segment_segment(*p)
    if kind.startswith("EdgeVertex"):  # vertex p[0], edge p[1]p[2]
        return _point_segment(*p)
    return float(np.linalg.norm(p[0] - p[1]))  # VertexVertex


def test_min_distance_is_the_smallest_pair_distance_in_metres():
    """The upper cube lands on the lower one: ``step_stats()["min_distance"]`` (stats.csv's
    column) equals the smallest distance of the pairs computed from their vertices, not its
    square (ipctk's ``compute_minimum_distance`` returns d^2)."""
    sim = Simulation(Scene.from_toml(STACK.format(steps=8)))
    state = sim.initial_state()
    for _ in range(8):
        state, _ = sim.step(state, 0.01)
    ipc = sim.problem.ipc
    recorded = ipc.step_stats()["min_distance"]
    x = ipc._update()
    distances = []
    for c in ipc.collisions:
        ids = [v for v in c.vertex_ids(ipc.mesh.edges, ipc.mesh.faces) if v >= 0]
        distances.append(_pair_distance(type(c).__name__, x[ids]))
    assert ipc.num_pairs > 0
    assert 0.0 < recorded < ipc.dhat
    assert abs(recorded - min(distances)) <= 1e-9 * recorded, (recorded, min(distances))
    sim.minimiser.destroy()


def test_landing_stack_keeps_newton_iterations_low_with_the_predictor_start():
    """Two coarse cubes, the lower one landing on the ground, the upper one on it (16 steps,
    implicit Euler, friction): Newton starts from the predictor x_n + h v_n cut by the CCD
    (the previous step's velocity), and the barrier's exact Hessian takes over once a full
    step is below 100x the stopping test's size, so the landings take at most 10 iterations
    a step and at most 3.5 on average (7 and 3.31 measured), and the stack, at rest from
    step 11, 2 a step. Started from x_n the upper cube's landing takes 11; with the exact
    Hessian only at the test's size (before) steps 11-14 take 3. Each step still meets IPC's
    step test with its force check (reason 5)."""
    sim = Simulation(Scene.from_toml(STACK.format(steps=16)))
    state = sim.initial_state()
    its = []
    for _ in range(16):
        state, stats = sim.step(state, 0.01)
        its.append(stats.newton_its)
        assert stats.reason == 5
    sim.minimiser.destroy()
    assert max(its) <= 10 and sum(its) / len(its) <= 3.5, its
    assert max(its[10:]) <= 2, its


def test_auto_reads_the_inertia_of_every_factorisation_after_new_pairs(tmp_path):
    """``solver.hessian = "auto"`` on the landing stack: contact pairs add nonzeros to the
    Hessian, so PCSetUp replaces MUMPS's factor (and the controls set on it) during the run;
    every step's Hessians still have their inertia read off their factorisation
    (``inertia_checks`` in stats.csv: at least one a step, over more than 10
    factorisations), none falls back to the CG probe (``inertia_fallbacks``). Before, the
    inertia was read by MatGetInertia, which needs ICNTL(24) = 1 on the factor: it failed
    once the factor was replaced, and auto lost its check for the rest of the run without a
    trace."""
    from test_contact_pace import run

    rows, _, _ = run(tmp_path, STACK.format(steps=12), 'solver.hessian="auto"')
    checks = [int(r["inertia_checks"]) for r in rows]
    fallbacks = [int(r["inertia_fallbacks"]) for r in rows]
    assert sum(int(r["factorisations"]) for r in rows) > 10
    assert int(rows[-1]["contact_pairs"]) > 0
    assert min(checks) >= 1 and not any(fallbacks), (checks, fallbacks)


@pytest.mark.mpi
def test_auto_reads_the_inertia_on_two_ranks(tmp_path):
    """The same under ``mpirun -n 2``: MUMPS counts the negative pivots of the whole matrix
    only with ICNTL(13) = 1, which must reach every replaced factor too (it is kept in
    PETSc's database while solving), so no factorisation falls back to the CG probe."""
    import subprocess

    from conftest import clean_environment, fem_anim_command, mpirun_command

    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    scene = tmp_path / "stack.toml"
    scene.write_text(STACK.format(steps=8))
    out = tmp_path / "out"
    r = subprocess.run(mpirun + fem_anim_command() + [
        "run", "-q", str(scene), "-o", str(out), "--set", 'solver.hessian="auto"',
        "--set", "output.render=false"], capture_output=True, text=True, timeout=600,
        env=clean_environment())
    assert r.returncode == 0, r.stderr
    rows = list(csv.DictReader(open(out / "stats.csv")))
    checks = [int(row["inertia_checks"]) for row in rows]
    fallbacks = [int(row["inertia_fallbacks"]) for row in rows]
    assert sum(int(row["factorisations"]) for row in rows) > 10
    assert min(checks) >= 1 and not any(fallbacks), (checks, fallbacks)
