# %% [markdown]
# # A 2D cantilever plate sagging under gravity
#
# `demos/plate_2d.toml`: a 1 x 0.1 m plate in plane strain (`mesh.dim = 2`, P2 triangles),
# neo-Hookean with E = 2e7 Pa, nu = 0.3, 1000 kg/m^3, clamped at x = 0 and released straight
# under gravity, with Rayleigh damping alpha = 6/s. Each Newmark step minimises
#
#     g(x) = 1/2 ||x - y||_M^2 + h^2/4 (E_elastic(x) - int rho g . x) + D(x)
#
# (seed eq. 4; D the damping's dissipation potential). The demo asserts:
#
# * the damped motion dissipates: the total energy (kinetic + elastic + gravity) never rises;
# * the plate comes to rest at the static solution, computed separately as one implicit Euler
#   step of 10^4 s from rest (the inertia term is then ~1e-7 of the elastic one): the tip
#   deflection agrees to 0.5 %;
# * the static tip deflection matches Euler-Bernoulli beam theory for plane strain,
#   w = q L^4 / (8 E' I), q = rho g t, E' = E / (1 - nu^2), I = t^3/12, within 3 % (shear and
#   finite rotation make the plate differ by about 1 %).
#
# The full run writes `out/demos/plate_2d/plate_2d.png`
# (`demos/plate_2d.png`, shown in the README, is a copy).

# %%
import os
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim.scene import load_scene
from fem_anim.simulation import Simulation

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "plate_2d"
reduced = ["mesh.element_size=0.05", "time.dt=0.03333333333333333", "time.steps=75",
           "output.render=false"] if REDUCED else []
scene = load_scene(HERE / "plate_2d.toml", reduced)
rank0 = MPI.COMM_WORLD.rank == 0


def tip_deflection(run) -> float:
    """Vertical displacement of the tip's mid-thickness point (rank 0)."""
    points = sim.domain.points
    tip = np.argmin(np.linalg.norm(points - [1.0, 0.05], axis=1))
    return float(-run.final_displacement[tip, 1])


# %% [markdown]
# ## The swing, and the static solution

# %%
sim = Simulation(scene, MPI.COMM_WORLD)
swing = sim.run(OUT, quiet=True)
w_dynamic = tip_deflection(swing) if rank0 else None

static_scene = load_scene(HERE / "plate_2d.toml", reduced + [
    "time.integrator=implicit_euler", "time.dt=1e4", "time.steps=1", "output.render=false"])
sim = Simulation(static_scene, MPI.COMM_WORLD)
static = sim.run(None, quiet=True)
w_static = tip_deflection(static) if rank0 else None

# %% [markdown]
# ## What the run must show

# %%
if rank0:
    m = scene["material"]
    E, nu, rho = m["youngs_modulus"], m["poisson_ratio"], m["density"]
    L, t = scene["mesh"]["size"]
    q = rho * 9.81 * t
    w_beam = q * L**4 / (8 * E / (1 - nu**2) * t**3 / 12)
    energy = np.array([r["total_energy"] for r in swing.rows])
    rise = np.max(np.diff(energy))
    print(f"tip deflection: settled {w_dynamic * 1e3:.2f} mm, static {w_static * 1e3:.2f} mm "
          f"({w_dynamic / w_static - 1:+.2%}), Euler-Bernoulli {w_beam * 1e3:.2f} mm "
          f"({w_static / w_beam - 1:+.2%}); largest energy rise per step {rise:.1e} J of "
          f"{abs(energy).max():.2f} J")
    assert rise <= 1e-9 * abs(energy).max()
    assert abs(w_dynamic / w_static - 1.0) < 0.005
    assert abs(w_static / w_beam - 1.0) < 0.03
    if not REDUCED:
        from fem_anim.render.process import render_file

        render_file(swing.output_dir / "final.vtu", OUT / "plate_2d.png",
                    title=f"2D plate at rest, tip sag {w_dynamic * 1e3:.1f} mm")
        print(f"picture {OUT / 'plate_2d.png'}")
