"""Gradients through the simulation (:mod:`fem_anim.adjoint`): the discrete adjoint is the
derivative of the discrete forward run.

For each integrator (implicit Euler, BDF2, Newmark; damped and undamped) and each parameter
kind (Young's modulus, Poisson's ratio, density, initial velocity):

* a Taylor test: along a direction delta, |J(theta + eps delta) - J(theta)| falls at order 1
  and |J(theta + eps delta) - J(theta) - eps dJ . delta| at order >= 1.9;
* the gradient equals central finite differences to 1e-6 relative;

the objectives (point targets, centre of mass, a reference run's trajectory, Python
callables, UFL forms) likewise; 2 ranks give the serial gradient to 1e-8 (this file run
under ``mpirun -n 2`` as a script, with point targets and a reference run's trajectory);
bad input is one clear error.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import ufl
from conftest import ROOT, clean_environment, fem_anim_command, mpirun_command
from scenes import scene_toml

import fem_anim
from fem_anim.adjoint.differentiate import AdjointModel
from fem_anim.adjoint.objectives import (CentreOfMassTarget, FormFunctional, PointTarget,
                                         StateFunctional, TrajectoryMatch)
from fem_anim.errors import ConvergenceError, FemAnimError

PARAMS = ["material.youngs_modulus", "material.poisson_ratio", "material.density",
          "initial.velocity"]
#: A direction per parameter kind: (names, step relative to the value or absolute)
KINDS = {"youngs_modulus": {"material.youngs_modulus": 2.0e3},
         "poisson_ratio": {"material.poisson_ratio": 0.05},
         "density": {"material.density": 200.0},
         "initial_velocity": {"initial.velocity[0]": 0.2, "initial.velocity[1]": -0.3,
                              "initial.velocity[2]": 0.4}}


def scene_dict(integrator: str, damped: bool = True, steps: int = 5) -> dict:
    """A pinned 1 x 0.2 x 0.2 m beam of 144 tetrahedra, thrown sideways under gravity."""
    d = {"mesh": {"dim": 3, "size": [1.0, 0.2, 0.2], "divisions": [6, 2, 2]},
         "material": {"youngs_modulus": 1.0e4, "poisson_ratio": 0.3, "density": 1000.0},
         "time": {"steps": steps, "dt": 0.02, "integrator": integrator},
         "output": {"render": False}, "gravity": {"acceleration": [0.0, 0.0, -9.81]},
         "initial": {"velocity": [0.0, 0.3, 0.1]},
         "pin": [{"min": [-0.01, -1.0, -1.0], "max": [0.01, 1.0, 1.0]}]}
    if damped:
        d["damping"] = {"alpha": 0.5, "beta": 1.0e-3}
    return d


def objective():
    """Two point targets at two times and the centre of mass at the end."""
    return PointTarget([1.0, 0.2, 0.2], [[1.0, 0.25, 0.1], [0.95, 0.2, 0.0]], [0.06, 0.1]) + \
        CentreOfMassTarget([[0.5, 0.12, 0.05]], [0.1])


CASES = [("implicit_euler", False), ("implicit_euler", True), ("bdf2", True),
         ("newmark", False), ("newmark", True)]
_MODELS: dict = {}


def model_for(integrator: str, damped: bool) -> AdjointModel:
    key = (integrator, damped)
    if key not in _MODELS:
        _MODELS[key] = AdjointModel(fem_anim.Scene.from_dict(scene_dict(integrator, damped)),
                                    PARAMS)
    return _MODELS[key]


def orders(values: list[float]) -> np.ndarray:
    """Observed orders of remainders at eps, eps/2, eps/4, ... (the last: the smallest eps)."""
    r = np.abs(np.asarray(values))
    return np.log2(r[:-1] / r[1:])


def taylor_remainders(model, obj, theta, delta, J0, grad, largest: float,
                      count: int) -> tuple[list[float], list[float]]:
    """J's remainders along ``delta`` from ``theta``, |J - J0| and |J - J0 - eps grad.delta|,
    at eps = largest, largest/2, ... (``count`` of them); the parameters are put back after
    each forward run (the models are shared between tests), and every run keeps the base
    run's IPC barrier stiffness (one piece of the discrete map; no contact: none)."""
    kappa = model.tape.barrier_stiffness
    first, second = [], []
    for k in range(count):
        eps = largest * 0.5 ** k
        try:
            J = model.forward(theta + eps * delta, obj)
        finally:
            model.parameters.assign(theta)
        assert model.tape.barrier_stiffness == kappa
        first.append(J - J0)
        second.append(J - J0 - eps * grad @ delta)
    return first, second


@pytest.mark.parametrize("integrator,damped", CASES)
@pytest.mark.parametrize("kind", list(KINDS))
def test_taylor_remainders_fall_at_orders_one_and_two(integrator, damped, kind):
    model, obj = model_for(integrator, damped), objective()
    theta = model.parameters.values()
    J0, grad = model.evaluate(theta, obj)
    delta = np.array([KINDS[kind].get(name, 0.0) for name in model.names])
    first, second = taylor_remainders(model, obj, theta, delta, J0, grad, 0.25, 5)
    assert abs(orders(first)[-1] - 1.0) < 0.1, (first, orders(first))
    # the asymptotic orders (the largest steps still see the third-order term)
    assert orders(second)[-1] >= 1.9 and np.all(orders(second) > 1.5), (second, orders(second))


@pytest.mark.parametrize("integrator,damped", CASES)
def test_gradient_equals_central_differences(integrator, damped):
    model, obj = model_for(integrator, damped), objective()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    for i, name in enumerate(model.names):
        eps = 1e-5 * max(abs(theta[i]), 1.0)
        up, down = theta.copy(), theta.copy()
        up[i] += eps
        down[i] -= eps
        fd = (model.forward(up, obj) - model.forward(down, obj)) / (2.0 * eps)
        assert grad[i] == pytest.approx(fd, rel=1e-6), name
    model.parameters.assign(theta)


@pytest.mark.parametrize("integrator", ["implicit_euler", "bdf2", "newmark"])
def test_gradient_with_a_moving_handle(integrator):
    """The pinned face moves (a handle): its prescribed motion does not depend on theta."""
    d = scene_dict(integrator, damped=True)
    d["pin"][0] |= {"velocity": [0.2, 0.0, 0.3], "angular_velocity": 2.0,
                    "axis": [1.0, 0.0, 0.0]}
    model = AdjointModel(fem_anim.Scene.from_dict(d), PARAMS)
    obj = objective()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    np.testing.assert_allclose(grad, central_differences(model, obj, theta), rtol=1e-6)


@pytest.mark.parametrize("model_name", ["stable_neohookean", "stvk"])
def test_gradient_in_2d_and_other_materials(model_name):
    """A plane-strain strip (64 triangles), BDF2 with damping."""
    d = {"mesh": {"dim": 2, "size": [1.0, 0.2], "divisions": [16, 2]},
         "material": {"model": model_name, "youngs_modulus": 1.0e4, "poisson_ratio": 0.3,
                      "density": 1000.0},
         "time": {"steps": 5, "dt": 0.02, "integrator": "bdf2"}, "output": {"render": False},
         "gravity": {"acceleration": [0.0, -9.81]}, "initial": {"velocity": [0.0, 0.3]},
         "damping": {"alpha": 0.5, "beta": 1.0e-3},
         "pin": [{"min": [-0.01, -1.0], "max": [0.01, 1.0]}]}
    model = AdjointModel(fem_anim.Scene.from_dict(d), PARAMS)
    obj = PointTarget([1.0, 0.2], [[1.0, 0.1]], [0.1]) + CentreOfMassTarget([[0.5, 0.05]],
                                                                            [0.06])
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    fd = central_differences(model, obj, theta)  # a component 1e6 below the largest is at
    np.testing.assert_allclose(grad, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())  # FD noise


def central_differences(model, obj, theta, names=None) -> np.ndarray:
    out = []
    for i, name in enumerate(model.names):
        if names is not None and name not in names:
            out.append(np.nan)
            continue
        eps = 1e-5 * max(abs(theta[i]), 1.0)
        up, down = theta.copy(), theta.copy()
        up[i] += eps
        down[i] -= eps
        out.append((model.forward(up, obj) - model.forward(down, obj)) / (2.0 * eps))
    model.parameters.assign(theta)
    return np.array(out)


def test_trajectory_of_a_reference_run(tmp_path):
    """The reference made with other E and nu: J > 0, its gradient the differences'; made
    with the same values, J is at the storage's round-off and the gradient tiny."""
    ref = scene_dict("newmark", steps=5)
    ref["material"] |= {"youngs_modulus": 1.3e4, "poisson_ratio": 0.25}
    with fem_anim.run(fem_anim.Scene.from_dict(ref), tmp_path / "ref") as reference:
        obj = TrajectoryMatch(reference.outdir)
        model = model_for("newmark", True)
        theta = model.parameters.values()
        J, grad = model.evaluate(theta, obj)
        assert J > 0.0
        fd = central_differences(model, obj, theta)
        np.testing.assert_allclose(grad, fd, rtol=1e-6)
        matched = theta.copy()
        matched[:2] = [1.3e4, 0.25]
        J_same, _ = model.evaluate(matched, obj)
        assert J_same < 1e-12 * J
    model.parameters.assign(theta)


def test_callable_and_form_objectives():
    model = model_for("bdf2", True)
    theta = model.parameters.values()

    def tip_height(u):  # separable: sum of owned z displacements squared
        z = u[2::3]
        grad = np.zeros_like(u)
        grad[2::3] = 2.0 * z
        return float(z @ z), grad

    for obj in (StateFunctional(tip_height),
                FormFunctional(lambda u: ufl.inner(u, u) * u[2] * ufl.dx, time=0.06)):
        _, grad = model.evaluate(theta, obj)
        np.testing.assert_allclose(grad, central_differences(model, obj, theta), rtol=1e-6)


def test_the_python_api_gives_the_models_gradient():
    scene = fem_anim.Scene.from_dict(scene_dict("bdf2", True))
    J, grads = fem_anim.gradient(scene, objective(), ["material.youngs_modulus",
                                                      "initial.velocity"])
    model = model_for("bdf2", True)
    J_model, grad = model.evaluate(model.parameters.values(), objective())
    assert J == pytest.approx(J_model, rel=1e-12)
    assert list(grads) == ["material.youngs_modulus", "initial.velocity[0]",
                           "initial.velocity[1]", "initial.velocity[2]"]
    np.testing.assert_allclose(list(grads.values()), grad[[0, 3, 4, 5]], rtol=1e-10)


def test_memory_and_cost_are_reported():
    model = model_for("implicit_euler", False)
    model.evaluate(model.parameters.values(), objective())
    n = model.problem.u.x.array.size
    # u, v, a at t = 0; u, v, a, u_old, v_old after each step
    assert model.tape.nbytes == 8 * n * (3 + 5 * model.steps)
    assert model.timing["forward"] > 0.0 and model.timing["backward"] > 0.0


@pytest.mark.parametrize("change,message", [
    ({"param": ["material.mooney_ratio"]}, "not a parameter"),
    ({"param": ["initial.velocity"], "initial": None}, "no [initial] section"),
    ({"obstacle": [{"type": "plane", "point": [0.0, 0.0, -1.0], "normal": [0.0, 0.0, 1.0]}],
      "time": {"steps": 2, "dt": 0.02, "integrator": "newmark"}}, "with contact"),
    ({"param": ["body.left.material.density"]}, "no body 'left'"),
    ({"param": ["region.soft.material.density"]}, "no region 'soft'"),
    ({"param": ["damping.alpha"]}, "no [damping] section"),
    ({"time": {"steps": 2, "dt": 0.02, "integrator": "symplectic_euler"}},
     "not differentiable"),
])
def test_bad_input_is_one_clear_error(change, message):
    d = scene_dict("implicit_euler", damped=False)
    params = change.pop("param", PARAMS)
    for key, value in change.items():
        if value is None:
            d.pop(key)
        else:
            d[key] = value
    with pytest.raises(FemAnimError, match=message.replace("[", r"\[").replace("]", r"\]")):
        AdjointModel(fem_anim.Scene.from_dict(d), params)


def test_target_on_another_mesh_is_refused(tmp_path):
    other = scene_dict("implicit_euler", damped=False, steps=2)
    other["mesh"]["divisions"] = [4, 2, 2]
    with fem_anim.run(fem_anim.Scene.from_dict(other), tmp_path / "other") as reference:
        with pytest.raises(FemAnimError, match="another mesh"):
            model_for("implicit_euler", False).evaluate(
                model_for("implicit_euler", False).parameters.values(),
                TrajectoryMatch(reference.outdir))


def test_unconverged_step_has_no_gradient():
    d = scene_dict("implicit_euler", damped=False, steps=2)
    d["solver"] = {"max_iterations": 1, "on_budget": "accept"}
    model = AdjointModel(fem_anim.Scene.from_dict(d), PARAMS)
    with pytest.raises(ConvergenceError, match="gradient is undefined"):
        model.evaluate(model.parameters.values(), objective())


def fem_anim_cli(args: list[str], cwd) -> subprocess.CompletedProcess:
    return subprocess.run(fem_anim_command() + args, cwd=cwd, capture_output=True, text=True,
                          timeout=600)


@pytest.fixture(scope="module")
def fit_setup(tmp_path_factory):
    """A scene file and a reference run made with E = 1.3e4 Pa, nu = 0.25 (the scene's:
    1e4 Pa, 0.3)."""
    root = tmp_path_factory.mktemp("fit")
    scene = scene_dict("implicit_euler", damped=False, steps=4)
    (root / "scene.toml").write_text(scene_toml(scene))
    reference = scene_dict("implicit_euler", damped=False, steps=4)
    reference["material"] |= {"youngs_modulus": 1.3e4, "poisson_ratio": 0.25}
    (root / "reference.toml").write_text(scene_toml(reference))
    r = fem_anim_cli(["run", "reference.toml", "-o", "ref", "-q"], root)
    assert r.returncode == 0, r.stderr
    return root


def test_fit_command_recovers_the_reference_material(fit_setup):
    root = fit_setup
    r = fem_anim_cli(["fit", "scene.toml", "--target", "ref", "--param",
                      "material.youngs_modulus", "--param", "material.poisson_ratio",
                      "-o", "fitted"], root)
    assert r.returncode == 0, r.stderr
    result = json.loads((root / "fitted" / "fit.json").read_text())
    assert result["material.youngs_modulus"] == pytest.approx(1.3e4, rel=1e-2)
    assert result["material.poisson_ratio"] == pytest.approx(0.25, rel=1e-2)
    assert result["iterations"] <= 30
    rows = (root / "fitted" / "fit.csv").read_text().splitlines()
    assert rows[0] == ("evaluation,material.youngs_modulus,material.poisson_ratio,objective,"
                       "gradient_norm,accepted")
    assert len(rows) - 1 == result["evaluations"]
    best = min(rows[1:], key=lambda row: float(row.split(",")[3]))
    assert float(best.split(",")[1]) == result["material.youngs_modulus"]
    assert float(best.split(",")[3]) == result["objective"]


@pytest.mark.parametrize("args,message", [
    (["--param", "material.mooney_ratio"], "not a parameter"),
    (["--param", "material.youngs_modulus", "--bounds", "material.density=1,2"],
     "not one of the fitted parameters"),
    (["--param", "material.youngs_modulus", "-o", "user"], "not empty"),
    (["--param", "material.youngs_modulus", "--target", "coarse"], "another mesh"),
    (["--param", "material.youngs_modulus", "--target", "nowhere"], "not a finished run"),
    (["--param", "material.youngs_modulus", "--set", "solver.max_iterations=1",
      "--set", 'solver.on_budget="accept"'], "gradient is undefined"),
])
def test_fit_command_bad_input_is_one_line(fit_setup, args, message):
    root = fit_setup
    (root / "user").mkdir(exist_ok=True)
    (root / "user" / "notes.txt").write_text("mine")
    if "coarse" in args and not (root / "coarse").exists():
        coarse = scene_dict("implicit_euler", damped=False, steps=4)
        coarse["mesh"]["divisions"] = [4, 2, 2]
        (root / "coarse.toml").write_text(scene_toml(coarse))
        assert fem_anim_cli(["run", "coarse.toml", "-o", "coarse", "-q"], root).returncode == 0
    target = [] if "--target" in args else ["--target", "ref"]
    r = fem_anim_cli(["fit", "scene.toml", *target, *args, "-o", "bad", "-q"]
                     if "-o" not in args else ["fit", "scene.toml", *target, *args, "-q"], root)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("fem-anim: error: "), r.stderr
    assert message in lines[0]
    assert (root / "user" / "notes.txt").read_text() == "mine"


def mpi_gradient(reference: str) -> dict:
    """J and the gradient of the damped Newmark case, point targets and a reference run's
    trajectory (run on any number of ranks)."""
    model = AdjointModel(fem_anim.Scene.from_dict(scene_dict("newmark", True)), PARAMS)
    J, grad = model.evaluate(model.parameters.values(),
                             objective() + TrajectoryMatch(reference))
    return {"J": J, "grad": list(map(float, grad))}


@pytest.mark.mpi
def test_two_ranks_give_the_serial_gradient(tmp_path):
    mpirun = mpirun_command(2)
    if mpirun is None:
        pytest.skip("mpirun not available")
    ref = scene_dict("newmark", steps=5)
    ref["material"] |= {"youngs_modulus": 1.3e4, "poisson_ratio": 0.25}
    fem_anim.run(fem_anim.Scene.from_dict(ref), tmp_path / "ref").close()
    r = subprocess.run([*mpirun, sys.executable, __file__, str(tmp_path / "ref")],
                       capture_output=True, text=True, timeout=600, env=clean_environment(),
                       cwd=ROOT)
    assert r.returncode == 0, r.stdout + r.stderr
    parallel = json.loads(r.stdout.strip().splitlines()[-1])
    serial = mpi_gradient(str(tmp_path / "ref"))
    assert parallel["J"] == pytest.approx(serial["J"], rel=1e-8)
    np.testing.assert_allclose(parallel["grad"], serial["grad"], rtol=1e-8)


if __name__ == "__main__":
    from mpi4py import MPI

    result = mpi_gradient(sys.argv[1])
    if MPI.COMM_WORLD.rank == 0:
        print(json.dumps(result))
