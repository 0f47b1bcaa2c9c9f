"""Several materials in one body (``[[region]]``, :mod:`fem_anim.mesh.regions`).

1. **Assembly against the numpy reference** on a two-region box (the reference beam of
   ``tests/test_reference_comparison.py``, cells with centroid x < 0.5 in one region): the
   elastic energy, its ``ufl.derivative`` gradient and Hessian, the mass matrix and the step
   objective equal the reference's sums with per-cell parameters and per-cell material models
   to round-off. Regions are given both as mesh physical groups and as boxes, with a later
   box overriding part of an earlier region.
2. **A two-material bar under a static pull** (soft and stiff halves in series): a handle
   stretches the bar by delta; for linear elasticity with nu = 0 the exact solution is
   piecewise linear, so the P1 solution is exact: each half elongates by
   delta (L_i/E_i) / sum_j (L_j/E_j), the stiff half strains less by the stiffness ratio, and
   the pull force is the series spring's A delta / sum_j (L_j/E_j). A neo-Hookean bar at 0.1 %
   strain agrees to O(strain).
3. **Validation**: unknown group names list the known ones, empty regions, overlaps that leave
   a region without cells, box regions named like a group, incompatible settings.
"""

from __future__ import annotations

import math

import subprocess

import numpy as np
import pytest
import ufl
from conftest import ROOT, fem_anim_command
from dolfinx import fem
from mpi4py import MPI
from scenes import DIVISIONS, LENGTHS, bar, beam, make_scene, wall_pin
from test_analytic import assembled_vector, scipy_matrix, set_displacement
from test_reference_comparison import (
    ASSEMBLY_RTOL,
    assert_close,
    deformed_positions,
    reference_order,
    step_callbacks,
)

from fem_anim import compat, reference
from fem_anim.errors import SceneError
from fem_anim.mesh.simplex import mesh_from_arrays
from fem_anim.problem.objective import EnergyProblem
from fem_anim.simulation.loop import Simulation

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                reason="serial: the numpy reference and the dof map are rank-local")

GROUPS = {"soft": 1, "stiff": 2}


def write_scene(directory, name: str, d: int, regions: str, **overrides):
    """The reference beam, neo-Hookean, with ``regions`` (TOML text) appended."""
    scene = beam(name, d, material={"model": "neohookean"}, **overrides)
    return make_scene(directory, scene, regions)


def two_region_beam(d: int, divisions=None, lengths=None):
    """The reference beam with markers 1 (``soft``, centroid x < L/2) and 2 (``stiff``)."""
    divisions, lengths = divisions or DIVISIONS[d], lengths or LENGTHS[d]
    points, cells = reference.box_mesh(divisions, lengths)
    centroids = points[cells].mean(axis=1)
    markers = np.where(centroids[:, 0] < 0.5 * lengths[0], 1, 2).astype(np.int32)
    domain = mesh_from_arrays(MPI.COMM_SELF, points, cells, markers, "two-region beam", GROUPS)
    return points, cells, centroids, domain


# --- 1. assembly against the reference -----------------------------------------------------------

#: (regions of the scene, expected per-cell (model, E, nu, rho) as a function of the centroid)
CASES = {
    "groups-same-model": (
        """[[region]]
name = "stiff"
youngs_modulus = 8.0e4
poisson_ratio = 0.2
density = 3000.0
""",
        lambda c: np.where(c[:, 0] < 0.5, 0, 1), ["neohookean", "neohookean"],
        [1.0e4, 8.0e4], [0.3, 0.2], [1000.0, 3000.0]),
    "groups-and-box-three-models": (
        """[[region]]
name = "stiff"
model = "stvk"
youngs_modulus = 8.0e4
density = 3000.0
[[region]]
name = "tip"
min = [0.75, -1.0, -1.0]
max = [2.0, 1.0, 1.0]
model = "corotated"
poisson_ratio = 0.45
""",
        lambda c: np.where(c[:, 0] < 0.5, 0, np.where(c[:, 0] < 0.75, 1, 2)),
        ["neohookean", "stvk", "corotated"], [1.0e4, 8.0e4, 1.0e4], [0.3, 0.3, 0.45],
        [1000.0, 3000.0, 1000.0]),
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("d", (2, 3))
def test_two_region_assembly_matches_reference(tmp_path, d, case):
    """Energy, gradient, Hessian, mass and the step objective with per-cell materials."""
    regions, which, models, E, nu, rho = CASES[case]
    regions = regions.replace(", -1.0, -1.0]", ", -1.0]" if d == 2 else ", -1.0, -1.0]")
    regions = regions.replace(", 1.0, 1.0]", ", 1.0]" if d == 2 else ", 1.0, 1.0]")
    scene = write_scene(tmp_path, f"{case}_{d}", d, regions,
                        gravity={"acceleration": [0.0, -9.81, 0.0][:d]})
    points, cells, centroids, domain = two_region_beam(d)
    problem = EnergyProblem(scene, domain)
    assert len(problem.elastic_terms) == len(set(models))
    k = which(centroids)
    material = np.asarray(models)[k]
    E_c, nu_c, rho_c = (np.asarray(v)[k] for v in (E, nu, rho))
    mu, lmbda = reference.lame_parameters(E_c, nu_c)
    ref = reference.build_problem(points, cells, material, E_c, nu_c, rho_c,
                                  [0.0, -9.81, 0.0][:d])

    order = reference_order(domain, problem.V)
    X = points.ravel()
    x = deformed_positions(points, cells, "rotated", seed=5)
    u = np.empty_like(x)
    u[order] = x - X
    set_displacement(problem, u)
    energy = problem.ufl_elastic
    gradient = ufl.derivative(energy, problem.u, ufl.TestFunction(problem.V))
    hessian = ufl.derivative(gradient, problem.u, ufl.TrialFunction(problem.V))
    forms = [fem.form(f) for f in (energy, gradient, hessian)]
    args = (points, cells, material, mu, lmbda, x)
    assert_close("elastic energy", problem.assemble_scalar(forms[0]),
                 reference.elastic_energy(*args), ASSEMBLY_RTOL)
    assert_close("elastic gradient", assembled_vector(forms[1])[order],
                 reference.elastic_gradient(*args), ASSEMBLY_RTOL)
    assert_close("elastic Hessian", scipy_matrix(forms[2])[order][:, order],
                 reference.elastic_hessian(*args), ASSEMBLY_RTOL)
    # the frames' energy density field: each cell's own material
    density = problem.cell_energy_density(problem.u.x.array.copy())
    volumes = np.abs(np.linalg.det(points[cells[:, 1:]] - points[cells[:, :1]])) / \
        math.factorial(d)
    original = np.asarray(domain.mesh.topology.original_cell_index)[:len(density)]
    assert_close("cell energy density", volumes[original] @ density,
                 reference.elastic_energy(*args), ASSEMBLY_RTOL)
    M = scipy_matrix(problem.mass_form)[order][:, order]
    assert_close("mass matrix", M, ref.mass, ASSEMBLY_RTOL)

    # the step objective SNES sees: g = 1/2 |x - y|_M^2 + w E, residual and Jacobian
    y = deformed_positions(points, cells, "perturbed", seed=6)
    w = 1e-3
    problem.weight.value = w
    problem.u_pred.x.array[order] = y - X
    g = 0.5 * (x - y) @ (ref.mass @ (x - y)) + w * ref.energy(x)
    value, residual, jacobian = step_callbacks(problem, u)
    assert_close("objective", value - w * ref.gravity_force @ X, g, ASSEMBLY_RTOL)
    assert_close("residual", residual[order], ref.mass @ (x - y) + w * ref.gradient(x),
                 ASSEMBLY_RTOL)
    assert_close("Jacobian", jacobian[order][:, order], ref.mass + w * ref.hessian(x),
                 ASSEMBLY_RTOL)


def test_corotated_data_is_computed_only_where_corotated_cells_read_it(tmp_path):
    """With three models, corotated's stretch trace (a batched SVD per quadrature point) is
    evaluated on the corotated cells alone, and there equals the SVD of F; the other cells'
    values are never read (each model integrates over its own tagged cells), so the elastic
    energy still equals the reference's (test above) at a fraction of the work."""
    from fem_anim.forms.corotated import stretch_trace

    regions, which, models, *_ = CASES["groups-and-box-three-models"]
    scene = write_scene(tmp_path, "corotated_cells", 3, regions)
    points, cells, centroids, domain = two_region_beam(3)
    problem = EnergyProblem(scene, domain)
    order = reference_order(domain, problem.V)
    x = deformed_positions(points, cells, "rotated", seed=5)
    u = np.empty_like(x)
    u[order] = x - points.ravel()
    set_displacement(problem, u)
    problem.update_quadrature_data()
    [data] = problem.quadrature_data
    original = np.asarray(domain.mesh.topology.original_cell_index)
    corotated = np.flatnonzero(np.asarray(models)[which(centroids[original])] == "corotated"
                               ).astype(np.int32)
    assert 0 < corotated.size < original.size
    assert np.array_equal(np.sort(data.cells), corotated)
    F = compat.evaluate(data.expression, domain.mesh, corotated).reshape(-1, 3, 3)
    dofs = compat.cell_dofs(data.function.function_space)
    values = data.function.x.array
    assert np.allclose(values[dofs[corotated].ravel()], stretch_trace(F), rtol=1e-14)
    others = np.setdiff1d(np.arange(original.size), corotated)
    assert not values[dofs[others].ravel()].any()


# --- 2. the two-material bar ---------------------------------------------------------------------

BAR_LENGTHS = (1.0, 0.1, 0.1)
BAR_DIVISIONS = (8, 1, 1)
SOFT, STIFF = 1.0e4, 1.0e5  # Pa: stiffness ratio 10
PULL_TIME = 1.0e4  # s: one implicit Euler step this long is a static solve (inertia ~1e-9)


def pull_bar(tmp_path, model: str, delta: float, nu: float = 0.0):
    """Pin x = 0, move the x = L face by ``delta`` in one long implicit Euler step."""
    L = BAR_LENGTHS[0]
    scene = make_scene(tmp_path, bar(
        f"bar_{model}", mesh={"size": list(BAR_LENGTHS)},
        material={"model": model, "youngs_modulus": SOFT, "poisson_ratio": nu, "density": 1000.0},
        region=[{"name": "stiff_half", "min": [L / 2, -1.0, -1.0], "max": [2 * L, 1.0, 1.0],
                 "youngs_modulus": STIFF}],
        time={"integrator": "implicit_euler", "dt": PULL_TIME, "steps": 1},
        pin=[wall_pin(), {"name": "handle", "min": [L - 1e-6, -1.0, -1.0],
                          "max": [L + 1e-6, 1.0, 1.0], "velocity": [delta / PULL_TIME, 0.0, 0.0]}]))
    points, cells = reference.box_mesh(BAR_DIVISIONS, BAR_LENGTHS)
    domain = mesh_from_arrays(MPI.COMM_SELF, points, cells, None, "bar")
    sim = Simulation(scene, MPI.COMM_SELF, {"snes_rtol": "1e-14", "snes_atol": "1e-16"},
                     domain=domain)
    state, _ = sim.step(sim.initial_state(), PULL_TIME)
    u = sim.gather.gather(state.u)
    # the pull force: the elastic forces on the handle's dofs, x components
    p = sim.problem
    force = assembled_vector(p.potential_gradient_form).reshape(-1, 3)
    X = p.V.tabulate_dof_coordinates()
    handle = np.abs(X[:, 0] - L) < 1e-9
    sim.minimiser.destroy()
    return points, cells, u, float(force[handle, 0].sum())


@pytest.mark.parametrize("model, rtol", [("linear", 1e-8), ("neohookean", 5e-3)])
def test_two_material_bar_is_a_series_spring(tmp_path, model, rtol):
    """Elongation per half, strain ratio and pull force of two springs in series."""
    L, A = BAR_LENGTHS[0], BAR_LENGTHS[1] * BAR_LENGTHS[2]
    delta = 1e-3 * L
    points, cells, u, force = pull_bar(tmp_path, model, delta)
    compliance = (L / 2) / SOFT + (L / 2) / STIFF
    middle = np.abs(points[:, 0] - L / 2) < 1e-9
    soft_elongation = u[middle, 0].mean()
    expected = delta * (L / 2) / SOFT / compliance
    assert_close("elongation of the soft half", soft_elongation, expected, rtol)
    assert_close("elongation of the stiff half", delta - soft_elongation, delta - expected, rtol)
    F = reference.deformation_gradient(points, cells, (points + u).ravel())
    strain = F[:, 0, 0] - 1.0
    stiff = points[cells].mean(axis=1)[:, 0] > L / 2
    ratio = strain[~stiff].mean() / strain[stiff].mean()
    assert_close("strain ratio", ratio, STIFF / SOFT, rtol)
    assert_close("pull force", force, A * delta / compliance, rtol)


# --- 3. validation -------------------------------------------------------------------------------


def problem_error(tmp_path, d: int, regions: str) -> str:
    scene = write_scene(tmp_path, "bad", d, regions)
    _, _, _, domain = two_region_beam(d)
    with pytest.raises(SceneError) as err:
        EnergyProblem(scene, domain)
    return str(err.value)


def test_unknown_group_lists_the_known_ones(tmp_path):
    message = problem_error(tmp_path, 2, '[[region]]\nname = "middle"\ndensity = 2.0\n')
    assert "region[0].name = 'middle' is not a physical group" in message
    assert "known: soft, stiff" in message


def test_empty_box_region(tmp_path):
    message = problem_error(tmp_path, 2, '[[region]]\nname = "far"\nmin = [5.0, 5.0]\n'
                            'max = [6.0, 6.0]\ndensity = 2.0\n')
    assert "region[0] (far) selects no cells" in message


def test_region_overridden_entirely_by_a_later_one(tmp_path):
    message = problem_error(tmp_path, 2, '[[region]]\nname = "soft"\ndensity = 2.0\n'
                            '[[region]]\nname = "everything"\nmin = [-1.0, -1.0]\n'
                            'max = [2.0, 2.0]\ndensity = 3.0\n')
    assert "region[0] (soft): all its cells are taken by region[1] (everything)" in message


def test_box_region_named_like_a_group(tmp_path):
    message = problem_error(tmp_path, 2, '[[region]]\nname = "soft"\nmin = [0.0, 0.0]\n'
                            'max = [0.2, 0.2]\ndensity = 2.0\n')
    assert "'soft' is a physical group of the mesh" in message


@pytest.mark.parametrize("regions, message", [
    ('[[region]]\nname = "a"\nmin = [0.0, 0.0]\ndensity = 2.0\n', "give both min and max"),
    ('[[region]]\nname = "a"\nmin = [0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\ndensity = 2.0\n',
     "region[0].min and region[0].max must have 2 entries"),
    ('[[region]]\nname = "a"\nmin = [0.5, 0.0]\nmax = [0.1, 1.0]\ndensity = 2.0\n',
     "region[0] (a) is an empty box"),
    ('[[region]]\nname = "soft"\n', "region[0] (soft) sets no material key"),
    ('[[region]]\nname = "soft"\ndensity = 2.0\n[[region]]\nname = "soft"\ndensity = 3.0\n',
     "region[1] (soft): the name is already used by region[0]"),
    ('[[region]]\nname = "soft"\nmodel = "rubber"\n', "region[0].model must be one of"),
    ('[[region]]\nname = "soft"\npoisson_ratio = 0.5\n', "region[0].poisson_ratio must be in"),
    ('[[region]]\ndensity = 2.0\n', "region[0].name is required"),
    ('[[region]]\nname = "soft"\nmodel = "stvk"\n[solver]\nhessian = "project"\n',
     "solver.hessian = \"project\" takes one material model per body"),
])
def test_bad_region_settings(tmp_path, regions, message):
    with pytest.raises(SceneError, match=None) as err:
        write_scene(tmp_path, "bad", 2, regions)
    assert message in str(err.value)


def test_command_line_error_for_an_unknown_group(tmp_path):
    """One line, exit code 2, on a real mesh file with named groups."""
    scene = tmp_path / "groups.toml"
    scene.write_text(f"""[mesh]
shape = "file"
file = "{ROOT / 'meshes' / 'data' / 'two_region_box.msh'}"
[[region]]
name = "middle"
youngs_modulus = 1e6
""")
    r = subprocess.run(fem_anim_command() + ["run", str(scene), "-o", str(tmp_path / "out")],
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr
    assert r.stderr.strip().splitlines() == [
        "fem-anim: error: region[0].name = 'middle' is not a physical group of the "
        "mesh (known: left, right); to select cells by position give min and max"]
