"""Terms of the step objective as compiled by :class:`fem_anim.problem.objective.EnergyProblem`.

g(u) = 1/2 ||u - u_pred||_M^2 + w [ int psi(F(u)) dV - int rho g.u dV ]      (seed eq. 4)

* mass: lumped (vertex rule, seed footnote 4) and consistent (eqs. (17)-(20)) mass matrices
  carry the same total mass rho * volume and the same linear momentum for a uniform velocity,
  in 2D and 3D; the lumped matrix is diagonal and holds the row sums of the consistent one;
* a scene without ``[gravity]`` compiles no gravity term (inspected in the UFL form, and the
  residual at rest is zero), while a scene with it carries g as a vector constant;
* the compiled objective, gradient and Hessian agree: central differences and Taylor
  remainders at a deformed state with a nonzero predictor and weight, for P1 and P2 and for
  consistent and lumped mass, with gravity. This guards an FFCx 0.5 miscompile (gravity at
  another quadrature degree than inertia in one form) together with the check that the
  objective equals the sum of its separately compiled terms;
* P2 runs the hanging beam close to a fine P1 mesh, and rejects lumped mass.

Fields are set from smooth functions of the dof coordinates (ghost values agree across ranks).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.errors import SceneError
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation

COMM = MPI.COMM_WORLD
RHO = 1000.0  # kg/m^3, the default scene's density
G = 9.81

BAR_3D = ["mesh.size=[1.0, 0.1, 0.1]", "mesh.element_size=0.1"]
BAR_2D = ["mesh.dim=2", "mesh.size=[1.0, 0.1]", "mesh.element_size=0.1",
          "pin.0.min=[-1.0e-6, -1.0]", "pin.0.max=[1.0e-6, 1.0]",
          "gravity.acceleration=[0.0, -9.81]"]
BAR_VOLUME = {3: 1.0 * 0.1 * 0.1, 2: 1.0 * 0.1}  # m^3 (3D), m^2 (2D)

NO_GRAVITY = """\
name = "bar_without_gravity"
[mesh]
size = [1.0, 0.1, 0.1]
element_size = 0.1
[[pin]]
name = "wall"
min = [-1.0e-6, -1.0, -1.0]
max = [1.0e-6, 1.0, 1.0]
"""

serial_only = pytest.mark.skipif(COMM.size > 1, reason="serial only: compares two meshes' dofs")

_simulations: dict[tuple[str, ...], Simulation] = {}


def bar(*overrides: str, dim: int = 3) -> Simulation:
    """The default (neohookean, gravity, pinned) scene on the coarse bar, built once."""
    key = (str(dim), *overrides)
    if key not in _simulations:
        base = BAR_3D if dim == 3 else BAR_2D
        _simulations[key] = Simulation(load_scene(None, overrides=[*base, *overrides]), COMM)
    return _simulations[key]


def mass_matrix(problem) -> PETSc.Mat:
    M = fem_petsc.assemble_matrix(problem.mass_form)
    M.assemble()
    return M


def owned(problem, values: np.ndarray) -> np.ndarray:
    """The owned part of a local (owned + ghost) dof array."""
    return values[: compat.petsc_vec(problem.u).getLocalSize()]


def free_mask(problem) -> np.ndarray:
    """Local dofs that are not pinned."""
    free = np.ones(problem.u.x.array.size)
    for bc in problem.bcs:
        free[bc.dof_indices()[0]] = 0.0
    return free


def wiggle(problem, seed: float) -> np.ndarray:
    """A rough but deterministic field of amplitude ~1 (a function of coordinates only)."""
    X = problem.V.tabulate_dof_coordinates()[:, : problem.d]
    k = np.arange(1, problem.d + 1)
    phase = X @ np.array([37.0, 53.0, 71.0][: problem.d]) * seed
    return np.sin(phase[:, None] * k + seed * k).ravel()


# --- mass ---------------------------------------------------------------------------------------


@pytest.mark.parametrize(("dim", "degree", "mass"), [(2, 1, "consistent"), (2, 1, "lumped"),
                                                      (3, 1, "consistent"), (3, 1, "lumped"),
                                                      (3, 2, "consistent")])
def test_total_mass_and_momentum(dim, degree, mass):
    """sum(M) = d rho V; 1/2 c.Mc = 1/2 rho V |c|^2; per-direction sum of M c = rho V c."""
    p = bar(f"element.degree={degree}", f'material.mass="{mass}"', dim=dim).problem
    m = RHO * BAR_VOLUME[dim]
    M = mass_matrix(p)
    ones, Mc = M.createVecs()
    ones.set(1.0)
    M.mult(ones, Mc)
    assert Mc.sum() == pytest.approx(dim * m, rel=1e-12)

    c = np.array([0.3, -1.2, 2.0][:dim])
    p.v.x.array[:] = np.tile(c, p.v.x.array.size // dim)
    p.u.x.array[:] = 0.0
    assert p.energies()["kinetic"] == pytest.approx(0.5 * m * c @ c, rel=1e-12)
    M.mult(compat.petsc_vec(p.v), Mc)
    momentum = COMM.allreduce(Mc.array.reshape(-1, dim).sum(axis=0), op=MPI.SUM)
    np.testing.assert_allclose(momentum, m * c, rtol=1e-12)
    for obj in (M, ones, Mc):
        obj.destroy()


@serial_only
@pytest.mark.parametrize("dim", [2, 3])
def test_lumped_mass_is_diagonal_row_sum(dim):
    """P1 vertex-rule mass: diagonal, and equal to the row sums of the consistent matrix."""
    consistent = bar("element.degree=1", 'material.mass="consistent"', dim=dim).problem
    lumped = bar("element.degree=1", 'material.mass="lumped"', dim=dim).problem
    np.testing.assert_array_equal(consistent.V.tabulate_dof_coordinates(),
                                  lumped.V.tabulate_dof_coordinates())
    Mc, Ml = mass_matrix(consistent), mass_matrix(lumped)
    diagonal = Ml.getDiagonal()
    assert Ml.norm(PETSc.NormType.FROBENIUS) ** 2 == pytest.approx(diagonal.norm() ** 2,
                                                                   rel=1e-14)
    row_sums, ones = Mc.createVecs()
    ones.set(1.0)
    Mc.mult(ones, row_sums)
    np.testing.assert_allclose(diagonal.array, row_sums.array, rtol=1e-12)
    assert diagonal.min()[1] > 0.0
    for obj in (Mc, Ml, diagonal, row_sums, ones):
        obj.destroy()


# --- gravity only when declared -----------------------------------------------------------------


def residual_at_rest(problem, weight: float) -> PETSc.Vec:
    """grad g at u = u_pred = 0 (F = I: only a load can make it nonzero)."""
    problem.u_pred.x.array[:] = 0.0
    problem.weight.value = weight
    x = compat.petsc_vec(problem.u).duplicate()
    x.set(0.0)
    r = problem.create_vector()
    problem.residual(None, x, r)
    x.destroy()
    return r


def test_scene_without_gravity_compiles_no_gravity_term(tmp_path: Path):
    path = tmp_path / "no_gravity.toml"
    path.write_text(NO_GRAVITY)
    scene = load_scene(path)
    assert "gravity" not in scene.data
    p = Simulation(scene, COMM).problem
    assert p.g is None
    assert "gravity" not in p.energy_forms
    # the form itself: only scalar constants (mu, lmbda, rho, w), no vector g anywhere
    constants = p.ufl_objective.constants()
    assert all(c.ufl_shape == () for c in constants)
    allowed = {p.u, p.u_pred, *(data.function for data in p.quadrature_data)}
    assert set(ufl.algorithms.extract_coefficients(p.ufl_objective)) <= allowed
    # and what it computes: no load, so the rest state is an equilibrium
    r = residual_at_rest(p, weight=1e-2)
    assert r.norm() < 1e-14
    r.destroy()


def test_scene_with_gravity_compiles_the_load():
    """Positive control: g is a vector constant, the rest residual is -w M g on free dofs."""
    p = bar().problem
    vectors = [c for c in p.ufl_objective.constants() if c.ufl_shape != ()]
    assert vectors == [p.g]
    np.testing.assert_array_equal(p.g.value, [0.0, 0.0, -G])
    w = 1e-2
    r = residual_at_rest(p, w)
    M = mass_matrix(p)
    expected = r.duplicate()
    gravity = compat.petsc_vec(p.u).duplicate()
    gravity.array[:] = np.tile(p.g.value, gravity.getLocalSize() // 3)
    M.mult(gravity, expected)
    expected.scale(-w)
    fem_petsc.set_bc(expected, p.bcs, None, 0.0)
    expected.axpy(-1.0, r)
    assert expected.norm() < 1e-12 * r.norm()
    # E_g of a uniform translation c: - rho V g.c
    c = np.array([0.1, 0.2, -0.3])
    p.u.x.array[:] = np.tile(c, p.u.x.array.size // 3)
    assert p.energies()["gravity"] == pytest.approx(-RHO * BAR_VOLUME[3] * (-G * c[2]),
                                                    rel=1e-12)
    for obj in (r, M, expected, gravity):
        obj.destroy()


# --- gradient and Hessian of the step objective -------------------------------------------------

CASES = [pytest.param(("element.degree=1", 'material.mass="consistent"'), id="P1-consistent"),
         pytest.param(("element.degree=1", 'material.mass="lumped"'), id="P1-lumped"),
         pytest.param(("element.degree=2", 'material.mass="consistent"'), id="P2-consistent")]
WEIGHT = 1e-2  # w = h^2/4 for h = 0.2 s: inertia and elastic terms of similar size


def staged_state(problem) -> tuple[PETSc.Vec, PETSc.Vec]:
    """A deformed state (pins held) with a nonzero predictor and weight, and a direction.

    Bending and twisting of a few cm plus 2 mm roughness (no element inverts); the
    predictor differs from u everywhere (also on pinned dofs); the direction is rough, of
    max-norm 1, zero on pinned dofs.
    """
    X = problem.V.tabulate_dof_coordinates()
    free = free_mask(problem)
    u = np.zeros_like(X)
    u[:, 0] = 0.1 * X[:, 0] * X[:, 1]
    u[:, 1] = 0.2 * X[:, 0] * X[:, 2]
    u[:, 2] = -0.05 * X[:, 0] ** 2
    u = (u.ravel() + 2e-3 * wiggle(problem, 1.0)) * free
    problem.u_pred.x.array[:] = u + 1e-2 * wiggle(problem, 2.0)
    problem.weight.value = WEIGHT
    x = compat.petsc_vec(problem.u).duplicate()
    x.array[:] = owned(problem, u)
    direction = x.duplicate()
    direction.array[:] = owned(problem, wiggle(problem, 3.0) * free)
    return x, direction


def taylor_order(eps: np.ndarray, remainders: list[float]) -> float:
    return np.polyfit(np.log(eps), np.log(remainders), 1)[0]


@pytest.mark.parametrize("overrides", CASES)
def test_gradient_matches_objective(overrides):
    """r.d = (g(x + e d) - g(x - e d)) / 2e; Taylor remainder g(x+ed) - g(x) - e r.d = O(e^2)."""
    p = bar(*overrides).problem
    x, d = staged_state(p)
    r = p.create_vector()
    g0 = p.objective(None, x)
    p.residual(None, x, r)
    slope = r.dot(d)

    def g(e: float) -> float:
        y = x.copy()
        y.axpy(e, d)
        value = p.objective(None, y)
        y.destroy()
        return value

    e = 1e-6
    central = (g(e) - g(-e)) / (2 * e)
    assert abs(central - slope) < 1e-6 * abs(slope)
    eps = 1e-3 * 0.5 ** np.arange(4)
    remainders = [abs(g(ei) - g0 - ei * slope) for ei in eps]
    assert abs(taylor_order(eps, remainders) - 2.0) < 0.2
    for obj in (x, d, r):
        obj.destroy()


@pytest.mark.parametrize("overrides", CASES)
def test_hessian_matches_gradient(overrides):
    """J d = (r(x + e d) - r(x - e d)) / 2e; Taylor remainder r(x+ed) - r(x) - e J d = O(e^2)."""
    p = bar(*overrides).problem
    x, d = staged_state(p)
    r0 = p.create_vector()
    p.residual(None, x, r0)
    A = p.create_matrix()
    p.jacobian(None, x, A, A)
    Jd = r0.duplicate()
    A.mult(d, Jd)

    def r(e: float) -> PETSc.Vec:
        y = x.copy()
        y.axpy(e, d)
        out = r0.duplicate()
        p.residual(None, y, out)
        y.destroy()
        return out

    e = 1e-6
    central = r(e)
    central.axpy(-1.0, r(-e))
    central.scale(1.0 / (2 * e))
    central.axpy(-1.0, Jd)
    assert central.norm() < 1e-6 * Jd.norm()
    eps = 1e-3 * 0.5 ** np.arange(4)
    remainders = []
    for ei in eps:
        rem = r(ei)
        rem.axpy(-1.0, r0)
        rem.axpy(-ei, Jd)
        remainders.append(rem.norm())
        rem.destroy()
    assert abs(taylor_order(eps, remainders) - 2.0) < 0.2
    for obj in (x, d, r0, A, Jd, central):
        obj.destroy()


@pytest.mark.parametrize("overrides", CASES)
def test_objective_is_the_sum_of_its_terms(overrides):
    """The one compiled step objective equals its separately compiled terms, and so does
    its gradient: g = 1/2 |u - y|_M^2 + w (E_el + E_g), r = M (u - y) + w grad E (free rows).
    """
    p = bar(*overrides).problem
    x, d = staged_state(p)
    g = p.objective(None, x)
    u = p.u.x.array.copy()
    p.v.x.array[:] = u - p.u_pred.x.array
    terms = p.energies()
    assert g == pytest.approx(terms["kinetic"] + WEIGHT * (terms["elastic"] + terms["gravity"]),
                              rel=1e-12)
    assert abs(terms["gravity"]) > 1e-3 * abs(g)

    r = p.create_vector()
    p.residual(None, x, r)
    M = mass_matrix(p)
    expected = r.duplicate()
    M.mult(compat.petsc_vec(p.v), expected)
    force = fem_petsc.assemble_vector(p.potential_gradient_form)
    force.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    expected.axpy(WEIGHT, force)
    fem_petsc.set_bc(expected, p.bcs, None, 0.0)
    expected.axpy(-1.0, r)
    assert expected.norm() < 1e-12 * r.norm()
    for obj in (x, d, r, M, expected, force):
        obj.destroy()


# --- P2 -----------------------------------------------------------------------------------------


def beam_sag(degree: int, element_size: float, steps: int = 30) -> tuple[float, float]:
    """Hanging beam (default scene), ``steps`` of 1/60 s: mean and lowest vertical displacement."""
    scene = load_scene(None, overrides=[f"element.degree={degree}",
                                        f"mesh.element_size={element_size}"])
    sim = Simulation(scene, COMM)
    state = sim.initial_state()
    for _ in range(steps):
        state, _ = sim.step(state, scene["time"]["dt"])
    p = sim.problem
    mesh = p.V.mesh
    volume = COMM.allreduce(fem.assemble_scalar(fem.form(1.0 * ufl.dx(domain=mesh))))
    mean = COMM.allreduce(fem.assemble_scalar(fem.form(p.u[2] * ufl.dx))) / volume
    lowest = COMM.allreduce(state.u.reshape(-1, 3)[:, 2].min(), op=MPI.MIN)
    return mean, lowest


@pytest.fixture(scope="module")
def p1_fine_sag() -> tuple[float, float]:
    return beam_sag(1, 0.05)


def test_p2_sag_close_to_fine_p1(p1_fine_sag):
    """P2 on 0.1 m elements vs P1 on 0.05 m after 0.5 s: within 5 % (P1 is stiffer: locking)."""
    mean, lowest = beam_sag(2, 0.1)
    assert mean < -0.3 and lowest < -0.8  # the beam did fall and bend
    assert mean == pytest.approx(p1_fine_sag[0], rel=0.05)
    assert lowest == pytest.approx(p1_fine_sag[1], rel=0.05)


@pytest.mark.slow
def test_p2_sag_mesh_converged(p1_fine_sag):
    """P2 on 0.05 m elements agrees with P2 on 0.1 m to 1 %, better than P1 does."""
    coarse, fine = beam_sag(2, 0.1), beam_sag(2, 0.05)
    for i in range(2):
        assert fine[i] == pytest.approx(coarse[i], rel=0.01)
        assert abs(fine[i] - coarse[i]) < abs(fine[i] - p1_fine_sag[i])


def test_lumped_mass_rejected_for_p2():
    with pytest.raises(SceneError, match=r"material\.mass.*element\.degree = 2"):
        load_scene(None, overrides=["element.degree=2", 'material.mass="lumped"'])
