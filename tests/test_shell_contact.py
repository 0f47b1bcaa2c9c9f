"""Shells in contact: obstacles at the half-thickness, IPC self contact at the thickness.

A shell's mesh is its mid-surface; its faces lie t / 2 on either side. Against an obstacle
(:mod:`fem_anim.contact.obstacles`) the barrier acts on the distance of the face, so a sheet
laid on the ground rests with its mid-surface at t / 2 + d*, d* the barrier's equilibrium
gap under the sheet's weight; with friction it slides to rest at Coulomb's deceleration
mu g. Against itself (:mod:`fem_anim.contact.ipc`, offset t) two layers stop with their
mid-surfaces t apart. Every frame is checked by the independent intersection check
(:func:`fem_anim.contact.intersection.crossing_pairs`), itself tested on known crossings.
"""

from __future__ import annotations

import numpy as np
import pytest

from fem_anim.contact.intersection import boundary_triangles, crossed_frames, crossing_pairs
from fem_anim.meshes.sheet import structured_sheet

T, RHO, E, G, DHAT = 0.002, 500.0, 1.0e6, 9.81, 1.0e-3


def _sheet(size=(0.2, 0.2), n=(4, 4), z=0.0):
    points, cells = structured_sheet(list(size), list(n), triangulation="right")
    points = np.c_[points[:, :2], np.full(len(points), z)]
    return points, cells


def _box_surface(lo, hi):
    """The boundary triangles of a box of 6 tetrahedra (Kuhn), its corner points."""
    corners = np.array([[x, y, z] for z in (lo[2], hi[2]) for y in (lo[1], hi[1])
                        for x in (lo[0], hi[0])])
    tets = np.array([[0, 1, 3, 7], [0, 1, 5, 7], [0, 2, 3, 7], [0, 2, 6, 7], [0, 4, 5, 7],
                     [0, 4, 6, 7]])
    return corners, boundary_triangles(tets)


def test_crossing_pairs_finds_a_sheet_through_a_solid_and_through_itself():
    """A flat sheet has no crossing (adjacent triangles excluded); a box pushed through the
    sheet crosses it, the box above it does not; a sheet folded through itself crosses."""
    points, cells = _sheet()
    assert len(crossing_pairs(points, cells)) == 0
    for z_lo, crossed in ((-0.05, True), (0.01, False)):
        box, skin = _box_surface([0.05, 0.05, z_lo], [0.15, 0.15, z_lo + 0.1])
        x = np.vstack([points, box])
        soup = np.vstack([cells, skin + len(points)])
        pairs = crossing_pairs(x, soup)
        assert (len(pairs) > 0) == crossed
        if crossed:  # every pair is one sheet triangle and one box triangle
            assert np.all((pairs[:, 0] < len(cells)) & (pairs[:, 1] >= len(cells)))
    # fold the half x > 0.1 back over the other half, from 1 cm above it to 2 cm below
    folded = points.copy()
    right = points[:, 0] > 0.1 + 1e-12
    folded[right, 0] = 0.1 - 0.5 * (points[right, 0] - 0.1)
    folded[right, 2] = 0.04 - 0.6 * (points[right, 0] - 0.1)
    above = folded.copy()
    above[right, 2] = 0.01
    assert crossed_frames(points, cells, [above - points]) == []
    assert crossed_frames(points, cells, [np.zeros_like(points), folded - points]) == [1]


def test_crossing_pairs_sweep_equals_every_pair():
    """On a random soup of 300 small triangles the sweep along x finds exactly the crossing
    pairs that testing every pair of triangles sharing no vertex finds (several chunks)."""
    from fem_anim.contact import intersection

    rng = np.random.default_rng(3)
    x = np.repeat(rng.random((300, 3)), 3, axis=0) + 0.15 * rng.standard_normal((900, 3))
    triangles = np.arange(900).reshape(300, 3)
    triangles[::7, 0] = triangles[1::7, 0][: len(triangles[::7])]  # some share a vertex
    found = {tuple(p) for p in intersection.crossing_pairs(x, triangles)}
    i, j = np.triu_indices(300, 1)
    keep = ~(triangles[i][:, :, None] == triangles[j][:, None, :]).any(axis=(1, 2))
    i, j = i[keep], j[keep]
    c = x[triangles]
    hit = np.zeros(i.size, bool)
    for s, t in ((i, j), (j, i)):
        for e0, e1 in ((0, 1), (1, 2), (2, 0)):
            hit |= intersection._segment_crosses(c[s, e0], c[s, e1], c[t, 0], c[t, 1],
                                                 c[t, 2], 0.0)
    assert len(found) > 20
    assert found == {(int(a), int(b)) for a, b in zip(i[hit], j[hit])}


def _barrier_gap(pressure: float, kappa: float, dhat: float) -> float:
    """d* with p(d*) = pressure, p = -kappa / dhat b'(d), b = -(d - dhat)^2 ln(d / dhat)."""
    from scipy.optimize import brentq

    def p(d):
        return -kappa / dhat * (-2 * (d - dhat) * np.log(d / dhat) - (d - dhat) ** 2 / d)
    return brentq(lambda d: p(d) - pressure, 1e-12 * dhat, dhat * (1 - 1e-12), xtol=1e-18)


def _scene(**extra):
    scene = {
        "name": "sheet", "mesh": {"shape": "sheet", "size": [0.2, 0.2],
                                  "origin": [-0.1, -0.1, 0.02], "element_size": 0.05},
        "shell": {"thickness": T},
        "material": {"model": "stvk", "youngs_modulus": E, "poisson_ratio": 0.3,
                     "density": RHO, "mass": "lumped"},
        "time": {"dt": 0.01, "steps": 20}, "output": {"render": False, "fps": 100},
        "gravity": {"acceleration": [0.0, 0.0, -G]},
        "obstacle": [{"type": "plane", "point": [0.0, 0.0, 0.0], "normal": [0, 0, 1],
                      "dhat": DHAT}]}
    for key, value in extra.items():
        scene[key] = value
    return scene


def _frames(scene, out):
    import fem_anim

    with fem_anim.run(fem_anim.Scene.from_dict(scene), out) as run:
        return run.points, run.cells, [run.displacement(k) for k in range(len(run.times))], \
            np.asarray(run.times)


def test_sheet_dropped_on_the_ground_rests_at_the_offset(tmp_path):
    """A flat sheet dropped 2 cm rests flat with its mid-surface at t / 2 + d*, d* the
    barrier's gap carrying its weight rho t g (kappa = E); no frame below it, no crossing."""
    points, cells, frames, _ = _frames(_scene(), tmp_path / "drop")
    z = points[:, 2] + frames[-1][:, 2]
    expected = T / 2 + _barrier_gap(RHO * T * G, E, DHAT)
    assert np.abs(z - expected).max() < 1e-9
    assert min((points[:, 2] + u[:, 2]).min() for u in frames) > T / 2
    assert crossed_frames(points, cells, frames) == []


def test_sheet_sliding_on_the_ground_stops_at_coulomb_deceleration(tmp_path):
    """A sheet resting at its gap, thrown along x at v0 on ground with friction mu: its
    centre moves v0 t - mu g t^2 / 2 while it slides (lagged IPC friction, implicit Euler:
    first order in dt) and it stops at v0^2 / (2 mu g)."""
    mu, v0 = 0.3, 0.5
    z0 = T / 2 + _barrier_gap(RHO * T * G, E, DHAT)
    scene = _scene(initial={"velocity": [v0, 0.0, 0.0]},
                   time={"dt": 0.005, "steps": 50})
    scene["mesh"]["origin"] = [-0.1, -0.1, z0]
    scene["obstacle"][0].update(friction=mu, epsv=1e-4)
    points, cells, frames, times = _frames(scene, tmp_path / "slide")
    x = np.array([u[:, 0].mean() for u in frames])
    stop = v0 / (mu * G)
    sliding = times < 0.8 * stop
    analytic = v0 * times - mu * G * times ** 2 / 2
    assert np.abs(x[sliding] - analytic[sliding]).max() < 0.03 * analytic[sliding].max()
    assert x[-1] == pytest.approx(v0 ** 2 / (2 * mu * G), rel=0.03)
    assert crossed_frames(points, cells, frames) == []


def _u_fold(path, length=0.1, gap=0.02, width=0.06, h=0.02):
    """A strip folded into a U as an OBJ file: lower leg z = 0 (x in [0, L]), a wall at
    x = L up to z = gap, an upper leg back over the lower one at z = gap."""
    n_along = round((2 * length + gap) / h)
    flat, cells = structured_sheet([2 * length + gap, width], [n_along, round(width / h)],
                                   triangulation="alternate")
    s = flat[:, 0]
    x = np.where(s <= length, s, np.where(s <= length + gap, length,
                                          length - (s - length - gap)))
    z = np.where(s <= length, 0.0, np.where(s <= length + gap, s - length, gap))
    points = np.c_[x, flat[:, 1], z]
    # repr of Python floats (numpy 2 writes np.float64(...) for its own scalars)
    lines = ["v " + " ".join(repr(float(c)) for c in p) for p in points]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in cells]
    path.write_text("\n".join(lines) + "\n")
    return points


def test_folded_strip_lands_on_itself_the_thickness_apart(tmp_path):
    """IPC self contact with the thickness as offset: the upper leg of a U-folded strip
    (lower leg and wall held, no bending stiffness) falls onto the lower leg. Contact pairs
    form, no frame has a crossing, and the upper leg's vertices above the lower leg (a held
    flat rectangle at z = 0) stay at z >= t, ending within t + d_hat."""
    length, gap = 0.1, 0.02
    _u_fold(tmp_path / "fold.obj", length, gap)
    scene = _scene(time={"dt": 0.01, "steps": 25})
    scene["mesh"] = {"shape": "file", "file": str(tmp_path / "fold.obj")}
    scene["shell"]["bending"] = 0.0
    scene["material"]["mass"] = "consistent"
    del scene["obstacle"]
    scene["contact"] = {"dhat": DHAT}
    scene["damping"] = {"alpha": 5.0}
    scene["pin"] = [{"min": [-0.01, -0.01, -0.001], "max": [length + 0.001, 0.07, 0.001]},
                    {"min": [length - 0.001, -0.01, -0.001], "max": [length + 0.001, 0.07,
                                                                       gap - 0.001]}]
    points, cells, frames, _ = _frames(scene, tmp_path / "fold")
    import fem_anim

    with fem_anim.open_run(tmp_path / "fold") as run:
        pairs = [row["contact_pairs"] for row in run.stats]
    assert max(pairs) > 0
    upper = np.isclose(points[:, 2], gap) & (points[:, 0] < length - 1e-9)
    over = lambda u: upper & (points[:, 0] + u[:, 0] > 0) & (  # noqa: E731
        points[:, 0] + u[:, 0] < length)
    lowest = [(points[over(u), 2] + u[over(u), 2]).min() for u in frames]
    assert min(lowest) >= T * (1 - 1e-9)
    assert lowest[-1] < T + DHAT
    assert crossed_frames(points, cells, frames) == []


@pytest.mark.mpi
def test_fold_on_two_ranks_equals_serial(tmp_path):
    """The U-fold with IPC friction (mu = 0.3) on 2 ranks: the energies of every step and the
    final displacement equal the serial run's to 1e-8 (the shell's triangles gathered to
    ipctk's rank and its forces sent back)."""
    import meshio

    from conftest import run_on_one_and_more_ranks
    from test_cli import read_stats

    _u_fold(tmp_path / "fold.obj")
    scene = tmp_path / "fold.toml"
    scene.write_text(f"""name = "fold"
[mesh]
shape = "file"
file = "{tmp_path / 'fold.obj'}"
[shell]
thickness = {T}
bending = 0.0
[material]
model = "stvk"
youngs_modulus = {E}
poisson_ratio = 0.3
density = {RHO}
[time]
dt = 0.01
steps = 15
[gravity]
acceleration = [0.0, 0.0, -{G}]
[contact]
dhat = {DHAT}
friction = 0.3
[[pin]]
min = [-0.01, -0.01, -0.001]
max = [0.101, 0.07, 0.001]
[[pin]]
min = [0.099, -0.01, -0.001]
max = [0.101, 0.07, 0.019]
[output]
render = false
""")
    outs = run_on_one_and_more_ranks(scene, tmp_path)
    a, b = read_stats(outs[1] / "stats.csv"), read_stats(outs[2] / "stats.csv")
    assert len(a) == len(b) and max(row["contact_pairs"] for row in a) > 0
    for ra, rb in zip(a, b):
        for key in ("kinetic", "elastic", "gravity", "contact"):
            assert rb[key] == pytest.approx(ra[key], rel=1e-8, abs=1e-14), (ra["step"], key)
    ua = meshio.read(outs[1] / "final.vtu").point_data["displacement"]
    ub = meshio.read(outs[2] / "final.vtu").point_data["displacement"]
    assert np.linalg.norm(ub - ua) <= 1e-8 * np.linalg.norm(ua)


def test_a_shell_thicker_than_its_elements_apart_is_refused(tmp_path):
    """Self contact with t = 6 cm on a sheet of 5 cm elements: non-adjacent triangles are
    nearer than the offset at rest (an infinite barrier), refused in one line, exit 2."""
    from test_shell import SHEET, _run

    text = SHEET.replace("thickness = 0.002", "thickness = 0.06").replace(
        "element_size = 0.1", "element_size = 0.05") + "[contact]\ndhat = 0.001\n"
    code, err = _run(tmp_path, "thick", text)
    assert code == 2
    assert len(err) == 1 and "not more than its thickness" in err[0], err


def test_two_layers_farther_apart_than_the_thickness_are_accepted(tmp_path):
    """A strip folded into a U whose legs are 2.5 mm apart (t = 2 mm, d_hat = 1 mm: within
    the contact's reach at rest, but farther apart than the offset) runs. The rest check
    compares a distance with the thickness: ipctk's minimum distance is a squared one
    (6.25e-6 m^2 here, below t), and comparing that with t refused these legs."""
    _u_fold(tmp_path / "fold.obj", 0.1, 0.0025)
    scene = _scene(time={"dt": 0.01, "steps": 2})
    scene["mesh"] = {"shape": "file", "file": str(tmp_path / "fold.obj")}
    scene["material"]["mass"] = "consistent"
    del scene["obstacle"]
    scene["contact"] = {"dhat": DHAT}
    points, cells, frames, _ = _frames(scene, tmp_path / "layers")
    assert len(frames) == 3 and crossed_frames(points, cells, frames) == []


def test_a_shell_run_is_drawn_in_3d(tmp_path):
    """The renderer reads a shell run's triangles as a surface in 3D (its scene.json has
    [shell]); a 2D solid's triangles stay 2D."""
    import json

    from fem_anim.render.frames import space_dim

    (tmp_path / "scene.json").write_text(json.dumps({"scene": {"shell": {"thickness": T},
                                                               "mesh": {"dim": 3}}}))
    assert space_dim("triangle", tmp_path) == 3
    (tmp_path / "scene.json").write_text(json.dumps({"scene": {"mesh": {"dim": 2}}}))
    assert space_dim("triangle", tmp_path) == 2
    assert space_dim("tetra", tmp_path) == 3
