"""Gradients for a handle's velocity (``pin.NAME.velocity``, :mod:`fem_anim.adjoint`).

A moving pin prescribes its nodes' displacement u_D(t) = (rotation part) + velocity
min(t, until): the velocity moves the pinned values of every step's solution (and, with
Newmark, the handle's exact rates put into v). On the beam of ``test_adjoint`` whose pinned
end is a handle (translating and turning), damped, on implicit Euler, BDF2 and Newmark, and
on the cube on the ground plane dragged by a handle on its top face (implicit Euler and
BDF2: Newmark with contact is refused):

* a Taylor test (first-order remainder at order 1, gradient-corrected at order >= 1.9;
  the plane's BDF2 slow-marked);
* central differences to 1e-6, also for a handle that stops (``until``) within the run;
* the velocity set in the model runs what the scene with it runs;
* 2 ranks give the serial J and gradient to 1e-8 (this file under ``mpirun -n 2``);
* bad input: a pin the scene lacks, a pin that does not move, a handle with IPC contact:
  one clear error (``fem-anim fit``: one line, exit code 2).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import gradients_on_two_ranks_equal_serial, print_on_rank_zero
from scenes import scene_toml
from test_adjoint import (central_differences, fem_anim_cli, objective, orders, scene_dict,
                         taylor_remainders)
from test_adjoint_contact import contacts, cubes_scene, plane_objective, plane_scene

import fem_anim
from fem_anim.adjoint.differentiate import AdjointModel
from fem_anim.errors import FemAnimError

HANDLE = ["pin.grip.velocity", "material.youngs_modulus"]
DIRECTION = {"pin.grip.velocity[0]": 0.1, "pin.grip.velocity[1]": -0.05,
             "pin.grip.velocity[2]": 0.08}


def beam_scene(integrator: str, until: float | None = None) -> dict:
    d = scene_dict(integrator, damped=True)
    d["pin"][0] |= {"name": "grip", "velocity": [0.2, 0.0, 0.3], "angular_velocity": 2.0,
                    "axis": [1.0, 0.0, 0.0]}
    if until is not None:
        d["pin"][0]["until"] = until
    return d


def dragged_plane_scene(integrator: str) -> dict:
    """The cube on the ground plane (friction 0.5), its top face dragged sideways and down."""
    d = plane_scene(integrator, friction=0.5, epsv=0.2)
    d["pin"] = [{"name": "grip", "min": [-1.0, -1.0, 0.2], "max": [1.0, 1.0, 1.0],
                 "velocity": [0.3, 0.1, -0.05]}]
    return d


SCENES = {"beam": (beam_scene, objective), "plane": (dragged_plane_scene, plane_objective)}
_MODELS: dict = {}


def model_for(scene: str, integrator: str) -> AdjointModel:
    if (scene, integrator) not in _MODELS:
        build, _ = SCENES[scene]
        _MODELS[scene, integrator] = AdjointModel(fem_anim.Scene.from_dict(build(integrator)),
                                                  HANDLE)
    return _MODELS[scene, integrator]


TAYLOR = [("beam", i) for i in ("implicit_euler", "bdf2", "newmark")] + \
    [("plane", "implicit_euler"), pytest.param("plane", "bdf2", marks=pytest.mark.slow)]


@pytest.mark.parametrize("scene,integrator", TAYLOR)
def test_taylor_remainders_fall_at_orders_one_and_two(scene, integrator):
    model, obj = model_for(scene, integrator), SCENES[scene][1]()
    theta = model.parameters.values()
    J0, grad = model.evaluate(theta, obj)
    if scene == "plane":
        assert sum(contacts(model)) > 0, "the scene makes no contact"
    delta = np.array([DIRECTION.get(n, 0.0) for n in model.names])
    first, second = taylor_remainders(model, obj, theta, delta, J0, grad, 0.5, 6)
    assert abs(orders(first)[-1] - 1.0) < 0.1, (first, orders(first))
    assert orders(second)[-1] >= 1.9 and orders(second)[-2] > 1.5, (second, orders(second))


@pytest.mark.parametrize("scene,integrator", [
    ("beam", "implicit_euler"), ("beam", "bdf2"), ("beam", "newmark"),
    ("plane", "implicit_euler"), ("plane", "bdf2")])
def test_gradient_equals_central_differences(scene, integrator):
    model, obj = model_for(scene, integrator), SCENES[scene][1]()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    fd = central_differences(model, obj, theta)
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("integrator", ["bdf2", "newmark"])
def test_a_handle_that_stops_within_the_run(integrator):
    """``until`` = 0.05 s of the run's 0.1 s: from then on u_D is constant in the velocity
    (the handle rests), and Newmark's rates are zero."""
    model = AdjointModel(fem_anim.Scene.from_dict(beam_scene(integrator, until=0.05)), HANDLE)
    obj = objective()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    fd = central_differences(model, obj, theta)
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_handle_parameter_runs_the_scene_with_that_velocity():
    model, obj = model_for("beam", "newmark"), objective()
    theta = model.parameters.values()
    changed = theta.copy()
    changed[:3] = [0.1, -0.2, 0.4]
    try:
        J = model.forward(changed, obj)
    finally:
        model.parameters.assign(theta)
    d = beam_scene("newmark")
    d["pin"][0]["velocity"] = [0.1, -0.2, 0.4]
    other = AdjointModel(fem_anim.Scene.from_dict(d), ["material.youngs_modulus"])
    assert J == pytest.approx(other.forward(None, obj), rel=1e-12)
    assert model.parameters.scene_values()["pin.grip.velocity"] == [0.2, 0.0, 0.3]


def test_bad_input_is_one_clear_error():
    d = beam_scene("implicit_euler")
    with pytest.raises(FemAnimError, match="no pin 'pin.hand'"):
        AdjointModel(fem_anim.Scene.from_dict(d), ["pin.hand.velocity"])
    with pytest.raises(FemAnimError, match="not a parameter"):
        AdjointModel(fem_anim.Scene.from_dict(d), ["pin.grip.velocity[3]"])
    d = scene_dict("implicit_euler", damped=False)
    d["pin"][0]["name"] = "grip"
    with pytest.raises(FemAnimError, match="does not move"):
        AdjointModel(fem_anim.Scene.from_dict(d), ["pin.grip.velocity"])


def test_fit_refuses_a_handle_with_ipc_contact_with_one_line(tmp_path):
    d = cubes_scene("implicit_euler")
    d["body"][0]["pin"] = [{"name": "grip", "min": [-1.0, -1.0, -1.0], "max": [1.0, 1.0, 1.0],
                            "velocity": [0.1, 0.0, 0.0]}]
    (tmp_path / "scene.toml").write_text(scene_toml(d))
    (tmp_path / "ref").mkdir()
    (tmp_path / "ref" / "trajectory.h5").write_bytes(b"")
    r = fem_anim_cli(["fit", "scene.toml", "--target", "ref", "--param",
                      "body.left.pin.grip.velocity", "-o", "fit", "-q"], tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fem-anim: error: "), r.stderr
    assert "with IPC contact" in lines[0], lines[0]


def mpi_gradients() -> dict:
    out = {}
    for scene, integrator in (("beam", "newmark"), ("plane", "implicit_euler")):
        model = model_for(scene, integrator)
        J, grad = model.evaluate(model.parameters.values(), SCENES[scene][1]())
        out[scene] = {"J": J, "grad": list(map(float, grad))}
    return out


@pytest.mark.mpi
def test_two_ranks_give_the_serial_gradient():
    gradients_on_two_ranks_equal_serial(__file__, mpi_gradients)


if __name__ == "__main__":
    print_on_rank_zero(mpi_gradients())
