"""How :func:`fem_anim.simulation.energy_report.energy_report` classifies a run's energy.

The contract: damping and friction only remove energy, so a *gain* is flagged for every
scene without moving pins (conservative, damped or with friction), a *loss* only for a
conservative scene (a damped or frictional scene is meant to lose it); a scene whose pins
move (a handle works on the body) is flagged for neither. Checked on constructed rows of
known drift, so each classification is seen both ways.
"""

from __future__ import annotations

import pytest
from scenes import beam, make_scene, wall_pin

from fem_anim.simulation.energy_report import DAMPED_THRESHOLD, describe_energy, energy_report

INITIAL = {"kinetic": 0.0, "elastic": 0.0, "gravity": 10.0, "total_energy": 10.0,
           "roundoff": 1e-9}


def scene(tmp_path, kind: str, integrator: str = "implicit_euler"):
    """A beam scene of one kind: conservative, damped, friction (obstacle or between bodies
    is the same key path for the report: an obstacle here), moving (a handle)."""
    pin = wall_pin(3)
    extra = {"conservative": {}, "damped": {"damping": {"alpha": 0.5}},
             "friction": {"obstacle": [{"type": "plane", "point": [0.0, 0.0, -0.5],
                                        "normal": [0.0, 0.0, 1.0], "friction": 0.4}]},
             "moving": {"pin": [dict(pin, velocity=[0.0, 0.0, 0.1])]}}[kind]
    base = beam(f"report_{kind}", 3, time={"integrator": integrator}, pin=[pin])
    return make_scene(tmp_path, dict(base, **extra))


def rows(drift: float) -> list[dict]:
    """Three steps exchanging 10 J (gravity turned into motion and back), the last one
    ending at E_0 (1 + drift) by a change of its kinetic energy (|drift| <= 0.2: the
    exchanged energy stays the 10 J of step 2)."""
    e0 = INITIAL["total_energy"]
    out = []
    for step, (kinetic, gravity) in enumerate(((5.0, 5.0), (10.0, 0.0), (8.0, 2.0)), 1):
        if step == 3:
            kinetic += e0 * drift
        out.append({"step": step, "time": 0.01 * step, "kinetic": kinetic, "elastic": 0.0,
                    "gravity": gravity, "total_energy": kinetic + gravity})
    return out


GAIN, LOSS, SMALL = 3 * DAMPED_THRESHOLD, -3 * DAMPED_THRESHOLD, 0.2 * DAMPED_THRESHOLD


@pytest.mark.parametrize("kind, conservative", [("conservative", True), ("damped", False),
                                                ("friction", False), ("moving", False)])
def test_conservative_means_no_damping_friction_or_moving_pin(tmp_path, kind, conservative):
    report = energy_report(rows(SMALL), INITIAL, scene(tmp_path, kind))
    assert report["conservative"] is conservative
    assert not report["flagged"]


@pytest.mark.parametrize("kind", ["conservative", "damped", "friction"])
def test_a_gain_is_flagged_for_every_scene_without_moving_pins(tmp_path, kind):
    s = scene(tmp_path, kind)
    report = energy_report(rows(GAIN), INITIAL, s)
    assert report["drift"] == pytest.approx(GAIN, rel=1e-12)
    assert report["exchanged_energy"] == pytest.approx(10.0, rel=1e-15)
    assert report["gained"] and report["flagged"] and not report["damped"]
    assert "GAINED" in describe_energy(report, s)


@pytest.mark.parametrize("kind, flagged", [("conservative", True), ("damped", False),
                                           ("friction", False), ("moving", False)])
def test_a_loss_is_flagged_only_for_a_conservative_scene(tmp_path, kind, flagged):
    s = scene(tmp_path, kind)
    report = energy_report(rows(LOSS), INITIAL, s)
    assert report["drift"] == pytest.approx(LOSS, rel=1e-12)
    assert report["damped"] is flagged and report["flagged"] is flagged
    assert not report["gained"]
    line = describe_energy(report, s)
    assert ("numerical damping" in line) is flagged


def test_moving_pins_may_gain_energy_unflagged(tmp_path):
    s = scene(tmp_path, "moving")
    report = energy_report(rows(GAIN), INITIAL, s)
    assert not report["flagged"] and not report["gained"]
    assert "not conserved by design" in describe_energy(report, s)


def test_a_turning_handle_is_a_moving_pin(tmp_path):
    """A pin with only an angular velocity moves too: a gain is not flagged."""
    pin = dict(wall_pin(3), angular_velocity=1.0, axis=[1.0, 0.0, 0.0])
    s = make_scene(tmp_path, beam("turning", 3, pin=[pin]))
    report = energy_report(rows(GAIN), INITIAL, s)
    assert not report["conservative"] and not report["flagged"]


def test_below_the_threshold_nothing_is_flagged(tmp_path):
    for drift in (SMALL, -SMALL):
        report = energy_report(rows(drift), INITIAL, scene(tmp_path, "conservative"))
        assert report["drift"] == pytest.approx(drift, rel=1e-12)
        assert not report["flagged"]
