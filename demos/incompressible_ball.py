# %% [markdown]
# # An incompressible ball squashed and released
#
# Nearly and exactly incompressible solids (issue 17). A soft rubber ball (radius 10 cm,
# E = 1e4 Pa, 1000 kg/m^3) with Poisson's ratio exactly 0.5 cannot be simulated with
# displacements alone: lambda is infinite. The mixed formulation adds a pressure p and
# makes each step a saddle point of (seed eq. 4, BDF2 with w = 4 h^2 / 9)
#
#     g(u, p) = 1/2 ||u - y||_M^2 + w int [ psi_dev(F) + p (J - 1) - p^2 / (2 kappa) ] dX,
#
# with the stable neo-Hookean deviatoric part psi_dev (`forms/incompressible.py`) and 1/kappa = 0,
# u in P2 and p in P1 (Taylor-Hood). The pressure has no inertia. For every P1 function q
# the step's solution satisfies int q (J - 1) dX = 0, so with q = 1 the volume of the body
# is exactly its rest volume (to the solver tolerance), while single cells may still
# change volume slightly (the constraint is weak).
#
# The ball's bottom cap is pinned; a press holds its top cap and moves it down 3 cm in
# 0.1 s (`demos/incompressible_ball.toml`). Then the press lets go: the demo continues the
# same state with the bottom pin only, and the ball springs back and wobbles. The demo
# asserts that the volume stays at its rest value at every step of both phases, that the
# squashed ball bulges sideways (it must, to keep its volume) and that it springs back
# after the release. Set FEM_ANIM_DEMO_REDUCED=1 for the short variant the tests run.

# %%
import dataclasses
import os
from pathlib import Path

import numpy as np
import ufl
from fem_anim.forms.kinematics import deformation_gradient
from mpi4py import MPI

from fem_anim import compat
from fem_anim.scene import load_scene
from fem_anim.simulation import Simulation

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "incompressible_ball"
overrides = ["mesh.element_size=0.05"] if REDUCED else []
RELEASED_STEPS = 10 if REDUCED else 40

# %% [markdown]
# ## The press phase
# The scene as written: both pins, the press moving. `Simulation.step` solves each saddle
# point with Newton on the residual (no objective: a line search on ||r||) and MUMPS LDL^T.

# %%
scene = load_scene(HERE / "incompressible_ball.toml", overrides)
press = Simulation(scene, MPI.COMM_WORLD)
p = press.problem
comm = p.comm

# The volume int J dX (exact for P2 with degree 4 quadrature) and the extent of the ball.
dx = ufl.Measure("dx", domain=press.domain.mesh, metadata={"quadrature_degree": 4})
forms = compat.compile_forms_together(
    {"volume": ufl.det(deformation_gradient(p.u)) * dx, "rest": 1.0 * dx}, {})
rest_volume = p.assemble_scalar(forms["rest"])
X = p.V.tabulate_dof_coordinates()[: p.V.dofmap.index_map.size_local, :3]


def measure(sim, state):
    """(relative volume change, height of the top, width of the ball) of a state."""
    sim.problem.u.x.array[:] = state.u
    volume = sim.problem.assemble_scalar(forms["volume"]) / rest_volume - 1.0
    x = X + state.u.reshape(-1, 3)[: X.shape[0]]
    top = comm.allreduce(x[:, 2].max() if x.size else -np.inf, op=MPI.MAX)
    width = comm.allreduce(x[:, 0].max() if x.size else -np.inf, op=MPI.MAX) - \
        comm.allreduce(x[:, 0].min() if x.size else np.inf, op=MPI.MIN)
    return volume, top, width


h = scene["time"]["dt"]
state = press.initial_state()
rows = [(0.0, *measure(press, state), 0)]
for _ in range(scene["time"]["steps"]):
    state, stats = press.step(state, h)
    rows.append((state.time, *measure(press, state), stats.newton_its))

# %% [markdown]
# ## The release
# The same mesh and state, the press pin dropped: a second `Simulation` on the same domain
# (so the dof numbering is the same) continues from the squashed state with its velocity.

# %%
free = dataclasses.replace(scene, data=scene.data | {"pin": scene["pin"][:1]})
released = Simulation(free, MPI.COMM_WORLD, domain=press.domain)
state = dataclasses.replace(state, u_old=None, v_old=None)  # BDF2 restarts with one Euler step
for _ in range(RELEASED_STEPS):
    state, stats = released.step(state, h)
    rows.append((state.time, *measure(released, state), stats.newton_its))

# %% [markdown]
# ## What the run must show

# %%
t, volume, top, width, newton = (np.array(c) for c in zip(*rows))
squashed = int(np.argmin(top))
if comm.rank == 0:
    print(f"max |V/V0 - 1| {np.abs(volume).max():.2e}; top {top[0]:.4f} -> {top[squashed]:.4f} "
          f"m at t = {t[squashed]:.2f} s -> max {top[squashed:].max():.4f} m after release; "
          f"width {width[0]:.4f} -> {width[squashed]:.4f} m; Newton its per step "
          f"{np.median(newton[1:]):.0f} (max {newton.max()})")
assert np.abs(volume).max() < 1e-9, "the volume changed"
assert top[squashed] < top[0] - 0.025, "the press did not squash the ball"
assert width[squashed] > width[0] + 0.005, "the squashed ball did not bulge"
assert top[squashed:].max() > top[squashed] + 0.01, "the ball did not spring back"

# %% [markdown]
# ## The volume against time (rank 0 writes `incompressible_ball.png` in the full run)

# %%
if comm.rank == 0:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    OUT.mkdir(parents=True, exist_ok=True)
    fig, (a, b) = plt.subplots(2, 1, figsize=(6, 5), sharex=True)
    a.plot(t, top, label="top of the ball")
    a.plot(t, width / 2, label="half width")
    a.axvline(0.1, color="grey", lw=0.5)
    a.set_ylabel("m")
    a.legend()
    b.plot(t, volume, "k.-")
    b.set_ylabel("V / V0 - 1")
    b.set_xlabel("t (s): pressed until 0.1 s, then released")
    fig.tight_layout()
    fig.savefig(OUT / "incompressible_ball.png", dpi=100)
    print(f"picture {OUT / 'incompressible_ball.png'}")
