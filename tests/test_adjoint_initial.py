"""Gradients for the initial state: spin and displacement (:mod:`fem_anim.adjoint.parameters`).

Parameters: ``initial.angular_velocity`` (the spin about the centre of mass, v_0 linear in
it: omega x (X - c)), ``initial.displacement`` (a rigid translation u_0 of the unpinned
nodes) and a body's ``body.NAME.initial.*``; and a region's density while the body spins
(the centre of mass moves with it: dv_0/drho = -omega x dc/drho). For each:

* on the pinned beam of ``test_adjoint`` with a denser tip region, spinning, damped, on
  implicit Euler, BDF2 and Newmark: a Taylor test per kind (the first-order remainder at
  order 1, the gradient-corrected one at order >= 1.9) and central differences to 1e-6;
* with contact (implicit Euler and BDF2; Newmark with contact is refused): the cube on the
  obstacle plane (barrier, and lagged friction) and the IPC cubes (a body's spin and
  displacement), a Taylor test each (BDF2's slow-marked) and central differences to 1e-6;
* a plane-strain strip (2D: the spin is one number) against central differences;
* the spin set in the model runs what the scene with that spin runs;
* a per-node u_0 and v_0 (``AdjointModel.set_initial_fields``) and their gradient
  (``initial_gradient``): a Taylor test along a smooth field, without and with contact, and
  its sums over the rigid fields are the rigid parameters' gradients;
* 2 ranks give the serial J and gradient to 1e-8 (this file run under ``mpirun -n 2``);
* bad input: one clear error (``fem-anim fit``: one line, exit code 2).
"""

from __future__ import annotations

import numpy as np
import pytest
from conftest import gradients_on_two_ranks_equal_serial, print_on_rank_zero
from scenes import scene_toml
from test_adjoint import fem_anim_cli, objective, orders, taylor_remainders
from test_adjoint_contact import contacts, cubes_objective, cubes_scene, plane_objective, \
    plane_scene
from test_adjoint_parameters import region_scene

import fem_anim
from fem_anim.adjoint.differentiate import AdjointModel
from fem_anim.adjoint.objectives import CentreOfMassTarget, PointTarget
from fem_anim.errors import FemAnimError

SPIN = [0.5, -0.4, 0.3]
BEAM = ["initial.angular_velocity", "initial.displacement", "region.tip.material.density",
        "material.density"]
PLANE = ["initial.angular_velocity", "initial.displacement", "material.youngs_modulus"]
CUBES = ["body.left.initial.angular_velocity", "body.right.initial.displacement",
         "body.right.initial.angular_velocity"]
#: A direction per parameter kind (per parameter name suffix), and its scale per scene
KINDS = {"spin": {"initial.angular_velocity[0]": 0.3, "initial.angular_velocity[1]": -0.2,
                  "initial.angular_velocity[2]": 0.4},
         "displacement": {"initial.displacement[0]": 0.01, "initial.displacement[1]": -0.02,
                          "initial.displacement[2]": 0.015},
         "centre_of_mass": {"region.tip.material.density": 200.0}}
SCALE = {"beam": 1.0, "plane": 0.5, "plane_friction": 0.25, "ipc": 0.5}
#: ... and a displacement's with contact: a millimetre against d_hat = 5 mm
CONTACT_DISPLACEMENT = 0.1


def beam_scene(integrator: str) -> dict:
    """The pinned beam with a tip region of 800 kg/m^3 (the rest: 1000), spinning."""
    d = region_scene(integrator)
    d["initial"]["angular_velocity"] = list(SPIN)
    return d


def spinning_plane_scene(integrator: str, friction: float = 0.0) -> dict:
    """The cube on the ground plane, spinning; with friction eps_v = 0.2 m/s: with 0.02 the
    slip of a contact point crosses eps_v h (where friction's f1 is C^1 only) within
    1e-5 m of the initial displacement, and central differences at that step were 4e-2
    from their limit (which is the adjoint's: 1e-7 m steps agreed to 3e-5)."""
    d = plane_scene(integrator, friction=friction, epsv=0.2 if friction else 0.02)
    d["initial"]["angular_velocity"] = [0.0, 0.5, 0.2]
    return d


def spinning_cubes_scene(integrator: str) -> dict:
    d = cubes_scene(integrator)
    d["body"][0]["initial"]["angular_velocity"] = [0.0, 0.0, 2.0]
    return d


SCENES = {"beam": (beam_scene, BEAM, objective),
          "plane": (spinning_plane_scene, PLANE, plane_objective),
          "plane_friction": (lambda i: spinning_plane_scene(i, 0.5), PLANE, plane_objective),
          "ipc": (spinning_cubes_scene, CUBES, cubes_objective)}
_MODELS: dict = {}


def model_for(scene: str, integrator: str) -> AdjointModel:
    if (scene, integrator) not in _MODELS:
        build, params, _ = SCENES[scene]
        _MODELS[scene, integrator] = AdjointModel(fem_anim.Scene.from_dict(build(integrator)),
                                                  params)
    return _MODELS[scene, integrator]


def direction(model: AdjointModel, kind: str) -> np.ndarray:
    return np.array([next((v for k, v in KINDS[kind].items() if name.endswith(k)), 0.0)
                     for name in model.names])


def central_differences(model, obj, theta) -> np.ndarray:
    out = []
    for i, name in enumerate(model.names):
        # a displacement: 1e-7 m (the barrier curves J strongly in it: at 1e-6 m the
        # differences' truncation error on the cube with friction was 1.3e-6 relative)
        eps = 1e-7 if "displacement" in name else 1e-5 * max(abs(theta[i]), 0.1)
        up, down = theta.copy(), theta.copy()
        up[i] += eps
        down[i] -= eps
        out.append((model.forward(up, obj) - model.forward(down, obj)) / (2.0 * eps))
    model.parameters.assign(theta)
    return np.array(out)


TAYLOR = [("beam", i, k) for i in ("implicit_euler", "bdf2", "newmark") for k in KINDS] + \
    [pytest.param(s, i, k, marks=pytest.mark.slow) if i == "bdf2" else (s, i, k)
     for s in ("plane", "plane_friction", "ipc") for i in ("implicit_euler", "bdf2")
     for k in ("spin", "displacement")]


@pytest.mark.parametrize("scene,integrator,kind", TAYLOR)
def test_taylor_remainders_fall_at_orders_one_and_two(scene, integrator, kind):
    model, obj = model_for(scene, integrator), SCENES[scene][2]()
    theta = model.parameters.values()
    J0, grad = model.evaluate(theta, obj)
    if scene != "beam":
        assert sum(contacts(model)) > 0, "the scene makes no contact"
    delta = SCALE[scene] * direction(model, kind)
    if scene != "beam" and kind == "displacement":
        delta *= CONTACT_DISPLACEMENT
    assert np.any(delta)
    first, second = taylor_remainders(model, obj, theta, delta, J0, grad, 0.5, 6)
    assert abs(orders(first)[-1] - 1.0) < 0.1, (first, orders(first))
    assert orders(second)[-1] >= 1.9 and orders(second)[-2] > 1.5, (second, orders(second))


FD = [("beam", i) for i in ("implicit_euler", "bdf2", "newmark")] + \
    [(s, i) for s in ("plane", "plane_friction", "ipc") for i in ("implicit_euler", "bdf2")]


@pytest.mark.parametrize("scene,integrator", FD)
def test_gradient_equals_central_differences(scene, integrator):
    model, obj = model_for(scene, integrator), SCENES[scene][2]()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    scale = np.maximum(np.abs(theta), 0.1)  # sensitivities: comparable across units
    fd = scale * central_differences(model, obj, theta)
    np.testing.assert_allclose(scale * grad, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def smooth_field(model, scale: float) -> np.ndarray:
    """A smooth per-node field (the same at a node on every rank: from its coordinates)."""
    X = model.problem.V.tabulate_dof_coordinates()[:, : model.problem.d]
    field = np.stack([np.sin(3.0 * X[:, 0] + k) * np.cos(2.0 * X[:, 1] - k)
                      for k in range(model.problem.d)], axis=1)
    return scale * field.reshape(-1)


NODAL = [("beam", i) for i in ("implicit_euler", "bdf2", "newmark")] + \
    [("plane", "implicit_euler"), ("plane_friction", "bdf2")]


@pytest.mark.parametrize("scene,integrator", NODAL)
@pytest.mark.parametrize("field,scale", [("u", 0.01), ("v", 0.3)])
def test_per_node_initial_state_taylor(scene, integrator, field, scale):
    """``set_initial_fields`` adds a per-node u_0 or v_0; ``initial_gradient`` is its
    gradient: a Taylor test along a smooth field."""
    model, obj = model_for(scene, integrator), SCENES[scene][2]()
    theta = model.parameters.values()
    J0, _ = model.evaluate(theta, obj)
    grad = model.initial_gradient[field].copy()
    delta = smooth_field(model, scale * (SCALE[scene] if scene != "beam" else 1.0) *
                         (CONTACT_DISPLACEMENT if scene != "beam" and field == "u" else 1.0))
    slope = model.sweep.dot(grad, delta)
    first, second = [], []
    try:
        for k in range(5):
            eps = 0.5 ** (k + 1)
            model.set_initial_fields(**{field: eps * delta})
            J = model.forward(theta, obj)
            first.append(J - J0)
            second.append(J - J0 - eps * slope)
    finally:
        model.set_initial_fields()
    assert abs(orders(first)[-1] - 1.0) < 0.1, (first, orders(first))
    assert orders(second)[-1] >= 1.9 and orders(second)[-2] > 1.5, (second, orders(second))


def test_per_node_gradient_holds_the_rigid_ones():
    """dJ/d(initial.displacement[i]) is dJ/du_0 summed over the unpinned nodes' i-th
    components (the rigid field of component i)."""
    model, obj = model_for("beam", "bdf2"), objective()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    G = model.initial_gradient
    for i in range(3):
        e = np.zeros((G["u"].size // 3, 3))
        e[:, i] = 1.0
        rigid = model.sweep.dot(G["u"], e.reshape(-1))
        assert rigid == pytest.approx(grad[model.names.index(f"initial.displacement[{i}]")],
                                      rel=1e-10)
    with pytest.raises(FemAnimError, match="shape"):
        model.set_initial_fields(u=np.zeros(5))


def test_spin_in_2d_is_one_number():
    d = {"mesh": {"dim": 2, "size": [1.0, 0.2], "divisions": [16, 2]},
         "material": {"youngs_modulus": 1.0e4, "poisson_ratio": 0.3, "density": 1000.0},
         "time": {"steps": 5, "dt": 0.02, "integrator": "bdf2"}, "output": {"render": False},
         "gravity": {"acceleration": [0.0, -9.81]},
         "initial": {"velocity": [0.0, 0.3], "angular_velocity": 0.8},
         "damping": {"alpha": 0.5, "beta": 1.0e-3},
         "pin": [{"min": [-0.01, -1.0], "max": [0.01, 1.0]}]}
    model = AdjointModel(fem_anim.Scene.from_dict(d), ["initial.angular_velocity",
                                                       "initial.displacement"])
    assert model.names == ["initial.angular_velocity", "initial.displacement[0]",
                           "initial.displacement[1]"]
    assert model.parameters.scene_values() == {"initial.angular_velocity": 0.8,
                                               "initial.displacement": [0.0, 0.0]}
    obj = PointTarget([1.0, 0.2], [[1.0, 0.1]], [0.1]) + CentreOfMassTarget([[0.5, 0.05]],
                                                                            [0.06])
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    fd = central_differences(model, obj, theta)
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


@pytest.mark.parametrize("integrator", ["bdf2", "newmark"])
def test_spin_parameter_runs_the_scene_with_that_spin(integrator):
    """The spin and the tip's density set in the model run what the scene with those values
    runs (the same centre of mass, moved by the density)."""
    model, obj = model_for("beam", integrator), objective()
    theta = model.parameters.values()
    changed = theta.copy()
    changed[:3] = [-0.2, 0.6, 0.1]
    changed[6] = 500.0  # region.tip.material.density
    J = model.forward(changed, obj)
    model.parameters.assign(theta)
    d = beam_scene(integrator)
    d["initial"]["angular_velocity"] = [-0.2, 0.6, 0.1]
    d["region"][0]["density"] = 500.0
    other = AdjointModel(fem_anim.Scene.from_dict(d), ["material.density"])
    assert J == pytest.approx(other.forward(None, obj), rel=1e-10)


@pytest.mark.parametrize("change,params,message", [
    ({"initial": None}, ["initial.angular_velocity"], "no [initial] section"),
    ({}, ["body.left.initial.displacement"], "no body 'left'"),
    ({}, ["region.tip.initial.displacement"], "not a parameter"),
    ({}, ["initial.angular_velocity[3]"], "not a parameter"),
    ({}, ["initial.displacement[x]"], "not a parameter"),
])
def test_bad_input_is_one_clear_error(change, params, message):
    d = beam_scene("implicit_euler")
    for key, value in change.items():
        d.pop(key) if value is None else d.__setitem__(key, value)
    with pytest.raises(FemAnimError, match=message.replace("[", r"\[").replace("]", r"\]")):
        AdjointModel(fem_anim.Scene.from_dict(d), params)


@pytest.mark.parametrize("params,message", [
    (["body.middle.initial.angular_velocity"], "no body 'middle'"),
    (["initial.displacement"], "own initial velocities and displacements"),
    (["body.left.initial.angular_velocity[1]", "body.left.initial.angular_velocity"],
     "named twice"),
])
def test_fit_refuses_a_parameter_the_scene_lacks_with_one_line(tmp_path, params, message):
    (tmp_path / "scene.toml").write_text(scene_toml(spinning_cubes_scene("implicit_euler")))
    (tmp_path / "ref").mkdir()
    (tmp_path / "ref" / "trajectory.h5").write_bytes(b"")
    args = [a for p in params for a in ("--param", p)]
    r = fem_anim_cli(["fit", "scene.toml", "--target", "ref", *args, "-o", "fit", "-q"],
                     tmp_path)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fem-anim: error: "), r.stderr
    assert message in lines[0], lines[0]


def mpi_gradients() -> dict:
    """J and the gradient of the spinning beam (Newmark) and the IPC cubes (implicit Euler)
    on any number of ranks."""
    out = {}
    for scene, integrator in (("beam", "newmark"), ("ipc", "implicit_euler")):
        model = model_for(scene, integrator)
        J, grad = model.evaluate(model.parameters.values(), SCENES[scene][2]())
        nodal = [model.sweep.dot(model.initial_gradient[k], smooth_field(model, 1.0))
                 for k in ("u", "v")]
        out[scene] = {"J": J, "grad": list(map(float, grad)) + nodal}
    return out


@pytest.mark.mpi
def test_two_ranks_give_the_serial_gradient():
    gradients_on_two_ranks_equal_serial(__file__, mpi_gradients)


if __name__ == "__main__":
    print_on_rank_zero(mpi_gradients())
