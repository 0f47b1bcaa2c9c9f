"""Cloth on cloth: IPC friction between two sheets against Coulomb's law.

Two sheets (one shell surface of two pieces, :mod:`fem_anim.mesh.shell_mesh`) lie one on the
other, kept their thickness t apart by ipctk's codimensional contact (``dmin = t``,
:mod:`fem_anim.contact.ipc`), with IPC's lagged friction mu between them. The top sheet,
thrown along x at v0, feels the friction mu N with N its weight m g:

* on a held (pinned) sheet it decelerates at mu g and stops after v0^2 / (2 mu g);
* on a free sheet lying on frictionless ground the pair exchanges momentum: the top sheet
  decelerates at mu g, the bottom one accelerates at mu g m_top / m_bottom, the horizontal
  momentum m_top v0 is kept (to round-off: the friction is a pair force and the ground
  pushes along z only) and both end at the common velocity v0 m_top / (m_top + m_bottom).

Implicit Euler integrates Coulomb's law exactly in velocity: while the top sheet slides,
each step takes mu g dt off its velocity (with the normal force lagged at the step's start,
as IPC lags it), so the per-step velocity drop is checked against mu g dt, and the positions
against the recurrence v_{k+1} = max(v_k - a dt, 0), x_{k+1} = x_k + dt v_{k+1}, which
differs from the continuum v0^2 / (2 a) by v0 dt / 2 (first order). The smoothing of the
friction below eps_v (ipctk's f1 over eps_v dt in displacement) acts only once the relative
speed is below eps_v: it changes the stop by at most eps_v^2 / (2 a), negligible here.
The normal force is the barrier's: each run first lets the sheets settle under gravity to
the barrier's equilibrium gap (``_settled``), whose positions are the rest shape of the
sliding run, so the lagged normal force equals the weight from the first step on. Every
frame of every run is checked by the independent intersection check
(:func:`fem_anim.contact.intersection.crossed_frames`).
"""

from __future__ import annotations

import numpy as np
import pytest

from fem_anim.contact.intersection import crossed_frames
from fem_anim.meshes.sheet import structured_sheet

T, RHO, E, G, DHAT = 0.002, 500.0, 1.0e6, 9.81, 1.0e-3
MU, V0 = 0.3, 0.3


def _write_obj(path, points, cells):
    # repr of Python floats (numpy 2 writes np.float64(...) for its own scalars)
    lines = ["v " + " ".join(repr(float(c)) for c in p) for p in points]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in cells]
    path.write_text("\n".join(lines) + "\n")


def _two_sheets(path, bottom_size, bottom_origin, h):
    """A 6 cm square sheet 1.2 d_hat above a bottom sheet (itself at ``bottom_origin``),
    shifted by h / 3 so that no vertex of one lies over a vertex of the other."""
    bottom, cb = structured_sheet(bottom_size, [round(s / h) for s in bottom_size],
                                  origin=bottom_origin, triangulation="alternate")
    z = bottom_origin[2] + T + 1.2 * DHAT
    top, ct = structured_sheet([0.06, 0.06], [round(0.06 / h)] * 2,
                               origin=[-0.03 + h / 3, -0.03 + h / 3, z],
                               triangulation="alternate")
    _write_obj(path, np.vstack([bottom, top]), np.vstack([cb, ct + len(bottom)]))


def _scene(path, dt, steps, epsv, **extra):
    scene = {"name": "layers", "mesh": {"shape": "file", "file": str(path)},
             "shell": {"thickness": T},
             "material": {"model": "stvk", "youngs_modulus": E, "poisson_ratio": 0.3,
                          "density": RHO, "mass": "lumped"},
             "time": {"integrator": "implicit_euler", "dt": dt, "steps": steps},
             "output": {"render": False, "fps": 1.0 / dt},
             "gravity": {"acceleration": [0.0, 0.0, -G]},
             "contact": {"dhat": DHAT, "friction": MU, "epsv": epsv, "stiffness": 1.0e4}}
    scene.update(extra)
    return scene


def _frames(scene, out):
    import fem_anim

    with fem_anim.run(fem_anim.Scene.from_dict(scene), out) as run:
        return run.points, run.cells, [run.displacement(k) for k in range(len(run.times))]


def _settled(tmp_path, scene):
    """Let the scene's sheets settle at rest (20 steps, no initial velocity) and write the
    settled surface as an OBJ file: the rest shape of the sliding run."""
    points, cells, frames = _frames(scene, tmp_path / "settle")
    settled = tmp_path / "settled.obj"
    _write_obj(settled, points + frames[-1], cells)
    return settled


def _vertex_mass(points, cells):
    """The lumped mass of each vertex (a third of each triangle's rho t area)."""
    e1, e2 = points[cells[:, 1]] - points[cells[:, 0]], points[cells[:, 2]] - points[cells[:, 0]]
    area = np.linalg.norm(np.cross(e1, e2), axis=1) / 2
    m = np.zeros(len(points))
    np.add.at(m, cells.ravel(), np.repeat(RHO * T * area / 3, 3))
    return m


def _coulomb_recurrence(v0, a, dt, steps):
    """Implicit Euler's positions under a constant friction deceleration a until it stops:
    v_{k+1} = max(v_k - a dt, 0), x_{k+1} = x_k + dt v_{k+1}."""
    v = np.maximum(v0 - a * dt * np.arange(1, steps + 1), 0.0)
    return np.r_[0.0, np.cumsum(dt * v)]


def _slide_on_held_sheet(tmp_path, h, dt, epsv, steps):
    """Top sheet thrown at V0 on a pinned sheet: the top's positions and velocities (mass
    weighted along x) and the run's frames."""
    _two_sheets(tmp_path / "layers.obj", [0.2, 0.1], [-0.05, -0.05, 0.0], h)
    pin = [{"min": [-0.06, -0.06, -0.001], "max": [0.16, 0.06, 0.001]}]
    settled = _settled(tmp_path, _scene(tmp_path / "layers.obj", dt, 20, epsv, pin=pin))
    scene = _scene(settled, dt, steps, epsv, pin=pin, initial={"velocity": [V0, 0.0, 0.0]})
    points, cells, frames = _frames(scene, tmp_path / "slide")
    top = points[:, 2] > T / 2
    m = _vertex_mass(points, cells)[top]
    x = np.array([m @ u[top, 0] / m.sum() for u in frames])
    return x, points, cells, frames, top


def _check_held_slide(x, points, cells, frames, top, dt, stop_tol):
    v = np.diff(x) / dt
    sliding = np.flatnonzero(v > MU * G * dt)  # steps that end still sliding
    drop = -np.diff(np.r_[V0, v])[sliding]
    assert len(sliding) >= 5
    assert drop.mean() == pytest.approx(MU * G * dt, rel=0.01)  # decelerates at mu g
    # each step's velocity near the straight line (a step's drop varies by some per cent
    # as the barrier's pairs change where vertices pass over the other sheet's edges)
    line = V0 - MU * G * dt * (sliding + 1)
    assert np.abs(v[sliding] - line).max() < 0.01 * V0
    discrete = _coulomb_recurrence(V0, MU * G, dt, len(x) - 1)
    assert np.abs(x - discrete).max() < 0.01 * discrete[-1]
    assert abs(v[-1]) < 1e-3 * V0  # it stopped
    assert x[-1] == pytest.approx(V0 ** 2 / (2 * MU * G), rel=stop_tol)
    gap = min((points[top, 2] + u[top, 2]).min() for u in frames)
    assert gap >= T * (1 - 1e-9)  # the mid-surfaces never nearer than t
    assert crossed_frames(points, cells, frames) == []


def test_sheet_thrown_on_a_held_sheet_stops_at_coulomb_distance(tmp_path):
    """Reduced (2 cm elements, dt = 5 ms): the top sheet's velocity drops by mu g dt each
    step while it slides (1 % on average; each step's velocity within 1 % of v0 of the line
    v0 - mu g t), its positions follow implicit Euler's Coulomb recurrence
    (1 % of the stop), and it stops at v0^2 / (2 mu g) within mu g dt / v0 + 1 % (the
    scheme's first-order lag v0 dt / 2); no crossing, never nearer than t."""
    dt = 0.005
    x, points, cells, frames, top = _slide_on_held_sheet(tmp_path, 0.02, dt, 1e-3, 28)
    _check_held_slide(x, points, cells, frames, top, dt, MU * G * dt / V0 + 0.01)


@pytest.mark.slow
def test_sheet_thrown_on_a_held_sheet_converges_to_coulomb_distance(tmp_path):
    """Fuller: 1 cm elements, dt = 1 ms, eps_v = 1e-4 m/s: the same checks, and the stop
    within 1.5 % of v0^2 / (2 mu g) (the scheme's lag is 1 % of it at this dt)."""
    dt = 0.001
    x, points, cells, frames, top = _slide_on_held_sheet(tmp_path, 0.01, dt, 1e-4, 120)
    _check_held_slide(x, points, cells, frames, top, dt, 0.015)


def _slope_run(tmp_path, slope, dt, epsv):
    """The held pair on a slope: the top sheet's velocities along x (mass weighted), the
    acceleration g (sin a - mu cos a) of Coulomb's sliding, and the frames."""
    cos, sin = 1 / np.hypot(1, slope), slope / np.hypot(1, slope)
    _two_sheets(tmp_path / "layers.obj", [0.2, 0.1], [-0.05, -0.05, 0.0], 0.02)
    pin = [{"min": [-0.06, -0.06, -0.001], "max": [0.16, 0.06, 0.001]}]
    settled = _settled(tmp_path, _scene(tmp_path / "layers.obj", dt, 20, epsv, pin=pin,
                                        gravity={"acceleration": [0.0, 0.0, -G * cos]}))
    scene = _scene(settled, dt, 24, epsv, pin=pin,
                   gravity={"acceleration": [G * sin, 0.0, -G * cos]})
    points, cells, frames = _frames(scene, tmp_path / "slope")
    top = points[:, 2] > T / 2
    m = _vertex_mass(points, cells)[top]
    v = np.diff([m @ u[top, 0] / m.sum() for u in frames]) / dt
    return v, G * (sin - MU * cos), points, cells, frames


@pytest.mark.parametrize("slope", [0.5, 0.2])
def test_sheet_on_a_held_sheet_on_a_slope(tmp_path, slope):
    """The held pair tilted (gravity g (sin a, 0, -cos a), tan a = ``slope``), settled under
    the normal part g cos a: steeper than mu (0.5), the top sheet slides down from rest at
    g (sin a - mu cos a) (1 % on average; its velocity within 1 % of the line a t); less
    steep (0.2), static friction holds it up to IPC's smoothing: below eps_v the friction is
    mu N f1(v / eps_v), f1(y) = 2 y - y^2, so the sheet creeps at the speed where that holds
    the weight's tangential part, v = eps_v (1 - sqrt(1 - tan a / mu)) (2 %, after its first
    steps), never faster than eps_v."""
    dt, epsv = 0.005, 1e-3
    v, a, points, cells, frames = _slope_run(tmp_path, slope, dt, epsv)
    if a > 0:
        assert np.diff(np.r_[0.0, v]).mean() == pytest.approx(a * dt, rel=0.01)
        t = dt * np.arange(1, len(v) + 1)
        assert np.abs(v - a * t).max() < 0.01 * a * t[-1]
    else:
        assert np.abs(v).max() < epsv
        creep = epsv * (1 - np.sqrt(1 - slope / MU))
        assert np.abs(v[4:] / creep - 1).max() < 0.02
    assert crossed_frames(points, cells, frames) == []


def _slide_on_free_sheet(tmp_path, monkeypatch, h, dt, epsv, steps):
    """The top sheet thrown at V0 on a free sheet lying on frictionless ground.

    ``[initial]`` gives the whole surface one rigid velocity, so the test gives the top
    sheet alone its velocity by replacing the run's initial-velocity function."""
    import fem_anim.simulation.loop as loop

    ground = [{"type": "plane", "point": [0.0, 0.0, 0.0], "normal": [0, 0, 1], "dhat": DHAT}]
    # centred on the top sheet across x: the friction's line of action passes through the
    # pair's centre of mass, so the sheets do not spin about z
    _two_sheets(tmp_path / "layers.obj", [0.12, 0.08], [-0.05, -0.04 + h / 3,
                                                        T / 2 + 1.2 * DHAT], h)
    settled = _settled(tmp_path, _scene(tmp_path / "layers.obj", dt, 20, epsv,
                                        obstacle=ground))
    cut = 1.5 * T + DHAT  # between the layers: bottom ~ t / 2 + d*, top ~ 3 t / 2 + d*

    def top_velocity(scene, problem):
        X = problem.V.tabulate_dof_coordinates()
        v = np.zeros_like(X)
        v[X[:, 2] > cut, 0] = V0
        return v.reshape(-1)

    monkeypatch.setattr(loop, "initial_velocity", top_velocity)
    points, cells, frames = _frames(_scene(settled, dt, steps, epsv, obstacle=ground),
                                    tmp_path / "slide")
    top = points[:, 2] > cut
    return points, cells, frames, top


def _check_free_slide(points, cells, frames, top, dt):
    m = _vertex_mass(points, cells)
    r = m[top].sum() / m[~top].sum()
    p0 = m[top].sum() * V0
    v = [(b - a) / dt for a, b in zip(frames, frames[1:])]  # implicit Euler's velocities
    px = np.array([m @ w[:, 0] for w in v])
    assert np.abs(px - p0).max() < 1e-12 * p0  # horizontal momentum: round-off
    vt = np.array([m[top] @ w[top, 0] for w in v]) / m[top].sum()
    vb = np.array([m[~top] @ w[~top, 0] for w in v]) / m[~top].sum()
    sliding = np.flatnonzero(vt - vb > (1 + r) * MU * G * dt)
    assert len(sliding) >= 5
    for w, w0, a in ((vt, V0, -MU * G), (vb, 0.0, r * MU * G)):
        assert np.diff(np.r_[w0, w])[sliding].mean() == pytest.approx(a * dt, rel=0.01)
        assert np.abs(w[sliding] - (w0 + a * dt * (sliding + 1))).max() < 0.01 * V0
    common = V0 * r / (1 + r)
    assert vt[-1] == pytest.approx(common, rel=0.01)
    assert vb[-1] == pytest.approx(common, rel=0.01)
    assert crossed_frames(points, cells, frames) == []


def test_free_sheets_exchange_momentum_by_friction(tmp_path, monkeypatch):
    """Reduced (2 cm elements, dt = 5 ms, 20 steps): the top sheet thrown on a free sheet on
    frictionless ground. Horizontal momentum equals m_top v0 at every step to 1e-12; while
    they slide the top loses mu g dt and the bottom gains mu g dt m_top / m_bottom per step
    (1 % on average; the velocities within 1 % of v0 of those lines); both end at
    v0 m_top / (m_top + m_bottom) (1 %); no crossing."""
    points, cells, frames, top = _slide_on_free_sheet(tmp_path, monkeypatch, 0.02, 0.005,
                                                      1e-3, 20)
    _check_free_slide(points, cells, frames, top, 0.005)


def _print_measurements() -> None:
    """The numbers of docs/cloth.md's table (the default runs and the slow one)."""
    import tempfile
    from pathlib import Path

    import fem_anim.simulation.loop as loop

    for h, dt, epsv, steps in ((0.02, 0.005, 1e-3, 28), (0.01, 0.001, 1e-4, 120)):
        x, points, cells, frames, top = _slide_on_held_sheet(Path(tempfile.mkdtemp()), h, dt,
                                                             epsv, steps)
        v = np.diff(x) / dt
        sliding = np.flatnonzero(v > MU * G * dt)
        line = V0 - MU * G * dt * (sliding + 1)
        rec = _coulomb_recurrence(V0, MU * G, dt, len(x) - 1)[-1]
        stop = V0 ** 2 / (2 * MU * G)
        gap = min((points[top, 2] + u[top, 2]).min() for u in frames)
        print(f"held, h = {h}, dt = {dt}: deceleration "
              f"{-np.diff(np.r_[V0, v])[sliding].mean() / (MU * G * dt):.5f} mu g, "
              f"max |v - line| {np.abs(v[sliding] - line).max() / V0:.2e} v0, stop "
              f"{x[-1]:.6f} m, recurrence {rec:.6f} ({x[-1] / rec - 1:+.4f}), continuum "
              f"{stop:.6f} ({x[-1] / stop - 1:+.4f}), lowest top vertex t + "
              f"{(gap - T) / DHAT:.3f} d_hat")

    for slope in (0.5, 0.2):
        v, a, *_ = _slope_run(Path(tempfile.mkdtemp()), slope, 0.005, 1e-3)
        if a > 0:
            print(f"slope {slope}: acceleration {np.diff(np.r_[0.0, v]).mean() / 0.005:.6f}, "
                  f"g (sin a - mu cos a) = {a:.6f}")
        else:
            creep = 1e-3 * (1 - np.sqrt(1 - slope / MU))
            print(f"slope {slope}: creep {v[4:].min():.4e} to {v[4:].max():.4e} m/s, "
                  f"eps_v (1 - sqrt(1 - tan a / mu)) = {creep:.4e}")

    class Patch:
        def setattr(self, obj, name, value):
            self.undo = (obj, name, getattr(obj, name))
            setattr(obj, name, value)

    patch, dt = Patch(), 0.005
    points, cells, frames, top = _slide_on_free_sheet(Path(tempfile.mkdtemp()), patch, 0.02,
                                                      dt, 1e-3, 20)
    setattr(*patch.undo)
    m = _vertex_mass(points, cells)
    r = m[top].sum() / m[~top].sum()
    v = [(b - a) / dt for a, b in zip(frames, frames[1:])]
    px = np.array([m @ w[:, 0] for w in v])
    vt = np.array([m[top] @ w[top, 0] for w in v]) / m[top].sum()
    vb = np.array([m[~top] @ w[~top, 0] for w in v]) / m[~top].sum()
    sliding = np.flatnonzero(vt - vb > (1 + r) * MU * G * dt)
    common = V0 * r / (1 + r)
    print(f"free, m_top / m_bottom = {r:.6f}: momentum error "
          f"{np.abs(px / (m[top].sum() * V0) - 1).max():.2e}, top "
          f"{-np.diff(np.r_[V0, vt])[sliding].mean() / (MU * G * dt):.5f} mu g, bottom "
          f"{np.diff(np.r_[0.0, vb])[sliding].mean() / (r * MU * G * dt):.5f} r mu g, end "
          f"{vt[-1] / common:.6f} and {vb[-1] / common:.6f} of the common velocity")


if __name__ == "__main__":
    _print_measurements()


@pytest.mark.mpi
def test_held_slide_on_two_ranks_equals_serial(tmp_path):
    """The sheet thrown on a held sheet (two pieces, IPC friction) for 12 steps on 2 ranks:
    every step's energies and the final displacement equal the serial run's to 1e-8."""
    import meshio

    from conftest import run_on_one_and_more_ranks
    from test_cli import read_stats

    _two_sheets(tmp_path / "layers.obj", [0.2, 0.1], [-0.05, -0.05, 0.0], 0.02)
    pin = [{"min": [-0.06, -0.06, -0.001], "max": [0.16, 0.06, 0.001]}]
    settled = _settled(tmp_path, _scene(tmp_path / "layers.obj", 0.005, 20, 1e-3, pin=pin))
    scene = tmp_path / "slide.toml"
    scene.write_text(f"""name = "slide"
[mesh]
shape = "file"
file = "{settled}"
[shell]
thickness = {T}
[material]
model = "stvk"
youngs_modulus = {E}
poisson_ratio = 0.3
density = {RHO}
mass = "lumped"
[time]
integrator = "implicit_euler"
dt = 0.005
steps = 12
[gravity]
acceleration = [0.0, 0.0, -{G}]
[initial]
velocity = [{V0}, 0.0, 0.0]
[contact]
dhat = {DHAT}
friction = {MU}
epsv = 1e-3
stiffness = 1e4
[[pin]]
min = [-0.06, -0.06, -0.001]
max = [0.16, 0.06, 0.001]
[output]
render = false
""")
    outs = run_on_one_and_more_ranks(scene, tmp_path)
    a, b = read_stats(outs[1] / "stats.csv"), read_stats(outs[2] / "stats.csv")
    assert len(a) == len(b) == 12 and min(row["contact_pairs"] for row in a) > 0
    for ra, rb in zip(a, b):
        for key in ("kinetic", "elastic", "gravity", "contact"):
            assert rb[key] == pytest.approx(ra[key], rel=1e-8, abs=1e-14), (ra["step"], key)
    ua = meshio.read(outs[1] / "final.vtu").point_data["displacement"]
    ub = meshio.read(outs[2] / "final.vtu").point_data["displacement"]
    assert np.linalg.norm(ub - ua) <= 1e-8 * np.linalg.norm(ua)
    assert ua[:, 0].max() > 0.01  # the top sheet slid (1.1 cm in these 12 steps)
