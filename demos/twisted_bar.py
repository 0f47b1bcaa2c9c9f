# %% [markdown]
# # A bar twisted by animated handles
#
# `demos/twisted_bar.toml`: a 1 x 0.1 x 0.1 m neo-Hookean bar (E = 1e5 Pa, nu = 0.3,
# 1000 kg/m^3, light mass-proportional damping alpha = 2/s) whose end faces are `[[pin]]`
# handles turning in opposite senses about the bar's axis, omega = -/+ pi/2 rad/s until
# t = 1 s, then holding: a total twist of pi (180 degrees). No gravity.
#
# Each step minimises g(x) = 1/2 ||x - y||_M^2 + h^2/4 E(x) (seed eq. 4) with the handles'
# vertices as Dirichlet values x = c + R(omega t)(X - c) (Rodrigues' formula,
# `fem_anim.problem.handles.PinMotion`). The demo asserts:
#
# * the measured twist of each end face (the angle between X - c and x - c in the y-z
#   plane, from the written displacement) equals the prescribed -/+ omega min(t, 1 s);
# * the twist inside the bar lies between the end values, increasing along the bar, and is
#   near zero at the middle (antisymmetric loading);
# * no element is inverted: det F > 0 in every cell;
# * the axial length changes by little (torsion of a neo-Hookean bar shortens it slightly,
#   the Poynting effect's cousin), |Delta L| < 5 %.
#
# Set FEM_ANIM_DEMO_REDUCED=1 for the short, coarse variant the test suite runs (45 degrees
# per end). The full run writes `out/demos/twisted_bar/twisted_bar.png`
# (`demos/twisted_bar.png`, shown in the README, is a copy).

# %%
import os
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim.reference import deformation_gradient
from fem_anim.scene import load_scene
from fem_anim.simulation import Simulation

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "twisted_bar"
overrides = ["mesh.element_size=0.05", "time.steps=20", "time.dt=0.03333333333333333",
             "pin.0.until=0.5", "pin.1.until=0.5", "output.render=false"] if REDUCED else []
scene = load_scene(HERE / "twisted_bar.toml", overrides)

# %% [markdown]
# ## Run

# %%
sim = Simulation(scene, MPI.COMM_WORLD)
run = sim.run(OUT, quiet=True)
t = run.state.time
print(f"{scene['time']['steps']} steps to t = {t:.3f} s, "
      f"{sum(r['newton_its'] for r in run.rows)} Newton iterations")

# %% [markdown]
# ## What the run must show
# Twist angles are measured on rank 0 from the final displacement in input vertex order:
# theta = atan2(r x r', r . r') with r = X - c and r' = x - c projected on the y-z plane.

# %%
if MPI.COMM_WORLD.rank == 0:
    points, cells = sim.domain.points, sim.domain.cells
    x = points + run.final_displacement[:, :3]
    c = np.array([0.05, 0.05])
    r, r_new = points[:, 1:] - c, x[:, 1:] - c
    theta = np.arctan2(r[:, 0] * r_new[:, 1] - r[:, 1] * r_new[:, 0], np.sum(r * r_new, axis=1))
    off_axis = np.linalg.norm(r, axis=1) > 1e-9
    pins = scene["pin"]
    for pin, at in ((pins[0], 0.0), (pins[1], 1.0)):
        prescribed = pin["angular_velocity"] * min(t, pin["until"])
        face = off_axis & (np.abs(points[:, 0] - at) < 1e-9)
        error = np.abs(theta[face] - prescribed).max()
        print(f"end x = {at}: twist {np.degrees(theta[face].mean()):+.2f} deg, prescribed "
              f"{np.degrees(prescribed):+.2f} deg, max error {error:.1e} rad")
        assert error < 1e-10, error

    slices = np.linspace(0.0, 1.0, 11)
    means = np.array([theta[off_axis & (np.abs(points[:, 0] - s) < 0.03)].mean()
                      for s in slices])
    print("twist along the bar (deg):", " ".join(f"{np.degrees(a):+.0f}" for a in means))
    assert np.all(np.diff(means) > 0), means
    assert abs(means[5]) < 0.1 * abs(means[-1]), means

    J = np.linalg.det(deformation_gradient(points, cells, x.ravel()))
    print(f"det F in [{J.min():.3f}, {J.max():.3f}]")
    assert J.min() > 0.0
    length = x[:, 0].max() - x[:, 0].min()
    print(f"length {length:.4f} m")
    assert abs(length - 1.0) < 0.05

    if not REDUCED:
        from fem_anim.render.process import render_file

        render_file(run.output_dir / "final.vtu", OUT / "twisted_bar.png",
                    title=f"twisted bar, t = {t:.2f} s, 180 degrees")
        print(f"picture {OUT / 'twisted_bar.png'}")
