"""The contact benchmark set and its plain ipctk + scipy IPC baseline.

* the baseline's objective, gradient and Hessian agree (central differences along random
  directions, with the barrier, the obstacle and both frictions active), and its Hessian is
  positive semidefinite (IPC's projections);
* the reduced set (``fem-anim bench --contact --size reduced``, few frames): every number of
  its table is recomputed from the CSVs and frames it wrote, no frame of either run crosses,
  and the baseline follows fem_anim's physics (centre-of-mass heights within
  :data:`~fem_anim.bench.contact_set.COM_TOLERANCE`).

The full set (:func:`test_full_set`) is slow.
"""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest
from mpi4py import MPI

from fem_anim.bench import contact_set as cs

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial bench")


def _staged_baseline(tmp_path):
    """The reduced stack with contact active: box 0 0.5 mm above the ground, box 1 0.5 mm
    above box 0, friction lagged at that state and the boxes then nudged sideways."""
    from fem_anim.mesh.bodies import build_scene_mesh
    from fem_anim.scene.loading import load_scene

    path = tmp_path / "stack.toml"
    path.write_text(cs.scene_text("stack", "reduced"))
    scene = load_scene(path)
    domain = build_scene_mesh(MPI.COMM_SELF, scene)
    sim = cs._baseline(scene, domain)
    body = np.zeros(domain.points.shape[0], int)
    body[domain.cells.ravel()] = np.repeat(domain.cell_markers - 1, 4)
    x = sim.X.copy()
    x[body == 0, 2] -= 1.5e-3
    x[body >= 1, 2] -= 3.0e-3
    sim.x = x.ravel()
    sim.v = np.random.default_rng(0).normal(scale=0.05, size=sim.ndof)
    sim._stage(0.01)
    assert len(sim.collisions) > 0 and sim.friction is not None and sim.kappa > 0
    rng = np.random.default_rng(1)
    nudge = np.zeros_like(x)
    nudge[:, :2] = rng.normal(scale=2e-4, size=(x.shape[0], 2))
    return sim, (x + nudge).ravel()


def test_baseline_gradient_and_hessian(tmp_path):
    """Taylor test: |g(x + e d) - g(x) - e grad.d| falls as e^2 (order 2) along random d."""
    sim, x = _staged_baseline(tmp_path)
    grad, H = sim.gradient_hessian(x)
    rng = np.random.default_rng(2)
    f0 = sim.objective(x)
    for _ in range(2):
        d = rng.normal(size=x.size)
        d /= np.abs(d).max()
        steps = 2e-5 * 0.5 ** np.arange(4)
        remainder = [abs(sim.objective(x + e * d) - f0 - e * (grad @ d)) for e in steps]
        orders = np.log2(np.array(remainder[:-1]) / remainder[1:])
        assert np.all(orders > 1.8), orders
    # IPC's projections make the Hessian positive semidefinite on the free dofs
    free = sim.free
    lam = np.linalg.eigvalsh(H[free][:, free].toarray())
    assert lam.min() >= -1e-8 * lam.max()


@pytest.fixture(scope="module")
def reduced_set(tmp_path_factory):
    out = tmp_path_factory.mktemp("contact_set")
    code = cs.main(["--size", "reduced", "--steps", "3", "--no-pictures", "--out", str(out)])
    assert code == 0
    return out, json.loads((out / "contact_set.json").read_text())


def _rows(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def test_reduced_set_numbers_recompute(reduced_set):
    from fem_anim.contact.intersection import crossed_frames

    out, summary = reduced_set
    assert [e["scene"] for e in summary["scenes"]] == list(cs.SCENES)
    table = (out / "contact_set.md").read_text()
    for e in summary["scenes"]:
        frames = e["frames"]
        data = np.load(out / f"{e['scene']}_frames.npz")
        points, cells, body = data["points"], data["cells"], data["body"]
        assert e["tets"] == cells.shape[0]
        for who in ("fem_anim", "baseline"):
            rows = _rows(out / f"{e['scene']}_{who}.csv")
            wall = sum(float(r["wall_s"]) for r in rows)
            own = sum(float(r["step_wall_s"]) for r in rows)
            got = e[who]
            assert got["s_per_step"] == pytest.approx(wall / frames, rel=1e-12)
            assert got["newton_per_step"] == pytest.approx(
                sum(int(r["newton_its"]) for r in rows) / frames, rel=1e-12)
            assert got["ipc_share"] == pytest.approx(
                sum(float(r["ipc_s"]) for r in rows) / wall, rel=1e-12)
            assert got["retries"] == sum(int(r["retries"]) for r in rows)
            assert got["retry_s"] == pytest.approx(wall - own, abs=1e-12)
            # each frame's accepted substeps end on the frame's time
            assert float(rows[-1]["time"]) == pytest.approx(frames * cs.DT, rel=1e-9)
            shots = data[who]
            assert shots.shape == (frames + 1,) + points.shape
            assert got["crossed_frames"] == len(crossed_frames(points, cells, shots)) == 0
        ratio = e["fem_anim"]["s_per_step"] / e["baseline"]["s_per_step"]
        assert e["ratio"] == pytest.approx(ratio, rel=1e-12)
        assert re.search(rf"\| {e['scene']} \| {e['tets']} \| {frames} \| fem_anim \|.*"
                         rf"\| {ratio:.2f} \|", table)
        com = [cs._com_heights(points, cells, body, data[who])
               for who in ("fem_anim", "baseline")]
        diff = np.max(np.abs(com[0] - com[1]), axis=1)
        assert e["com_height_max_diff_m"] == pytest.approx(diff.max(), rel=1e-12, abs=1e-15)
        assert e["com_height_final_diff_m"] == pytest.approx(diff[-1], rel=1e-12, abs=1e-15)
        assert e["mean_height_final_diff_m"] == pytest.approx(
            abs(com[0][-1].mean() - com[1][-1].mean()), rel=1e-12, abs=1e-15)
        inside = diff <= cs.COM_TOLERANCE
        assert e["agree_until_s"] == pytest.approx(
            cs.DT * ((np.argmin(inside) if not inside.all() else inside.size) - 1))


def test_reduced_set_same_physics(reduced_set):
    _, summary = reduced_set
    for e in summary["scenes"]:
        assert e["baseline"]["unconverged_steps"] == 0, e["scene"]
        assert e["com_height_max_diff_m"] <= cs.COM_TOLERANCE, e["scene"]
        # the bodies fall: both runs move them (a baseline that stands still would agree
        # with a frozen fem_anim only by luck)
    stack = summary["scenes"][0]
    assert stack["max_pairs"]["fem_anim"] > 0 and stack["max_pairs"]["baseline"] > 0


def test_bad_arguments(capsys):
    assert cs.main(["--only", "tower"]) == 2
    assert "unknown scene 'tower'" in capsys.readouterr().err


@pytest.mark.slow
def test_full_set(tmp_path):
    assert cs.main(["--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "contact_set.json").read_text())
    for e in summary["scenes"]:
        assert e["fem_anim"]["crossed_frames"] == e["baseline"]["crossed_frames"] == 0


def test_physics_check_agreement_time():
    a = np.zeros((6, 2))
    b = a.copy()
    b[3:, 1] = [0.5, 3.0, 1.0]  # mm-scale differences: within 2 mm until frame 3
    b *= 1e-3
    got = cs.physics_check(a, b, dt=0.1)
    assert got["agree_until_s"] == pytest.approx(0.3)
    assert got["com_height_max_diff_m"] == pytest.approx(3e-3)
    assert got["com_height_final_diff_m"] == pytest.approx(1e-3)
    assert got["mean_height_final_diff_m"] == pytest.approx(0.5e-3)
    assert cs.physics_check(a, a, dt=0.1)["agree_until_s"] == pytest.approx(0.5)


def test_com_heights_file(reduced_set):
    out, summary = reduced_set
    for e in summary["scenes"]:
        rows = _rows(out / f"{e['scene']}_com_heights.csv")
        fa = np.array([float(r["fem_anim_m"]) for r in rows]).reshape(e["frames"] + 1, -1)
        bl = np.array([float(r["baseline_m"]) for r in rows]).reshape(e["frames"] + 1, -1)
        assert fa.shape[1] == e["bodies"]
        assert cs.physics_check(fa, bl)["com_height_max_diff_m"] == pytest.approx(
            e["com_height_max_diff_m"], rel=1e-9, abs=1e-15)
