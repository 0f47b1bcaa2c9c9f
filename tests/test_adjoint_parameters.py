"""Gradients for the Rayleigh coefficients and for per-region and per-body materials
(:mod:`fem_anim.adjoint.parameters`).

On the damped beam of ``test_adjoint`` (implicit Euler, BDF2, Newmark):

* ``damping.alpha`` and ``damping.beta``: a Taylor test each (first-order remainder at
  order 1, gradient-corrected one at order >= 1.9) and central differences to 1e-6;
* a ``[[region]]`` at the free end with its own E and density next to the rest's
  ``[material]``: a Taylor test per parameter and central differences, and the region's
  gradient plus the rest's equals the gradient of the same scene without the region (the
  parameters' cells partition the mesh);
* a two-body scene's per-body constants: in ``test_adjoint_contact`` (the IPC cubes).
"""

from __future__ import annotations

import numpy as np
import pytest
from test_adjoint import objective, orders, scene_dict, taylor_remainders

import fem_anim
from fem_anim.adjoint.differentiate import AdjointModel

DAMPING = ["damping.alpha", "damping.beta"]
REGION = ["material.youngs_modulus", "region.tip.material.youngs_modulus",
          "region.tip.material.density", "material.density"]
DIRECTIONS = {"damping.alpha": 0.2, "damping.beta": 5.0e-4,
              "material.youngs_modulus": 2.0e3, "region.tip.material.youngs_modulus": 2.0e3,
              "region.tip.material.density": 200.0, "material.density": 200.0}
INTEGRATORS = ["implicit_euler", "bdf2", "newmark"]
_MODELS: dict = {}


def region_scene(integrator: str) -> dict:
    d = scene_dict(integrator, damped=True)
    d["region"] = [{"name": "tip", "min": [0.6, -1.0, -1.0], "max": [2.0, 1.0, 1.0],
                    "youngs_modulus": 1.5e4, "density": 800.0}]
    return d


def model_for(which: str, integrator: str) -> AdjointModel:
    if (which, integrator) not in _MODELS:
        scene = scene_dict(integrator, damped=True) if which == "damping" else \
            region_scene(integrator)
        _MODELS[which, integrator] = AdjointModel(fem_anim.Scene.from_dict(scene),
                                                  DAMPING if which == "damping" else REGION)
    return _MODELS[which, integrator]


def central_differences(model, obj, theta) -> np.ndarray:
    out = []
    for i in range(theta.size):
        eps = 1e-5 * max(abs(theta[i]), 1e-3 if abs(theta[i]) < 1.0 else 1.0)
        up, down = theta.copy(), theta.copy()
        up[i] += eps
        down[i] -= eps
        out.append((model.forward(up, obj) - model.forward(down, obj)) / (2.0 * eps))
    model.parameters.assign(theta)
    return np.array(out)


CASES = [(w, i, n) for w, names in (("damping", DAMPING), ("region", REGION))
         for i in INTEGRATORS for n in names]


@pytest.mark.parametrize("which,integrator,name", CASES)
def test_taylor_remainders_fall_at_orders_one_and_two(which, integrator, name):
    model, obj = model_for(which, integrator), objective()
    theta = model.parameters.values()
    J0, grad = model.evaluate(theta, obj)
    delta = np.array([DIRECTIONS[name] if n == name else 0.0 for n in model.names])
    first, second = taylor_remainders(model, obj, theta, delta, J0, grad, 0.25, 5)
    assert abs(orders(first)[-1] - 1.0) < 0.1, (first, orders(first))
    assert orders(second)[-1] >= 1.9 and np.all(orders(second) > 1.5), (second, orders(second))


@pytest.mark.parametrize("which", ["damping", "region"])
@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_gradient_equals_central_differences(which, integrator):
    model, obj = model_for(which, integrator), objective()
    theta = model.parameters.values()
    _, grad = model.evaluate(theta, obj)
    # scaled by the values (sensitivities theta_i dJ/dtheta_i, comparable across units): the
    # tip's E moves J 40 times less than the rest's, and its differences' noise is the same
    fd = theta * central_differences(model, obj, theta)
    np.testing.assert_allclose(theta * grad, fd, rtol=1e-6, atol=1e-6 * np.abs(fd).max())


def test_region_and_rest_sum_to_the_global_derivative():
    """E everywhere = E on the tip and E on the rest: with the tip's E equal to the rest's,
    dJ/dE_tip + dJ/dE_rest is the scene-without-region's dJ/dE."""
    d = region_scene("bdf2")
    d["region"][0] |= {"youngs_modulus": 1.0e4, "density": 1000.0}
    split = AdjointModel(fem_anim.Scene.from_dict(d), REGION)
    whole = AdjointModel(fem_anim.Scene.from_dict(scene_dict("bdf2", damped=True)),
                         ["material.youngs_modulus"])
    J_split, g_split = split.evaluate(split.parameters.values(), objective())
    J_whole, g_whole = whole.evaluate(whole.parameters.values(), objective())
    assert J_split == pytest.approx(J_whole, rel=1e-10)
    assert g_split[0] + g_split[1] == pytest.approx(g_whole[0], rel=1e-8)
