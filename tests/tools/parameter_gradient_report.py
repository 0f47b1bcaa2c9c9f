"""The numbers of docs/gradients.md's parameter section: the gradient of each new parameter
kind (initial spin and displacement, friction coefficients, a handle's velocity) against
central differences, and how smooth J is in the initial displacement under obstacle
friction.

For the scenes of ``tests/test_adjoint_initial.py``, ``tests/test_adjoint_friction.py`` and
``tests/test_adjoint_handles.py``: per parameter the adjoint gradient, central differences
(step 1e-5 max(|theta|, 0.1), 1e-7 m for a displacement) and their relative distance; then, on the spinning cube with
friction 0.5, the central differences of J in the initial z displacement at steps 1e-4 to
1e-7 m with eps_v = 0.02 and 0.2 m/s, against the adjoint.

Usage::

    .venv/bin/python tests/tools/parameter_gradient_report.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import fem_anim  # noqa: E402
import test_adjoint_friction as friction  # noqa: E402
import test_adjoint_handles as handles  # noqa: E402
import test_adjoint_initial as initial  # noqa: E402
from fem_anim.adjoint.differentiate import AdjointModel  # noqa: E402

CASES = [(f"{module.__name__}: {scene}", module.SCENES[scene][0], params, objective, i)
         for module, scenes in ((initial, ("beam", "plane", "plane_friction", "ipc")),
                                (friction, ("plane", "ipc")), (handles, ("beam", "plane")))
         for scene in scenes
         for params, objective in [(module.SCENES[scene][1], module.SCENES[scene][2])
                                   if module is not handles else
                                   (handles.HANDLE, module.SCENES[scene][1])]
         for i in (("implicit_euler", "bdf2", "newmark") if scene == "beam"
                   else ("implicit_euler", "bdf2"))]


def differences(model, obj, theta, index, eps) -> float:
    up, down = theta.copy(), theta.copy()
    up[index] += eps
    down[index] -= eps
    return (model.forward(up, obj) - model.forward(down, obj)) / (2.0 * eps)


def main() -> None:
    for label, build, params, objective, integrator in CASES:
        model = AdjointModel(fem_anim.Scene.from_dict(build(integrator)), params)
        obj = objective()
        theta = model.parameters.values()
        _, grad = model.evaluate(theta, obj)
        fd = np.array([differences(model, obj, theta, i, 1e-7 if "displacement" in name
                                   else 1e-5 * max(abs(theta[i]), 0.1))
                       for i, name in enumerate(model.names)])
        model.parameters.assign(theta)
        print(f"{label}, {integrator}: |g - fd|/|fd| = "
              f"{np.linalg.norm(grad - fd) / np.linalg.norm(fd):.1e}")
        for name, g, f in zip(model.names, grad, fd):
            print(f"    {name:40s} adjoint {g: .6e}  differences {f: .6e}  "
                  f"rel {abs(g - f) / abs(f) if f else float('nan'):.1e}")
    for epsv in (0.02, 0.2):
        d = initial.spinning_plane_scene("implicit_euler", 0.5)
        d["obstacle"][0]["epsv"] = epsv
        model = AdjointModel(fem_anim.Scene.from_dict(d), ["initial.displacement[2]"])
        obj = initial.plane_objective()
        theta = model.parameters.values()
        _, grad = model.evaluate(theta, obj)
        print(f"eps_v = {epsv} m/s: adjoint dJ/du_z = {grad[0]:.6e}")
        for step in (1e-4, 1e-5, 1e-6, 1e-7):
            f = differences(model, obj, theta, 0, step)
            print(f"    step {step:.0e} m: differences {f:.6e}, "
                  f"rel {abs(f - grad[0]) / abs(grad[0]):.1e}")


if __name__ == "__main__":
    main()
