# %% [markdown]
# # A jelly cube dropped on the ground
#
# Contact as an energy (issue 7): a soft neo-Hookean cube (20 cm, E = 2e4 Pa, nu = 0.4,
# 1000 kg/m^3) falls 15 cm onto the ground plane z = 0, bounces and comes to rest. Each step
# minimises (seed eq. 4, BDF2 with w = 4 h^2 / 9)
#
#     g(x) = 1/2 ||x - y||_M^2 + w [ E_elastic(x) + E_gravity(x) + E_contact(x) + D(x) ],
#
# with the IPC log barrier (Li et al. 2020) over the cube's boundary, kappa in Pa,
#
#     E_contact = kappa / d_hat  int_dOmega b(d) dA,
#     b(d) = -(d - d_hat)^2 ln(d / d_hat) for d < d_hat, 0 beyond,
#
# d the height of a boundary point above the ground, d_hat = 3 mm, and D the lagged friction
# potential (mu = 0.5, eps_v = 1 cm/s; `forms/obstacle_contact.py`). Newton's line search never
# evaluates a state where a contact point touches the ground: its direction is scaled so no
# point comes closer than a tenth of its distance (`fem_anim/contact/obstacles.py`).
#
# The demo asserts its physics: no vertex is ever at or below the ground in any frame; the
# cube bounces (loses contact again after the first impact); it comes to rest on the ground
# (kinetic energy a few percent of its peak, bottom within a few d_hat); and the total energy
# (kinetic + elastic + gravity + barrier) only falls, up to BDF2's small oscillation, since
# BDF2 and friction dissipate and the barrier is conservative. The scene is
# `demos/jelly_cube.toml` (`fem-anim run demos/jelly_cube.toml`). Set
# FEM_ANIM_DEMO_REDUCED=1 for the short variant the test suite runs.

# %%
import os
import shutil
from pathlib import Path

import meshio
import numpy as np
from mpi4py import MPI

from fem_anim.scene import load_scene
from fem_anim.simulation import Simulation

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "jelly_cube"
overrides = ["mesh.element_size=0.1", "output.render=false"] if REDUCED else []

# %% [markdown]
# ## Run the scene
# `Simulation.run` writes `trajectory.xdmf`, `stats.csv`, `final.vtu` and `final.png`.

# %%
scene = load_scene(HERE / "jelly_cube.toml", overrides)
sim = Simulation(scene, MPI.COMM_WORLD)
run = sim.run(OUT, quiet=True)
rows = run.rows
dhat = scene["obstacle"][0]["dhat"]

# %% [markdown]
# ## What the run must show
# Heights of every vertex in every written frame (rank 0 reads the trajectory).

# %%
if MPI.COMM_WORLD.rank == 0:
    with meshio.xdmf.TimeSeriesReader(str(OUT / "trajectory.xdmf")) as reader:
        points, _ = reader.read_points_cells()
        lowest = np.array([(points[:, 2] + reader.read_data(k)[1]["displacement"][:, 2]).min()
                           for k in range(reader.num_steps)])
    contact = np.array([r["contact"] for r in rows])
    kinetic = np.array([r["kinetic"] for r in rows])
    energy = np.array([r["total_energy"] for r in rows])
    first = int(np.argmax(contact > 0))
    newton = [r["newton_its"] for r in rows]
    print(f"lowest vertex over all frames {lowest.min():.3e} m; first contact at step "
          f"{first + 1}; Newton its per step: free fall {np.median(newton[:first]):.0f}, "
          f"in contact median {np.median(newton[first:]):.0f}, max {max(newton)}; "
          f"final kinetic {kinetic[-1]:.3e} J (peak {kinetic.max():.3f} J); total energy "
          f"{energy[0]:.3f} -> {energy[-1]:.3f} J")
    assert lowest.min() > 0.0, "a vertex reached the ground"
    assert first > 0 and np.any(contact[first:] == 0.0), "the cube did not bounce"
    assert kinetic[-1] < 0.05 * kinetic.max(), "the cube is not at rest"
    assert lowest[-1] < 3 * dhat, "the cube does not rest on the ground"
    assert np.all(np.diff(energy) < 0.02 * kinetic.max()), "energy was created"
    assert energy[-1] < energy[first] - 0.5 * kinetic.max(), "nothing was dissipated"
    if not REDUCED:  # demos/jelly_cube.png, shown in the README, is a copy of it
        shutil.copyfile(OUT / "final.png", OUT / "jelly_cube.png")
