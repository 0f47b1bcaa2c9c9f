# %% [markdown]
# # Four soft bodies dropped into a pile
#
# Several bodies in contact (issue 16): a jelly box (neo-Hookean, E = 2e4 Pa), a rubber ball
# (stable neo-Hookean, 5e4 Pa), a wooden-ish log (corotated, 1e5 Pa) and a ring (StVK,
# 3e4 Pa) fall onto the ground and onto each other. All four are one DOLFINx mesh (the
# union of the bodies' meshes, `fem_anim/mesh/bodies.py`), so each step is one minimisation
# (seed eq. 4, implicit Euler with w = h^2)
#
#     g(x) = 1/2 ||x - y||_M^2 + w [ E_elastic(x) + E_gravity(x) + E_ground(x) + B(x) + D(x) ],
#
# where E_ground is the obstacle barrier of the ground plane (`forms/obstacle_contact.py`) and B the
# IPC Toolkit's barrier between all boundary surfaces, bodies with each other and each
# with itself (`fem_anim/contact/ipc.py`),
#
#     B(x) = kappa sum_k a_k b(d_k^2, d_hat^2) / d_hat^3,
#     b(s, s_hat) = -(s - s_hat)^2 ln(s / s_hat) for s < s_hat,
#
# over the point-triangle and edge-edge pairs k closer than d_hat = 2 mm (a_k their share
# of the surface area), with IPC's adaptive kappa, and D IPC's lagged friction (mu = 0.3).
# Every line-search trial is capped by ipctk's continuous collision detection, so no state
# the solver accepts has an intersection.
#
# The demo asserts its physics on the frames read back from disk: no surface crosses
# another in any frame (ipctk's `has_intersections` on the boundary triangles taken from
# the tetrahedra), no vertex is at or below the ground, the bodies end up touching each
# other (active pairs), and the motion has settled (kinetic energy a small part of the
# potential energy released). The scene is `demos/pile.toml` (`fem-anim run demos/pile.toml`;
# `render.color_by = "body"` gives each body its colour, the ground is drawn). Set
# FEM_ANIM_DEMO_REDUCED=1 for the short, coarse variant the test suite runs.

# %%
import os
from pathlib import Path

import meshio
import numpy as np
from mpi4py import MPI

from fem_anim.contact.intersection import crossed_frames
from fem_anim.scene import load_scene
from fem_anim.simulation import Simulation

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "pile"
overrides = ["time.steps=25", "output.render=false"] + [
    f"body.{k}.mesh.element_size={h}" for k, h in enumerate((0.06, 0.05, 0.04, 0.03))] \
    if REDUCED else []

# %% [markdown]
# ## Run the scene
# `Simulation.run` writes `trajectory.xdmf`, `stats.csv` (with `contact_s`, the time spent in
# ipctk, and `contact_pairs`), `final.vtu` and the pictures.

# %%
scene = load_scene(HERE / "pile.toml", overrides)
sim = Simulation(scene, MPI.COMM_WORLD)
run = sim.run(OUT, quiet=True)
rows = run.rows

# %% [markdown]
# ## What the run must show
# The boundary triangles are the faces of one tetrahedron only; each frame's positions go
# to ipctk's intersection test, independently of the solver's own surface.

# %%
if MPI.COMM_WORLD.rank == 0:
    with meshio.xdmf.TimeSeriesReader(str(OUT / "trajectory.xdmf")) as reader:
        points, blocks = reader.read_points_cells()
        frames = [reader.read_data(k)[1]["displacement"] for k in range(reader.num_steps)]
    crossed = crossed_frames(points, blocks[0].data, frames)
    lowest = min((points[:, 2] + u[:, 2]).min() for u in frames)
    pairs = [r["contact_pairs"] for r in rows]
    kinetic = np.array([r["kinetic"] for r in rows])
    released = rows[0]["gravity"] - min(r["gravity"] for r in rows)
    share = sum(r["contact_s"] for r in rows) / sum(r["step_wall_s"] for r in rows)
    newton = [r["newton_its"] for r in rows]
    print(f"{len(frames)} frames, crossed: {crossed}; lowest vertex {lowest:.2e} m; pairs at "
          f"the end {pairs[-1]} (max {max(pairs)}); kinetic {kinetic[-1]:.3g} J of "
          f"{released:.3g} J released; Newton its median {np.median(newton):.0f}, max "
          f"{max(newton)}; ipctk {100 * share:.0f} % of the step time")
    assert not crossed, f"frames {crossed} have intersecting surfaces"
    assert lowest > 0.0, "a vertex reached the ground"
    assert max(pairs) > 0, "the bodies never touched"
    if not REDUCED:
        assert pairs[-1] > 0, "the bodies do not rest on each other"
        assert kinetic[-1] < 0.1 * released, "the pile has not settled"
        print(f"picture {OUT / 'final.png'}")
