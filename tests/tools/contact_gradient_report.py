"""The numbers of docs/gradients.md's contact section: gradients through contact against
central differences, and the backward sweep's cost against the forward run.

For the scenes of ``tests/test_adjoint_contact.py`` (a cube dropped on an obstacle plane,
with and without friction; two cubes in IPC contact, with and without friction), each with
implicit Euler and BDF2: the adjoint gradient, central differences (step 1e-5 relative),
the relative distance |g - fd| / |fd| (whole vector) and per parameter, and the median
forward and backward wall times of 3 evaluations.

Usage::

    .venv/bin/python tests/tools/contact_gradient_report.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import fem_anim  # noqa: E402
from fem_anim.adjoint.differentiate import AdjointModel  # noqa: E402
from test_adjoint_contact import (BODY, MATERIAL, cubes_objective, cubes_scene,  # noqa: E402
                                  plane_objective, plane_scene)

ONLY = sys.argv[1:]
CASES = [("obstacle plane", lambda i: plane_scene(i), MATERIAL, plane_objective),
         ("obstacle plane, friction 0.5", lambda i: plane_scene(i, friction=0.5), MATERIAL,
          plane_objective),
         ("IPC cubes", lambda i: cubes_scene(i), BODY, cubes_objective),
         ("IPC cubes, friction 0.3", lambda i: cubes_scene(i, friction=0.3), BODY,
          cubes_objective)]


def main() -> None:
    for label, build, params, objective in [c for c in CASES if not ONLY or c[0] in ONLY]:
        for integrator in ("implicit_euler", "bdf2"):
            model = AdjointModel(fem_anim.Scene.from_dict(build(integrator)), params)
            obj = objective()
            theta = model.parameters.values()
            times = []
            for _ in range(3):
                _, grad = model.evaluate(theta, obj)
                times.append((model.timing["forward"], model.timing["backward"]))
            fd = []
            for i in range(theta.size):
                eps = 1e-5 * max(abs(theta[i]), 1.0)
                up, down = theta.copy(), theta.copy()
                up[i] += eps
                down[i] -= eps
                fd.append((model.forward(up, obj) - model.forward(down, obj)) / (2 * eps))
            fd = np.array(fd)
            forward, backward = np.median(np.array(times), axis=0)
            print(f"{label}, {integrator}: |g - fd|/|fd| = "
                  f"{np.linalg.norm(grad - fd) / np.linalg.norm(fd):.2e}; "
                  f"forward {forward:.3f} s, backward {backward:.3f} s "
                  f"(ratio {backward / forward:.2f})")
            for name, g, f in zip(model.names, grad, fd):
                rel = abs(g - f) / abs(f) if f != 0 else float("nan")
                print(f"    {name:40s} adjoint {g: .6e}  differences {f: .6e}  rel {rel:.1e}")


if __name__ == "__main__":
    main()
