# %% [markdown]
# # Recovering a jelly's stiffness from its motion
#
# A jelly cube hangs from its top face and wobbles under gravity. We record its motion with
# one material (the "measurement"), then forget the material and recover Young's modulus E
# and Poisson's ratio nu from the recorded trajectory alone, by gradient descent through
# the simulation.
#
# Every time step is the minimisation of seed eq. 4,
#
#     x_{n+1} = argmin_x g(x) = 1/2 ||x - y_n||_M^2 + w E(x; mu(E, nu), lambda(E, nu)),
#
# (neo-Hookean E, Newmark's predictor y_n and weight w = h^2/4). The objective is the
# distance of the simulated trajectory to the recorded one,
#
#     J(E, nu) = 1/2 sum_n sum_vertices |u_n - u_n^ref|^2   (m^2).
#
# Its gradient comes from the discrete adjoint (`fem_anim.adjoint`): at each converged step
# grad_x g = 0, so dx_{n+1}/dtheta = -H^-1 d(grad_x g)/dtheta with H the exact Hessian of g;
# one backward sweep over the kept states gives dJ/dE and dJ/dnu for the cost of about one
# linear solve per step. scipy's L-BFGS-B then minimises J (`fem_anim.adjoint.fit`), the
# same driver as `fem-anim fit SCENE --target RUN_DIR --param material.youngs_modulus
# --param material.poisson_ratio`.
#
# Parameters: a 0.2 m cube of density 1000 kg/m^3, recorded with E = 5 kPa, nu = 0.35;
# the fit starts from E = 2 kPa, nu = 0.25. Time step 1/60 s, 20 steps (reduced in CI:
# a coarser mesh and 8 steps).

# %%
import os
from pathlib import Path

import numpy as np

import fem_anim
from fem_anim.adjoint import AdjointModel, TrajectoryMatch
from fem_anim.adjoint.fit import fit

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "fit_material"
TRUE = {"youngs_modulus": 5.0e3, "poisson_ratio": 0.35}  # Pa, -
START = {"youngs_modulus": 2.0e3, "poisson_ratio": 0.25}
n = 3 if REDUCED else 4  # cells per edge (6 n^3 tetrahedra)


def jelly(material: dict) -> fem_anim.Scene:
    """The hanging jelly cube with a given E and nu."""
    return fem_anim.Scene.from_dict({
        "name": "hanging_jelly",
        "mesh": {"dim": 3, "size": [0.2, 0.2, 0.2], "divisions": [n, n, n]},
        "material": {"model": "neohookean", "density": 1000.0, **material},
        "time": {"integrator": "newmark", "dt": 1.0 / 60.0, "steps": 8 if REDUCED else 20},
        "gravity": {"acceleration": [0.0, 0.0, -9.81]},
        "pin": [{"name": "top", "min": [-1.0, -1.0, 0.2 - 1e-6], "max": [1.0, 1.0, 1.0]}],
        "output": {"render": False},
    })


# %% [markdown]
# ## The measurement: a run with the true material

# %%
reference = fem_anim.run(jelly(TRUE), OUT / "reference")
sag = -reference.displacement(-1)[:, 2].min()
print(f"recorded {len(reference.times) - 1} steps; the bottom sags {100 * sag:.1f} cm")
assert sag > 1e-3  # the jelly moves: there is something to fit

# %% [markdown]
# ## The gradient at the start, checked against central differences

# %%
model = AdjointModel(jelly(START), ["material.youngs_modulus", "material.poisson_ratio"])
objective = TrajectoryMatch(reference.outdir)
theta0 = model.parameters.values()
J0, grad0 = model.evaluate(theta0, objective)
for i, name in enumerate(model.names):
    eps = 1e-4 * abs(theta0[i])  # above the forward solves' round-off in J, below truncation
    up, down = theta0.copy(), theta0.copy()
    up[i] += eps
    down[i] -= eps
    fd = (model.forward(up, objective) - model.forward(down, objective)) / (2 * eps)
    print(f"dJ/d{name}: adjoint {grad0[i]:.10e}, central differences {fd:.10e}")
    assert abs(grad0[i] - fd) <= 1e-6 * abs(fd)
model.parameters.assign(theta0)

# %% [markdown]
# ## The fit

# %%


def show(entry: dict) -> None:
    E, nu = entry["theta"]
    print(f"E = {E:10.2f} Pa, nu = {nu:.5f}: J = {entry['value']:.4e} m^2, "
          f"|dJ/dtheta| = {entry['gradient_norm']:.3e}")


result = fit(model, objective, max_iterations=30, report=show)
E, nu = result.theta
print(f"{result.message}: {result.iterations} iterations, {result.evaluations} runs; "
      f"E = {E:.2f} Pa (true {TRUE['youngs_modulus']:g}), nu = {nu:.5f} "
      f"(true {TRUE['poisson_ratio']:g})")
print(f"memory of the kept states: {model.tape.nbytes / 2**20:.2f} MiB on this rank "
      f"({model.tape.nbytes / model.tape.steps / 1024:.1f} KiB per step); last evaluation: "
      f"forward {model.timing['forward']:.2f} s, backward {model.timing['backward']:.2f} s")

# %% [markdown]
# ## Checks: the material is recovered within 1 % in at most 30 iterations

# %%
assert result.iterations <= 30
assert abs(E / TRUE["youngs_modulus"] - 1.0) < 0.01
assert abs(nu / TRUE["poisson_ratio"] - 1.0) < 0.01
assert result.value < 1e-6 * J0
reference.close()
