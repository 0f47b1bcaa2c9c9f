# %% [markdown]
# # A cloth draped over a ball
#
# A thin shell in contact (issue 30): a 0.6 m square of cloth (t = 1 mm, StVK membrane,
# E = 1 MPa, 0.3 kg/m^2, hinge bending derived from E, nu and t) falls onto a ball of
# radius 12 cm lying on the ground, drapes over it, its corners reach the ground and it
# settles into folds. The cloth's mesh is its mid-surface (`docs/cloth.md`), and each step
# is one minimisation (seed eq. 4, implicit Euler with w = h^2)
#
#     g(x) = 1/2 ||x - y||_M^2 + w [ E_membrane(x) + E_bending(x) + E_gravity(x)
#                                     + E_ball(x) + E_ground(x) + B(x) + D(x) ]
#            + Rayleigh's mass-proportional dissipation,
#
# where E_ball and E_ground are the obstacle barriers (`forms/obstacle_contact.py`) acting on
# the distance of the cloth's *face*, t / 2 from the mid-surface, at every vertex;
# B is the IPC Toolkit's barrier of the cloth with itself over its triangles, with the
# thickness t as the offset: it acts on d^2 - t^2, so two layers of a fold stop with their
# mid-surfaces t apart (`fem_anim/contact/contact_surface.py`, `fem_anim/contact/ipc.py`); D
# is the lagged friction (0.3 between layers, 0.4 on the ball and the ground). Every
# line-search trial is capped by the obstacles' step bound and ipctk's continuous collision
# detection (stopping at the offset), so no state the solver accepts crosses anything.
#
# The demo asserts its physics on the frames read back from disk: no two triangles of the
# cloth that share no vertex cross each other in any frame (the independent numpy
# segment-triangle check of `fem_anim/contact/intersection.py`), no vertex comes closer to
# the ball or the ground than t / 2, the cloth hangs over the ball (its top rests on the
# ball, its corners on the ground) and, in the full run, it has settled (kinetic energy a
# small part of the potential energy released) and folded onto itself (the folds' layers
# came within t + d_hat of each other: self-contact pairs). The scene is `demos/drape.toml`
# (`fem-anim run demos/drape.toml`). Set FEM_ANIM_DEMO_REDUCED=1 for the short, coarse
# variant the test suite runs.

# %%
import os
import tomllib
from pathlib import Path

import meshio
import numpy as np
from mpi4py import MPI

from fem_anim.contact.intersection import crossed_frames
from fem_anim.scene import load_scene
from fem_anim.simulation import Simulation

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "drape"
overrides = ["time.steps=25", "mesh.element_size=0.1", "output.render=false"] \
    if REDUCED else []

# %% [markdown]
# ## Run the scene
# `Simulation.run` writes `trajectory.xdmf`, `stats.csv` (with `contact_pairs`, the cloth's
# self-contact pairs, and `contact_s`, the time spent in ipctk), `final.vtu` and the pictures.

# %%
scene = load_scene(HERE / "drape.toml", overrides)
sim = Simulation(scene, MPI.COMM_WORLD)
result = sim.run(OUT, quiet=True)
rows = result.rows

# %% [markdown]
# ## What the run must show
# The geometry of the ball and the ground is read from the scene file, not from the solver.

# %%
if MPI.COMM_WORLD.rank == 0:
    cfg = tomllib.loads((HERE / "drape.toml").read_text())
    t = cfg["shell"]["thickness"]
    ball = next(o for o in cfg["obstacle"] if o["name"] == "ball")
    center, radius = np.asarray(ball["center"]), ball["radius"]
    with meshio.xdmf.TimeSeriesReader(str(OUT / "trajectory.xdmf")) as reader:
        points, blocks = reader.read_points_cells()  # a shell's points are 3D
        frames = [reader.read_data(k)[1]["displacement"] for k in range(reader.num_steps)]
    cells = blocks[0].data
    crossed = crossed_frames(points, cells, frames)
    to_ball = min((np.linalg.norm(points + u - center, axis=1) - radius).min() for u in frames)
    to_ground = min((points[:, 2] + u[:, 2]).min() for u in frames)
    x = points + frames[-1]
    kinetic = np.array([r["kinetic"] for r in rows])
    released = rows[0]["gravity"] - min(r["gravity"] for r in rows)
    newton = [r["newton_its"] for r in rows]
    pairs = [r["contact_pairs"] for r in rows]
    print(f"{len(frames)} frames, crossed: {crossed}; nearest to the ball {to_ball:.2e} m, "
          f"to the ground {to_ground:.2e} m (t/2 = {t / 2} m); top {x[:, 2].max():.4f} m; "
          f"kinetic {kinetic[-1]:.3g} J of {released:.3g} J released; self-contact pairs max "
          f"{max(pairs)}; Newton its median {np.median(newton):.0f}, max {max(newton)}; "
          f"mean step {np.mean([r['step_wall_s'] for r in rows]):.2f} s")
    assert not crossed, f"frames {crossed} have crossing triangles"
    assert to_ball > t / 2 and to_ground > t / 2, "the cloth came within t/2 of an obstacle"
    top = center[2] + radius + t / 2  # the cloth's mid-surface on the ball's top
    assert abs(x[:, 2].max() - top) < 2e-3, "the cloth does not rest on the ball"
    if not REDUCED:
        assert to_ground < t / 2 + 2e-3, "the corners never reached the ground"
        assert kinetic[-1] < 0.02 * released, "the cloth has not settled"
        assert max(pairs) > 0, "no fold touched another layer of the cloth"
        print(f"picture {OUT / 'final.png'}")
