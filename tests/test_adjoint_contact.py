"""Gradients through contact (:mod:`fem_anim.adjoint`).

Contact scenes: a cube dropped at an angle onto an obstacle plane (barrier only, and with
lagged friction), and two cubes thrown at each other with IPC contact at a fixed barrier
stiffness (barrier only, and with lagged friction), each with implicit Euler and BDF2;
every term, the lagged friction's dependence on the step's start included, is
differentiated. For each:

* a Taylor test per parameter kind (per-body E, nu, density and initial velocity for the
  cubes): |J(theta + eps delta) - J(theta)| falls at order 1,
  |J(theta + eps delta) - J(theta) - eps dJ . delta| at order >= 1.9 (BDF2's: slow-marked);
* the gradient equals central finite differences to 1e-6 (relative to its largest
  component: the cubes' spin-free z velocity is zero up to round-off);
* 2 ranks give the serial J and gradient to 1e-8.

The barrier is C^2 where a point enters d_hat (b, b', b'' vanish there) and the friction's
f0 is C^2 where the slip passes eps_v h, so points and pairs entering or leaving d_hat do
not break the discrete map's smoothness; IPC's kappa does (it is piecewise constant in the
parameters with the adaptive schedule): the perturbations here (at most 5 % of a value)
keep every step's kappa (asserted; the scenes use a fixed kappa anyway).

Also: a body's parameters set in the model run what the scene with those values runs, and
the refusals (Newmark with contact, a body the scene lacks, scene-wide keys in a scene of
bodies) are one line from ``fem-anim fit``, exit code 2.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import ROOT, clean_environment, mpirun_command
from scenes import scene_toml
from test_adjoint import central_differences, fem_anim_cli, orders, taylor_remainders

import fem_anim
from fem_anim.adjoint.differentiate import AdjointModel
from fem_anim.adjoint.objectives import CentreOfMassTarget, PointTarget
from fem_anim.errors import FemAnimError

MATERIAL = ["material.youngs_modulus", "material.poisson_ratio", "material.density",
            "initial.velocity"]
BODY = ["body.left.material.youngs_modulus", "body.right.material.poisson_ratio",
        "body.right.material.density", "body.left.initial.velocity"]


def plane_scene(integrator: str, friction: float = 0.0, steps: int = 8,
                epsv: float = 0.02) -> dict:
    """A 0.2 m cube of 48 tetrahedra, 4 mm above the ground plane, thrown down and sideways:
    its bottom enters d_hat = 5 mm in the first step and stays in contact."""
    return {"name": "drop",
            "mesh": {"dim": 3, "size": [0.2, 0.2, 0.2], "origin": [-0.1, -0.1, 0.004],
                     "divisions": [2, 2, 2]},
            "material": {"youngs_modulus": 1.0e4, "poisson_ratio": 0.3, "density": 1000.0},
            "time": {"steps": steps, "dt": 0.01, "integrator": integrator},
            "output": {"render": False}, "gravity": {"acceleration": [0.0, 0.0, -9.81]},
            "initial": {"velocity": [0.3, 0.0, -0.4]},
            "obstacle": [{"name": "ground", "type": "plane", "normal": [0, 0, 1],
                          "dhat": 0.005, "stiffness": 1.0e4, "friction": friction,
                          "epsv": epsv}]}


def cubes_scene(integrator: str, friction: float = 0.0, steps: int = 8,
                stiffness="1e4") -> dict:
    """Two 0.1 m cubes (6 tetrahedra each), the right one turned 10 degrees, thrown at each
    other: IPC contact from the second step on."""
    return {"name": "cubes", "time": {"steps": steps, "dt": 0.01, "integrator": integrator},
            "output": {"render": False},
            "contact": {"dhat": 0.005, "stiffness": stiffness if stiffness == "adaptive"
                        else float(stiffness), "friction": friction},
            "body": [{"name": "left", "offset": [-0.11, 0, 0],
                      "mesh": {"shape": "box", "size": [0.1, 0.1, 0.1], "element_size": 0.1},
                      "material": {"youngs_modulus": 1e4, "density": 1000},
                      "initial": {"velocity": [0.6, 0.2, 0]}},
                     {"name": "right", "offset": [0.03, 0.0, 0], "rotation": [0, 0, 10],
                      "mesh": {"shape": "box", "size": [0.1, 0.1, 0.1], "element_size": 0.1},
                      "material": {"youngs_modulus": 2e4, "density": 800},
                      "initial": {"velocity": [-0.6, 0, 0]}}]}


def plane_objective():
    return PointTarget([0.1, 0.1, 0.004], [[0.15, 0.1, 0.0]], [0.08]) + \
        CentreOfMassTarget([[0.02, 0.0, 0.09]], [0.06])


def cubes_objective():
    return CentreOfMassTarget([[0.0, 0.02, 0.05]], [0.08]) + \
        PointTarget([-0.01, 0.05, 0.05], [[0.0, 0.06, 0.05]], [0.06])


SCENES = {"plane": (plane_scene, MATERIAL, plane_objective),
          "plane_friction": (lambda i: plane_scene(i, friction=0.5), MATERIAL, plane_objective),
          "ipc": (cubes_scene, BODY, cubes_objective),
          "ipc_friction": (lambda i: cubes_scene(i, friction=0.3), BODY, cubes_objective)}
#: A direction per parameter kind (per parameter name suffix)
KINDS = {"youngs_modulus": {"material.youngs_modulus": 500.0},
         "poisson_ratio": {"material.poisson_ratio": 0.015},
         "density": {"material.density": 40.0},
         "initial_velocity": {"initial.velocity[0]": 0.04, "initial.velocity[1]": -0.03,
                              "initial.velocity[2]": 0.02}}
#: The directions' scale per scene: sticking friction (a stiff viscous law below a slip
#: of eps_v h) curves J strongly, so its Taylor test needs smaller steps to be asymptotic
SCALE = {"plane": 1.0, "plane_friction": 0.5, "ipc": 0.5, "ipc_friction": 0.5}
_MODELS: dict = {}


def model_for(scene: str, integrator: str) -> AdjointModel:
    key = (scene, integrator)
    if key not in _MODELS:
        build, params, _ = SCENES[scene]
        _MODELS[key] = AdjointModel(fem_anim.Scene.from_dict(build(integrator)), params)
    return _MODELS[key]


def contacts(model: AdjointModel) -> list[int]:
    """Per step: how many obstacle contact points or IPC pairs are within d_hat."""
    p, tape, out = model.problem, model.tape, []
    for n in range(1, tape.steps + 1):
        p.u.x.array[:] = tape.states[n].u
        if p.ipc is not None:
            p.ipc._update()
            out.append(p.comm.bcast(p.ipc.num_pairs, root=0))
        else:
            x, _ = p.contact._evaluate()
            out.append(int(np.sum(p.contact._distances(x)[0] < 0.005)))
    return out


def direction(model: AdjointModel, kind: str) -> np.ndarray:
    return np.array([next((v for k, v in KINDS[kind].items() if name.endswith(k)), 0.0)
                     for name in model.names])


CASES = [(s, i) for s in SCENES for i in ("implicit_euler", "bdf2")]
#: The Taylor tests with BDF2 are slow-marked (the default run keeps implicit Euler's and
#: BDF2's central differences)
TAYLOR_CASES = [pytest.param(s, i, marks=pytest.mark.slow) if i == "bdf2" else (s, i)
                for s, i in CASES]


@pytest.mark.parametrize("scene,integrator", TAYLOR_CASES)
@pytest.mark.parametrize("kind", list(KINDS))
def test_contact_taylor_remainders_fall_at_orders_one_and_two(scene, integrator, kind):
    model, obj = model_for(scene, integrator), SCENES[scene][2]()
    theta = model.parameters.values()
    J0, grad = model.evaluate(theta, obj)
    assert sum(contacts(model)) > 0, "the scene makes no contact"
    delta = SCALE[scene] * direction(model, kind)
    first, second = taylor_remainders(model, obj, theta, delta, J0, grad, 1.0, 6)
    assert abs(orders(first)[-1] - 1.0) < 0.1, (first, orders(first))
    # asymptotic: the largest steps cross the C^1 seams of IPC's distance types
    assert orders(second)[-1] >= 1.9 and orders(second)[-2] > 1.5, (second, orders(second))


@pytest.mark.parametrize("scene,integrator", CASES)
def test_contact_gradient_equals_central_differences(scene, integrator):
    model, obj = model_for(scene, integrator), SCENES[scene][2]()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    fd = central_differences(model, obj, theta)
    # a component 1e6 below the largest (the cubes' spin-free z velocity) is FD noise
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_body_parameters_are_the_scenes_values():
    """Setting a body's parameters in the model runs what the scene with those values runs
    (the left body's velocity on its own dofs only; the right body's density on its cells)."""
    model, obj = model_for("ipc", "implicit_euler"), cubes_objective()
    theta = model.parameters.values()
    changed = theta.copy()
    changed[2] = 700.0  # body.right.material.density
    changed[3:6] = [0.5, 0.1, 0.05]  # body.left.initial.velocity
    J = model.forward(changed, obj)
    model.parameters.assign(theta)
    d = cubes_scene("implicit_euler")
    d["body"][1]["material"]["density"] = 700.0
    d["body"][0]["initial"]["velocity"] = [0.5, 0.1, 0.05]
    other = AdjointModel(fem_anim.Scene.from_dict(d), BODY)
    assert J == pytest.approx(other.forward(None, obj), rel=1e-9)


@pytest.mark.parametrize("change,message", [
    ({"time": {"steps": 2, "dt": 0.01, "integrator": "newmark"}}, "with contact"),
    ({"param": ["body.middle.material.density"]}, "no body 'middle'"),
    ({"param": ["body.left.initial.velocity", "initial.velocity"]}, "own initial velocities"),
    ({"param": ["material.youngs_modulus"]}, "own materials"),
])
def test_bad_contact_input_is_one_line(tmp_path, change, message):
    """``fem-anim fit`` refuses with one line and exit code 2 (before reading the target:
    its trajectory file here is empty)."""
    d = cubes_scene("implicit_euler")
    params = change.pop("param", ["body.left.material.youngs_modulus"])
    d |= change
    (tmp_path / "scene.toml").write_text(scene_toml(d))
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
    """J and the gradient of the obstacle scene and the IPC cubes, both with friction
    (BDF2), on any number of ranks."""
    out = {}
    for scene in ("plane_friction", "ipc_friction"):
        model = model_for(scene, "bdf2")
        J, grad = model.evaluate(model.parameters.values(), SCENES[scene][2]())
        out[scene] = {"J": J, "grad": list(map(float, grad))}
    return out


@pytest.mark.mpi
def test_contact_gradients_on_two_ranks_equal_serial():
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    r = subprocess.run([*mpirun, sys.executable, __file__], capture_output=True, text=True,
                       timeout=900, env=clean_environment(), cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    parallel = json.loads(r.stdout.strip().splitlines()[-1])
    serial = mpi_gradients()
    for scene, result in serial.items():
        assert parallel[scene]["J"] == pytest.approx(result["J"], rel=1e-8), scene
        np.testing.assert_allclose(parallel[scene]["grad"], result["grad"], rtol=1e-8,
                                   atol=1e-8 * np.abs(result["grad"]).max())


if __name__ == "__main__":
    from mpi4py import MPI

    result = mpi_gradients()
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(result))
