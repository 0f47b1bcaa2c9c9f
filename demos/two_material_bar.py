# %% [markdown]
# # Two materials in one bar: springs in series
#
# `demos/two_material_bar.toml`: the 0.2 x 0.1 x 0.1 m box of `meshes/data/two_region_box.msh`,
# whose gmsh physical volumes `left` (x < 0.1 m) and `right` (x > 0.1 m) become regions of
# different material: the body's `[material]` (neo-Hookean, E_1 = 1e5 Pa, nu = 0,
# 1000 kg/m^3) on the left, and a `[[region]]` named `right` with E_2 = 1e6 Pa. The elastic
# energy is a sum over the regions (`fem_anim.mesh.regions`),
#
#     E(u) = int_left psi(F; mu_1, lmbda_1) dV + int_right psi(F; mu_2, lmbda_2) dV,
#
# and each step minimises g(x) = 1/2 ||x - y||_M^2 + h^2 E(x) (implicit Euler, seed section
# 3.1), its numerical dissipation and Rayleigh damping (alpha = 40/s) letting the bar come to
# rest. The face x = 0 is held and a handle pulls
# the face x = L = 0.2 m by delta = 2 mm (1 % strain) during the first 0.25 s.
#
# At rest the halves are two springs in series, each of stiffness k_i = E_i A / L_i. For
# small strain the soft half elongates by delta k_2 / (k_1 + k_2) = 10/11 delta, the stiff one
# by 1/11 delta, and the strains differ by the stiffness ratio E_2 / E_1 = 10. With nu = 0
# (lmbda = 0) the neo-Hookean stress of F = diag(s, 1, 1) is P_xx = mu (s - 1/s) and the
# lateral stress vanishes, so the exact solution is piecewise homogeneous: stretches s_1, s_2
# with mu_1 (s_1 - 1/s_1) = mu_2 (s_2 - 1/s_2) and L/2 (s_1 + s_2 - 2) = delta. P1 elements
# represent it exactly. The demo asserts the elongations against that 1D solution (to 1e-8,
# measured 3e-11), the linear series-spring values to 1 % and the strain ratio
# to the stiffness ratio within 2 % (the neo-Hookean response at 1.8 % strain is that much
# softer than linear). The full run writes `out/demos/two_material_bar/two_material_bar.png`
# (`demos/two_material_bar.png`, shown in the README, is a copy).

# %%
import os
from pathlib import Path

import numpy as np
from mpi4py import MPI
from scipy.optimize import brentq

from fem_anim.reference import deformation_gradient
from fem_anim.scene import load_scene
from fem_anim.simulation import Simulation

REDUCED = os.environ.get("FEM_ANIM_DEMO_REDUCED") == "1"
HERE = Path(__file__).resolve().parent
OUT = Path(os.environ.get("FEM_ANIM_DEMO_OUT", "out/demos")) / "two_material_bar"
overrides = ["time.steps=60", "time.dt=0.01", "output.render=false"] if REDUCED else []
scene = load_scene(HERE / "two_material_bar.toml", overrides)
E1 = scene["material"]["youngs_modulus"]
E2 = scene["region"][0]["youngs_modulus"]
L, delta = 0.2, scene["pin"][1]["velocity"][0] * scene["pin"][1]["until"]

# %% [markdown]
# ## Run

# %%
sim = Simulation(scene, MPI.COMM_WORLD)
run = sim.run(OUT, quiet=True)
last = run.rows[-1]
print(f"t = {run.state.time:.2f} s, kinetic {last['kinetic']:.2e} J, elastic "
      f"{last['elastic']:.3e} J")

# %% [markdown]
# ## What the run must show
# Elongations from the displacement of the interface x = 0.1 m; strains from F_xx - 1 per
# cell (rank 0, input vertex order).

# %%
def stretches(mu1: float, mu2: float) -> tuple[float, float]:
    """The 1D neo-Hookean series solution (s_1, s_2) for the elongation delta."""
    def other(s1):
        stress = mu1 * (s1 - 1 / s1)
        return brentq(lambda s: mu2 * (s - 1 / s) - stress, 0.5, 2.0, xtol=1e-15)

    s1 = brentq(lambda s: L / 2 * (s + other(s) - 2) - delta, 1.0, 1.0 + 4 * delta / L,
                xtol=1e-15)
    return s1, other(s1)


if MPI.COMM_WORLD.rank == 0:
    points, cells = sim.domain.points, sim.domain.cells
    u = run.final_displacement[:, :3]
    soft = u[np.abs(points[:, 0] - L / 2) < 1e-9, 0].mean()
    expected = delta * E2 / (E1 + E2)
    F = deformation_gradient(points, cells, (points + u).ravel())
    strain = F[:, 0, 0] - 1.0
    stiff_cells = points[cells].mean(axis=1)[:, 0] > L / 2
    ratio = strain[~stiff_cells].mean() / strain[stiff_cells].mean()
    print(f"soft half elongates {soft * 1e3:.4f} mm (series springs: {expected * 1e3:.4f} mm, "
          f"error {soft / expected - 1:+.2%}); stiff half {(delta - soft) * 1e3:.4f} mm")
    s1, s2 = stretches(E1 / 2, E2 / 2)  # mu = E / 2 for nu = 0
    exact = L / 2 * (s1 - 1)
    print(f"strain ratio soft/stiff {ratio:.3f} (stiffness ratio {E2 / E1:.0f}, 1D neo-Hookean "
          f"{(s1 - 1) / (s2 - 1):.3f}); soft elongation vs the 1D neo-Hookean solution "
          f"{soft / exact - 1:+.1e}")
    assert abs(soft / exact - 1.0) < 1e-8
    assert abs(soft / expected - 1.0) < 0.01
    assert abs(ratio / (E2 / E1) - 1.0) < 0.02
    assert last["kinetic"] < 1e-4 * last["elastic"], "the bar should have come to rest"
    if not REDUCED:
        from fem_anim.render.process import render_file

        render_file(run.output_dir / "final.vtu", OUT / "two_material_bar.png",
                    title="soft (left) and stiff (right) halves pulled by 2 mm")
        print(f"picture {OUT / 'two_material_bar.png'}")
