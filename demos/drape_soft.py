# %% [markdown]
# # A cloth draped over a soft block
#
# A thin shell and a soft solid in contact, in one run (issue 30): a 0.6 m square of cloth
# (t = 1 mm, StVK membrane, E = 1 MPa, 0.3 kg/m^2, hinge bending derived from E, nu and t)
# falls onto a jelly block (0.24 x 0.24 x 0.16 m, neo-Hookean, E = 20 kPa, nu = 0.4,
# 1000 kg/m^3) resting on the ground, drapes over it, and its corners fall towards the
# ground. DOLFINx has one cell type per mesh, so the cloth (triangles in 3D) and the block
# (tetrahedra) are two meshes with two displacement spaces, but each time step is ONE
# minimisation over both unknowns x = (x_block, x_cloth) (seed eq. 4, implicit Euler,
# w = h^2):
#
#     g(x) = 1/2 ||x - y||_M^2 + w [ E_block(x_block) + E_cloth(x_cloth) + E_gravity(x)
#                                     + E_ground(x) + B(x) + D(x) ]
#            + Rayleigh's mass-proportional dissipation,
#
# E_ground the ground's barrier on both bodies' vertices (the cloth's at its face, t / 2
# below the mid-surface), B the IPC Toolkit's barrier on the union of the block's boundary
# triangles and the cloth's triangles with the thickness t as the minimum distance (the
# cloth's mid-surface stays t from the block and from its own other layers), D IPC's lagged
# friction. One Newton system over both bodies, each line-search trial bounded by one
# continuous collision detection of the joint step: the contact between cloth and block is
# implicit, not staggered (`fem_anim/problem/joint_objective.py`, docs/cloth.md).
#
# The demo asserts its physics on the frames read back from disk: in no frame does a
# triangle of the cloth cross a boundary triangle of the block or another triangle of the
# cloth, nor does a vertex of the cloth lie inside the block (the independent numpy check of
# `fem_anim/contact/intersection.py` on both meshes together), no vertex of either body
# comes closer to the ground than it may, the cloth lies on the block (its highest point t
# above the block's top) and the block carries it (its top sinks). The scene is
# `demos/drape_soft.toml` (`fem-anim run demos/drape_soft.toml`). Set
# FEM_ANIM_DEMO_REDUCED=1 for the short, coarse variant the test suite runs.

# %%
import os
import tomllib
from pathlib import Path

import h5py
import numpy as np
from mpi4py import MPI

from fem_anim.contact.intersection import boundary_triangles, intersecting
from fem_anim.scene import Scene
from fem_anim.simulation.joint_run import run_joint

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "drape_soft"

# %% [markdown]
# ## The scene
# The reduced variant takes coarser meshes and 14 steps (the cloth lands at the 9th).

# %%
data = tomllib.loads((HERE / "drape_soft.toml").read_text())
if REDUCED:
    data["time"]["steps"] = 14
    data["output"] = {"render": False}
    data["body"][0]["mesh"]["element_size"] = 0.08
    data["body"][1]["mesh"]["element_size"] = 0.1
scene = Scene.from_dict(data, source=str(HERE / "drape_soft.toml"), base_dir=HERE)

# %% [markdown]
# ## Run it
# `run_joint` is `fem-anim run`'s path for a shell beside solids: `solids.xdmf` and
# `shell.xdmf` (each mesh's frames), `trajectory.xdmf` (what is seen: the block's boundary
# and the cloth, which the renderer draws: `final.png`, `animation.mp4`), `stats.csv` (with
# `contact_pairs`: the IPC pairs of cloth and block and of the cloth with itself),
# `final_solids.vtu`, `final_shell.vtu`, `summary.json`.

# %%
rows, report = run_joint(scene, OUT, MPI.COMM_WORLD, quiet=True)

# %% [markdown]
# ## What the run must show
# The geometry is read from the scene file, the motion from the written trajectories.

# %%


def frames(path: Path):
    """Rest points, cells and every frame's displacement of one trajectory."""
    with h5py.File(path, "r") as h5:
        count = len(h5.attrs["times"])
        return (np.asarray(h5["data0"]), np.asarray(h5["data1"]),
                [np.asarray(h5[f"data{k + 2}"]) for k in range(count)])


if MPI.COMM_WORLD.rank == 0:
    t = data["body"][1]["shell"]["thickness"]
    size, origin = data["body"][0]["mesh"]["size"], data["body"][0]["mesh"]["origin"]
    top = origin[2] + size[2]
    Xs, tets, us = frames(OUT / "solids.h5")
    Xc, tris, uc = frames(OUT / "shell.h5")
    surface = np.concatenate([boundary_triangles(tets), tris + len(Xs)])
    crossed = [k for k, (a, b) in enumerate(zip(us, uc))
               if intersecting(np.concatenate([Xs + a, Xc + b]), surface)]
    block_ground = min((Xs[:, 2] + u[:, 2]).min() for u in us)
    cloth_ground = min((Xc[:, 2] + u[:, 2]).min() for u in uc)
    block, cloth = Xs + us[-1], Xc + uc[-1]
    block_top = block[:, 2].max()
    # the cloth over the block's top face (1 cm in from its edges)
    over = np.all(np.abs(cloth[:, :2] - (np.asarray(origin[:2]) + 0.5 * np.asarray(size[:2])))
                  < 0.5 * np.asarray(size[:2]) - 0.01, axis=1)
    gap = cloth[over, 2] - block_top
    kinetic = rows[-1]["kinetic"]
    released = rows[0]["gravity"] - min(r["gravity"] for r in rows)
    newton = [r["newton_its"] for r in rows]
    pairs = [r["contact_pairs"] for r in rows]
    print(f"{len(uc)} frames, {len(rows)} steps ({sum(r['retries'] for r in rows)} retried), "
          f"crossed: {crossed}; block top {top:.4f} -> {block_top:.4f} m; cloth over it "
          f"{gap.min() * 1e3:.2f} to {gap.max() * 1e3:.2f} mm above it (t = {t * 1e3:g} mm); "
          f"lowest cloth vertex {cloth_ground * 1e3:.2f} mm, lowest block vertex "
          f"{block_ground * 1e3:.2f} mm; kinetic {kinetic:.3g} J of {released:.3g} J released; "
          f"contact pairs max {max(pairs)}; Newton its median {np.median(newton):.0f}, max "
          f"{max(newton)}; mean step {np.mean([r['step_wall_s'] for r in rows]):.2f} s")
    assert not crossed, f"frames {crossed} have an intersection"
    assert block_ground > 0.0 and cloth_ground > t / 2, "a body reached the ground"
    assert max(pairs) > 0, "the cloth never touched the block"
    assert block_top < top, "the block did not give under its weight"
    assert over.any() and gap.min() > 0.0 and gap.max() < 0.02, \
        "the cloth does not lie on the block"
    assert not report["gained"], "the run gained energy"
    if not REDUCED:
        assert cloth_ground < t / 2 + 2e-3, "the cloth's corners never reached the ground"
        assert kinetic < 0.02 * released, "the bodies have not settled"
        print(f"picture {OUT / 'final.png'}")
