"""Wind and aerodynamic drag on a shell (``[wind]``, :mod:`fem_anim.forms.aerodynamic_drag`).

The drag law f = -C_d rho_a |s| s n / 2 per area (s = (v - w) . n) is checked through whole
runs against its analytic consequences: a sheet falling flat follows implicit Euler's exact
recurrence for the drag law step by step and reaches the terminal velocity
w - sqrt(2 (m/A) g / (C_d rho_a)); falling edge-on it feels no drag (free fall, any wind in
its plane); Newmark reaches the same terminal velocity; 2 ranks equal serial.
"""

from __future__ import annotations

import contextlib
import io
import math

import numpy as np
import pytest

from fem_anim.cli import main as cli_main

RHO, T, G, CD, RHO_AIR, SIDE = 500.0, 0.002, 9.81, 1.2, 1.2, 0.2
MASS = RHO * T * SIDE * SIDE  # kg

FALL = f"""
name = "fall"
[mesh]
shape = "sheet"
size = [{SIDE}, {SIDE}]
element_size = 0.1
[shell]
thickness = {T}
[material]
model = "stvk"
youngs_modulus = 1.0e6
poisson_ratio = 0.3
density = {RHO}
[time]
dt = 0.1
steps = 40
integrator = "implicit_euler"
[gravity]
acceleration = [0.0, 0.0, -{G}]
[wind]
velocity = [0.0, 0.0, 1.0]
drag_coefficient = {CD}
air_density = {RHO_AIR}
[output]
render = false
"""


def _run(tmp_path, name, text, *args):
    """Run a scene in this process; (exit code, stderr lines, stats rows)."""
    from test_cli import read_stats

    scene = tmp_path / f"{name}.toml"
    scene.write_text(text)
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = cli_main(["run", str(scene), "-o", str(tmp_path / name), "--quiet", *args])
    lines = [line for line in err.getvalue().splitlines() if line.strip()]
    rows = read_stats(tmp_path / name / "stats.csv") if code == 0 else []
    return code, lines, rows


def _speeds(rows):
    """|v| of the rigidly moving sheet at each step, from its kinetic energy (m/s)."""
    return np.array([math.sqrt(2 * r["kinetic"] / MASS) for r in rows])


def test_falling_flat_follows_the_drag_law_to_terminal_velocity(tmp_path):
    """Implicit Euler with the drag law: r_{k+1} = r_k - h g + h k r_{k+1}^2 for the
    relative velocity r = v - w < 0 (k = C_d rho_a / (2 m/A)), solved in closed form per step,
    equals the run's velocity at every step; the last is the terminal velocity
    w - sqrt(2 (m/A) g / (C_d rho_a))."""
    code, err, rows = _run(tmp_path, "fall", FALL)
    assert code == 0, err
    h, w, k = 0.1, 1.0, CD * RHO_AIR / (2 * RHO * T)
    r, expected = -w, []  # at rest in a wind of 1 m/s upwards
    for _ in rows:
        c = r - h * G
        r = (1 - math.sqrt(1 - 4 * h * k * c)) / (2 * h * k)
        expected.append(abs(w + r))
    assert np.allclose(_speeds(rows), expected, rtol=1e-8, atol=0)
    terminal = math.sqrt(2 * RHO * T * G / (CD * RHO_AIR)) - w
    assert _speeds(rows)[-1] == pytest.approx(terminal, rel=1e-7)


def test_newmark_reaches_the_same_terminal_velocity(tmp_path):
    """Newmark (its initial acceleration includes the drag at rest in the wind) settles at
    the drag law's terminal velocity, and faster drag (C_d doubled) lowers it by sqrt(2)."""
    for cd in (CD, 2 * CD):
        code, err, rows = _run(tmp_path, f"newmark{cd}", FALL, "--set",
                               "time.integrator=newmark", "--set",
                               f"wind.drag_coefficient={cd}")
        assert code == 0, err
        terminal = math.sqrt(2 * RHO * T * G / (cd * RHO_AIR)) - 1.0
        assert _speeds(rows)[-1] == pytest.approx(terminal, rel=1e-6)


def test_edge_on_sheet_feels_no_drag(tmp_path):
    """Gravity and wind in the sheet's plane: no normal relative velocity, no drag; the
    sheet falls freely, v = g t at every step (implicit Euler is exact for free fall)."""
    text = FALL.replace(f"acceleration = [0.0, 0.0, -{G}]", f"acceleration = [0.0, -{G}, 0.0]")
    text = text.replace("velocity = [0.0, 0.0, 1.0]", "velocity = [3.0, 2.0, 0.0]")
    code, err, rows = _run(tmp_path, "edge", text, "--set", "time.steps=10")
    assert code == 0, err
    times = np.array([r["time"] for r in rows])
    assert np.allclose(_speeds(rows), G * times, rtol=1e-9, atol=0)


def test_wind_without_a_shell_is_one_line_exit_2(tmp_path):
    """[wind] on a solid: one error line, exit 2."""
    text = FALL.replace('shape = "sheet"', 'shape = "box"').replace(
        f"size = [{SIDE}, {SIDE}]", "size = [0.2, 0.2, 0.2]").replace(
        f"[shell]\nthickness = {T}\n", "")
    code, err, _ = _run(tmp_path, "solid", text)
    assert code == 2
    assert len(err) == 1 and err[0].startswith("fem-anim: error: ") and "[wind]" in err[0], err


FLAG = """
name = "flag"
[mesh]
shape = "sheet"
size = [0.4, 0.2]
element_size = 0.1
[shell]
thickness = 0.001
[material]
model = "stvk"
youngs_modulus = 1.0e6
poisson_ratio = 0.3
density = 500.0
[time]
dt = 0.02
steps = 8
[gravity]
acceleration = [0.0, 0.0, -9.81]
[wind]
velocity = [3.0, 0.0, 2.0]
[[pin]]
min = [-0.01, -0.01, -0.01]
max = [0.01, 0.21, 0.01]
[output]
render = false
"""


def test_work_of_the_wind_is_not_flagged_as_a_gain(tmp_path):
    """A sheet pinned on one edge, without gravity, blown by the wind: its total energy
    rises from zero (the wind works on it) and the energy report does not flag that as the
    scheme's gain."""
    import json

    code, err, rows = _run(tmp_path, "blown", FLAG.replace(
        "[gravity]\nacceleration = [0.0, 0.0, -9.81]\n", ""))
    assert code == 0, err
    energy = json.loads((tmp_path / "blown" / "summary.json").read_text())["energy"]
    assert energy["drift"] > 0.1 and not energy["gained"] and not energy["flagged"], energy


@pytest.mark.mpi
def test_two_ranks_equal_serial_in_wind(tmp_path):
    """A sheet pinned on one edge in a slanted wind: 2 ranks' energies and final
    displacement equal the serial run's to 1e-8."""
    import meshio

    from conftest import run_on_one_and_more_ranks
    from test_cli import read_stats

    scene = tmp_path / "flag.toml"
    scene.write_text(FLAG)
    outs = run_on_one_and_more_ranks(scene, tmp_path)
    a, b = read_stats(outs[1] / "stats.csv"), read_stats(outs[2] / "stats.csv")
    assert len(a) == len(b) == 8
    for ra, rb in zip(a, b):
        for key in ("kinetic", "elastic", "gravity"):
            assert rb[key] == pytest.approx(ra[key], rel=1e-8, abs=1e-14), (ra["step"], key)
    ua = meshio.read(outs[1] / "final.vtu").point_data["displacement"]
    ub = meshio.read(outs[2] / "final.vtu").point_data["displacement"]
    assert np.linalg.norm(ub - ua) <= 1e-8 * np.linalg.norm(ua)
    assert np.abs(ua[:, 0]).max() > 1e-4  # the wind moved it downwind (x), not only gravity
