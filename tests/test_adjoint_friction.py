"""Gradients for the friction coefficients (:mod:`fem_anim.adjoint.parameters`).

``obstacle.NAME.friction`` (the lagged friction of an ``[[obstacle]]``: a UFL term
mu D_1, its mu a Constant) and ``contact.friction`` (IPC's lagged friction: ipctk's
D = mu D_1, dR/dmu = w grad D / mu), on the spinning cube sliding on the ground plane and
the IPC cubes, with implicit Euler and BDF2 (Newmark with contact is refused; friction
needs contact, so there is no contact-free case):

* a Taylor test per scene and integrator (first-order remainder at order 1, the
  gradient-corrected one at order >= 1.9; BDF2's slow-marked);
* central differences to 1e-6, next to a material parameter;
* 2 ranks give the serial J and gradient to 1e-8 (this file under ``mpirun -n 2``);
* bad input: a friction the scene lacks or has at 0 is one clear error (``fem-anim fit``:
  one line, exit code 2).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import gradients_on_two_ranks_equal_serial, print_on_rank_zero
from scenes import scene_toml
from test_adjoint import fem_anim_cli, orders, taylor_remainders
from test_adjoint_contact import contacts, cubes_objective, plane_objective
from test_adjoint_initial import spinning_cubes_scene, spinning_plane_scene

import fem_anim
from fem_anim.adjoint.differentiate import AdjointModel
from fem_anim.errors import FemAnimError


def cubes_with_friction(integrator: str) -> dict:
    d = spinning_cubes_scene(integrator)
    d["contact"]["friction"] = 0.3
    return d


SCENES = {"plane": (lambda i: spinning_plane_scene(i, 0.5),
                    ["obstacle.ground.friction", "material.youngs_modulus"], plane_objective),
          "ipc": (cubes_with_friction,
                  ["contact.friction", "body.left.material.youngs_modulus"], cubes_objective)}
#: The Taylor test's direction: a change of mu
DIRECTION = {"plane": 0.2, "ipc": 0.2}
_MODELS: dict = {}


def model_for(scene: str, integrator: str) -> AdjointModel:
    if (scene, integrator) not in _MODELS:
        build, params, _ = SCENES[scene]
        _MODELS[scene, integrator] = AdjointModel(fem_anim.Scene.from_dict(build(integrator)),
                                                  params)
    return _MODELS[scene, integrator]


TAYLOR = [pytest.param(s, i, marks=pytest.mark.slow) if i == "bdf2" else (s, i)
          for s in SCENES for i in ("implicit_euler", "bdf2")]


@pytest.mark.parametrize("scene,integrator", TAYLOR)
def test_taylor_remainders_fall_at_orders_one_and_two(scene, integrator):
    model, obj = model_for(scene, integrator), SCENES[scene][2]()
    theta = model.parameters.values()
    J0, grad = model.evaluate(theta, obj)
    assert sum(contacts(model)) > 0, "the scene makes no contact"
    delta = np.zeros(theta.size)
    delta[0] = DIRECTION[scene]
    first, second = taylor_remainders(model, obj, theta, delta, J0, grad, 0.5, 6)
    assert abs(orders(first)[-1] - 1.0) < 0.1, (first, orders(first))
    assert orders(second)[-1] >= 1.9 and orders(second)[-2] > 1.5, (second, orders(second))


@pytest.mark.parametrize("scene", list(SCENES))
@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2"])
def test_gradient_equals_central_differences(scene, integrator):
    model, obj = model_for(scene, integrator), SCENES[scene][2]()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    fd = []
    for i in range(theta.size):
        eps = 1e-5 * abs(theta[i])
        up, down = theta.copy(), theta.copy()
        up[i] += eps
        down[i] -= eps
        fd.append((model.forward(up, obj) - model.forward(down, obj)) / (2.0 * eps))
    model.parameters.assign(theta)
    fd = theta * np.array(fd)  # sensitivities theta_i dJ/dtheta_i: comparable across units
    assert abs(fd[0]) > 1e-3 * np.abs(fd).max()  # mu does move J (the forward sees it)
    np.testing.assert_allclose(theta * grad, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_friction_parameter_runs_the_scene_with_that_friction():
    model, obj = model_for("ipc", "implicit_euler"), cubes_objective()
    theta = model.parameters.values()
    changed = theta.copy()
    changed[0] = 0.45
    try:
        J = model.forward(changed, obj)
    finally:
        model.parameters.assign(theta)
    d = cubes_with_friction("implicit_euler")
    d["contact"]["friction"] = 0.45
    other = AdjointModel(fem_anim.Scene.from_dict(d), ["body.left.material.youngs_modulus"])
    assert J == pytest.approx(other.forward(None, obj), rel=1e-10)
    assert model.scene["contact"]["friction"] == 0.3  # the scene's table is not changed


@pytest.mark.parametrize("build,params,message", [
    (lambda: spinning_plane_scene("implicit_euler", 0.0), ["obstacle.ground.friction"],
     "friction is 0"),
    (lambda: spinning_plane_scene("implicit_euler", 0.5), ["obstacle.wall.friction"],
     "no obstacle 'wall'"),
    (lambda: spinning_plane_scene("implicit_euler", 0.5), ["contact.friction"],
     "no [contact] section"),
    (lambda: spinning_cubes_scene("implicit_euler"), ["contact.friction"], "friction is 0"),
])
def test_bad_input_is_one_clear_error(build, params, message):
    with pytest.raises(FemAnimError, match=message.replace("[", r"\[").replace("]", r"\]")):
        AdjointModel(fem_anim.Scene.from_dict(build()), params)


def test_assigning_a_nonpositive_friction_is_refused():
    model = model_for("plane", "implicit_euler")
    theta = model.parameters.values()
    bad = theta.copy()
    bad[0] = 0.0
    with pytest.raises(FemAnimError, match="not positive"):
        model.parameters.assign(bad)
    model.parameters.assign(theta)


def test_fit_refuses_a_friction_the_scene_lacks_with_one_line(tmp_path):
    (tmp_path / "scene.toml").write_text(scene_toml(spinning_cubes_scene("implicit_euler")))
    (tmp_path / "ref").mkdir()
    (tmp_path / "ref" / "trajectory.h5").write_bytes(b"")
    r = fem_anim_cli(["fit", "scene.toml", "--target", "ref", "--param",
                      "obstacle.ground.friction", "-o", "fit", "-q"], tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fem-anim: error: "), r.stderr
    assert "no obstacle 'ground'" in lines[0], lines[0]


def mpi_gradients() -> dict:
    """J and the gradient of both scenes (BDF2) on any number of ranks."""
    out = {}
    for scene in SCENES:
        model = model_for(scene, "bdf2")
        J, grad = model.evaluate(model.parameters.values(), SCENES[scene][2]())
        out[scene] = {"J": J, "grad": list(map(float, grad))}
    return out


@pytest.mark.mpi
def test_two_ranks_give_the_serial_gradient():
    gradients_on_two_ranks_equal_serial(__file__, mpi_gradients)


if __name__ == "__main__":
    print_on_rank_zero(mpi_gradients())
