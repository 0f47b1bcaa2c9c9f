"""DOLFINx against the numpy reference, on the same P1 mesh.

Both sides get the cell -> vertex arrays of :func:`fem_anim.reference.box_mesh`: the
reference assembles over them as they are, DOLFINx after :func:`fem_anim.mesh.build.mesh_from_arrays`
has distributed and reordered them. A DOLFINx dof (geometry node ``i``, component ``c``) is
mapped to the reference dof ``d * input_index[i] + c`` through
:attr:`fem_anim.output.files.VertexGather.node_to_dof` and
:attr:`fem_anim.mesh.build.SimplexMesh.input_index`; DOLFINx holds displacements ``u = x - X``, the
reference positions ``x``.

Compared, in this order:

1. elastic energy, gradient and Hessian (the last as sparse matrices) at a randomly perturbed
   and at a rotated state, for every material in 2D and 3D, with ``ufl.derivative`` of the
   same elastic UFL energy the problem binds;
2. the step objective ``g = 1/2 ||x - y||_M^2 + w E`` that SNES minimises, its residual and
   Jacobian (``EnergyProblem.objective_form``, ``residual_form``, ``jacobian_form``), the
   potential gradient (Newmark's initial acceleration) and the gravity energy;
3. consistent and lumped mass matrices, kinetic and gravity energies;
4. trajectories of a beam pinned at ``x = 0`` and hanging under gravity, 20 steps of each
   integrator (also with the lumped mass), against :func:`fem_anim.reference.simulate`; the
   materials other than neo-Hookean are marked ``slow``.

Assembly agrees to round-off, so its tolerance is a multiple of machine precision; the
trajectories agree to the Newton tolerances, both set tight. Serial only: the reference is
serial and the dof map is rank-local.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc
from scenes import DENSITY, DIVISIONS, LENGTHS, POISSON_RATIO, YOUNGS_MODULUS, beam, make_scene

from fem_anim import compat, reference
from fem_anim.mesh.simplex import mesh_from_arrays
from fem_anim.output.files import VertexGather
from fem_anim.problem.objective import EnergyProblem
from fem_anim.simulation.loop import Simulation

pytestmark = pytest.mark.skipif(
    MPI.COMM_WORLD.size > 1, reason="serial: the numpy reference and the dof map are rank-local"
)

EPS = np.finfo(float).eps
#: Assembly of the same sums in another order: measured <= 3e-15 relative (6e-14 for the
#: gravity energy, which the reference gets as a difference of two sums).
ASSEMBLY_RTOL = 1e4 * EPS
#: Trajectories, positions: both Newton solvers stop at tight tolerances; measured <= 1.5e-9.
TRAJECTORY_RTOL = 1e-8
#: Trajectories, displacements (relative to the largest one, so small motions count too):
#: measured <= 2.4e-9. The Minimiser may stop at its round-off floor before ``snes_rtol``
#: (reported as ``POLISH_FAILED_REASON``): the backtracking line search cannot see a decrease
#: of ``g`` below its floating-point resolution, which leaves residuals of ~1e-9 relative in
#: some steps.
DISPLACEMENT_RTOL = 1e-7

MATERIALS = ("linear", "stvk", "corotated", "neohookean", "stable_neohookean")
DIMS = (2, 3)
INTEGRATORS = ("newmark", "implicit_euler", "bdf2", "symplectic_euler")

# The body: the reference beam of tests/scenes.py (DIVISIONS, LENGTHS, the material): 1 m,
# 4 cells along its length; Kuhn simplices (2 per square, 6 per cube).
GRAVITY = {2: (0.0, -9.81), 3: (0.0, -9.81, 0.0)}  # m/s^2
PIN_MIN = {2: (-1e-6, -1.0), 3: (-1e-6, -1.0, -1.0)}  # the face x = 0
PIN_MAX = {2: (1e-6, 1.0), 3: (1e-6, 1.0, 1.0)}
STEPS = 20
DT = {"newmark": 1 / 60, "implicit_euler": 1 / 60, "bdf2": 1 / 60,
      "symplectic_euler": 1 / 250}  # s; symplectic Euler diverges at 1/60 on this mesh
DOLFINX_NEWTON = {"snes_rtol": "1e-12", "snes_atol": "1e-14"}
REFERENCE_NEWTON = {"atol": 1e-12, "rtol": 1e-14}


# --- scenes, meshes and the dof map --------------------------------------------------------------


def write_scene(directory, d: int, material: str, *, mass: str = "consistent",
                integrator: str = "newmark", pinned: bool = False):
    """A scene for the reference beam (its ``[mesh]`` is validated but not built)."""
    name = f"{material}_{d}d_{mass}_{integrator}{'_pinned' if pinned else ''}"
    return make_scene(directory, beam(
        name, d, material={"model": material, "mass": mass},
        time={"integrator": integrator, "dt": DT[integrator], "steps": STEPS},
        gravity={"acceleration": GRAVITY[d]},
        pin=[{"name": "wall", "min": PIN_MIN[d], "max": PIN_MAX[d]}] if pinned else None))


def beam_mesh(d: int):
    """The reference arrays and the DOLFINx mesh made from them."""
    points, cells = reference.box_mesh(DIVISIONS[d], LENGTHS[d])
    domain = mesh_from_arrays(MPI.COMM_SELF, points, cells, None, f"reference box {d}D")
    return points, cells, domain


def reference_order(domain, V) -> np.ndarray:
    """``order[r]`` = local DOLFINx dof of reference dof ``r`` (``d * vertex + component``)."""
    d = domain.dim
    node_to_dof = VertexGather(domain, V).node_to_dof
    dolfinx_dofs = (node_to_dof[:, None] * d + np.arange(d)).ravel()
    reference_dofs = (domain.input_index[:, None] * d + np.arange(d)).ravel()
    order = np.full(reference_dofs.size, -1, dtype=np.int64)
    order[reference_dofs] = dolfinx_dofs
    assert np.all(order >= 0) and np.unique(order).size == order.size
    return order


def pinned_mask(points: np.ndarray, d: int) -> np.ndarray:
    """Reference dofs of the vertices in the scene's pin box (the test ``problem._pins`` uses)."""
    inside = np.all((points >= PIN_MIN[d]) & (points <= PIN_MAX[d]), axis=1)
    return np.repeat(inside, d)


def step_callbacks(problem, u: np.ndarray) -> tuple[float, np.ndarray, sp.csr_matrix]:
    """g, grad g (pinned rows: u - u_bc) and the Hessian at the displacement ``u`` (local
    dofs) from the callbacks SNES calls: the assembled forms plus the terms assembled once
    (:mod:`fem_anim.problem.constant_terms`)."""
    work = compat.petsc_vec(problem.u).copy()
    with work.localForm() as local:
        local.array[:] = u
    value = problem.objective(None, work)
    b = problem.create_vector()
    problem.residual(None, work, b)
    with b.localForm() as local:
        residual = local.array.copy()
    A = problem.create_matrix("aij")
    problem.jacobian(None, work, A, A)
    indptr, indices, values = A.getValuesCSR()
    jacobian = sp.csr_matrix((values, indices, indptr), shape=A.getSize())
    for obj in (work, b, A):
        obj.destroy()
    return value, residual, jacobian


class Comparison:
    """One :class:`EnergyProblem` on the reference mesh, with the dof map both ways."""

    def __init__(self, scene):
        d = scene.dim
        self.points, self.cells, self.domain = beam_mesh(d)
        self.X = self.points.ravel()
        self.problem = EnergyProblem(scene, self.domain)
        self.order = reference_order(self.domain, self.problem.V)
        np.testing.assert_array_equal(
            self.domain.mesh.geometry.x[:, :d], self.points[self.domain.input_index])
        self._elastic_forms = None

    # -- moving values between numberings -------------------------------------------------
    def to_reference(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(values)[self.order]

    def set_function(self, function: fem.Function, values: np.ndarray) -> None:
        function.x.array[self.order] = values

    def set_positions(self, x: np.ndarray) -> None:
        """``u = x - X`` through the solver entry point (refreshes quadrature data)."""
        work = compat.petsc_vec(self.problem.u).copy()
        with work.localForm() as local:
            local.array[self.order] = x - self.X
        self.problem.set_state(work)
        work.destroy()

    # -- assembly ---------------------------------------------------------------------------
    def scalar(self, form) -> float:
        return self.problem.assemble_scalar(form)

    def vector(self, form) -> np.ndarray:
        b = fem_petsc.assemble_vector(form)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        with b.localForm() as local:
            values = self.to_reference(local.array.copy())
        b.destroy()
        return values

    def matrix(self, form) -> sp.csr_matrix:
        A = fem_petsc.assemble_matrix(form)
        A.assemble()
        indptr, indices, data = A.getValuesCSR()
        csr = sp.csr_matrix((data, indices, indptr), shape=A.getSize())
        A.destroy()
        return csr[self.order][:, self.order]

    def step_at(self, x: np.ndarray) -> tuple[float, np.ndarray, sp.csr_matrix]:
        """g, grad g and the Hessian at positions ``x`` from the callbacks SNES calls
        (:func:`step_callbacks`), in reference order."""
        u = np.empty_like(x)
        u[self.order] = x - self.X
        value, residual, jacobian = step_callbacks(self.problem, u)
        return value, self.to_reference(residual), jacobian[self.order][:, self.order]

    def elastic_forms(self):
        """Elastic energy, its gradient and Hessian by ``ufl.derivative``, compiled once."""
        if self._elastic_forms is None:
            p = self.problem
            energy = p.ufl_elastic
            gradient = ufl.derivative(energy, p.u, ufl.TestFunction(p.V))
            hessian = ufl.derivative(gradient, p.u, ufl.TrialFunction(p.V))
            self._elastic_forms = tuple(map(fem.form, (energy, gradient, hessian)))
        return self._elastic_forms


@pytest.fixture(scope="module")
def scene_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("scenes")


@pytest.fixture(scope="module")
def comparison(scene_dir):
    """``comparison(d, material, mass)``: one :class:`Comparison` per argument set."""
    cache = {}

    def get(d: int, material: str, mass: str = "consistent") -> Comparison:
        key = (d, material, mass)
        if key not in cache:
            cache[key] = Comparison(write_scene(scene_dir, d, material, mass=mass))
        return cache[key]

    return get


# --- states and measures of agreement ------------------------------------------------------------


def rotation(d: int, angle: float = 0.7) -> np.ndarray:
    """A rotation by ``angle`` (about the axis (1, 2, 3) in 3D)."""
    if d == 2:
        c, s = np.cos(angle), np.sin(angle)
        return np.array([[c, -s], [s, c]])
    k = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def deformed_positions(points: np.ndarray, cells: np.ndarray, kind: str,
                       seed: int = 0) -> np.ndarray:
    """``X + a r``, ``r`` uniform in [-1, 1], rotated and shifted for ``"rotated"``.

    ``a`` is a fifth of the grid spacing: ``|F - I| <= 0.4`` and ``det F`` stays in about
    [0.5, 1.7], so every material (neo-Hookean needs ``det F > 0``) is evaluated where smooth.
    """
    d = points.shape[1]
    rng = np.random.default_rng(seed)
    spacing = min(np.asarray(LENGTHS[d]) / DIVISIONS[d])
    x = points + 0.2 * spacing * rng.uniform(-1.0, 1.0, points.shape)
    if kind == "rotated":
        x = x @ rotation(d).T + 0.3 * np.arange(1, d + 1)
    x = x.ravel()
    J = np.linalg.det(reference.deformation_gradient(points, cells, x))
    assert J.min() > 0.25, f"test state too distorted: min det F = {J.min():.3f}"
    return x


def relative_difference(actual, expected) -> float:
    """``max |actual - expected| / max |expected|`` for scalars, vectors or sparse matrices."""
    if sp.issparse(expected):
        assert actual.shape == expected.shape
        return abs(actual - expected).max() / abs(expected).max()
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape
    return np.abs(actual - expected).max() / np.abs(expected).max()


def assert_close(what: str, actual, expected, rtol: float) -> None:
    difference = relative_difference(actual, expected)
    assert difference <= rtol, f"{what}: relative difference {difference:.3e} > {rtol:.1e}"


# --- 1. elastic energy, gradient, Hessian --------------------------------------------------------


@pytest.mark.parametrize("kind", ["perturbed", "rotated"])
@pytest.mark.parametrize("material", MATERIALS)
@pytest.mark.parametrize("d", DIMS)
def test_elastic_energy_gradient_hessian(comparison, d, material, kind):
    """Elastic energy, ``ufl.derivative`` gradient and Hessian equal the reference sums."""
    c = comparison(d, material)
    x = deformed_positions(c.points, c.cells, kind)
    c.set_positions(x)
    mu, lmbda = reference.lame_parameters(YOUNGS_MODULUS, POISSON_RATIO)
    args = (c.points, c.cells, material, mu, lmbda, x)
    energy, gradient, hessian = c.elastic_forms()

    expected = reference.elastic_energy(*args)
    assert_close("elastic energy", c.scalar(energy), expected, ASSEMBLY_RTOL)
    assert_close("problem.energy_forms['elastic']",
                 c.scalar(c.problem.energy_forms["elastic"]), expected, ASSEMBLY_RTOL)
    assert_close("elastic gradient", c.vector(gradient), reference.elastic_gradient(*args),
                 ASSEMBLY_RTOL)
    H = reference.elastic_hessian(*args)
    H_dolfinx = c.matrix(hessian)
    assert_close("elastic Hessian", H_dolfinx, H, ASSEMBLY_RTOL)
    # Same sparsity: every vertex pair sharing a cell couples all components.
    assert H_dolfinx.nnz == H.nnz


# --- 2. the step objective as SNES sees it -------------------------------------------------------


@pytest.mark.parametrize("material", MATERIALS)
@pytest.mark.parametrize("d", DIMS)
def test_step_objective(comparison, d, material):
    """The objective, residual and Jacobian callbacks SNES calls against the reference ``g``.

    ``g(x) = 1/2 ||x - y||_M^2 + w (E_elastic(x) - f_g . x)``, with the Newmark weight and a
    random predictor ``y``. DOLFINx's gravity potential ``-f_g . u`` differs from the
    reference's ``-f_g . x`` by the constant ``-f_g . X``, times ``w`` in ``g``. The
    callbacks assemble w E_elastic and add the inertia and gravity terms from a mass matrix
    and a force vector assembled once (:mod:`fem_anim.problem.constant_terms`).
    """
    c = comparison(d, material)
    ref = reference.build_problem(c.points, c.cells, material, YOUNGS_MODULUS, POISSON_RATIO,
                                  DENSITY, GRAVITY[d])
    x = deformed_positions(c.points, c.cells, "perturbed", seed=1)
    y = deformed_positions(c.points, c.cells, "perturbed", seed=2)
    w = (1 / 60) ** 2 / 4
    p = c.problem
    p.weight.value = w
    c.set_function(p.u_pred, y - c.X)
    c.set_positions(x)
    M = ref.mass

    g = 0.5 * (x - y) @ (M @ (x - y)) + w * ref.energy(x)
    value, residual, jacobian = c.step_at(x)
    assert_close("objective", value - w * ref.gravity_force @ c.X, g, ASSEMBLY_RTOL)
    assert_close("residual", residual, M @ (x - y) + w * ref.gradient(x), ASSEMBLY_RTOL)
    assert_close("Jacobian", jacobian, M + w * ref.hessian(x), ASSEMBLY_RTOL)
    assert_close("potential gradient", c.vector(p.potential_gradient_form), ref.gradient(x),
                 ASSEMBLY_RTOL)
    assert_close("gravity energy", c.scalar(p.energy_forms["gravity"]),
                 -ref.gravity_force @ (x - c.X), ASSEMBLY_RTOL)


# --- 3. mass -------------------------------------------------------------------------------------


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
@pytest.mark.parametrize("d", DIMS)
def test_mass_and_gravity(comparison, d, mass):
    """``mass_form`` is the reference (lumped) mass matrix; kinetic and gravity energies agree."""
    c = comparison(d, "linear", mass)
    p = c.problem
    lumped = mass == "lumped"
    M = reference.mass_matrix(c.points, c.cells, DENSITY, lumped=lumped)
    M_dolfinx = c.matrix(p.mass_form)
    assert_close("mass matrix", M_dolfinx, M, ASSEMBLY_RTOL)
    assert_close("total mass", M_dolfinx.sum() / d, DENSITY * np.prod(LENGTHS[d]), ASSEMBLY_RTOL)

    rng = np.random.default_rng(3)
    v = rng.standard_normal(c.X.size)
    c.set_function(p.v, v)
    assert_close("kinetic energy", c.scalar(p.energy_forms["kinetic"]), 0.5 * v @ (M @ v),
                 ASSEMBLY_RTOL)

    x = deformed_positions(c.points, c.cells, "rotated", seed=4)
    c.set_positions(x)
    g = np.asarray(GRAVITY[d])
    expected = (reference.gravity_energy(c.points, c.cells, DENSITY, g, x)
                - reference.gravity_energy(c.points, c.cells, DENSITY, g, c.X))
    assert_close("gravity energy", c.scalar(p.energy_forms["gravity"]), expected, ASSEMBLY_RTOL)


# --- 4. trajectories -----------------------------------------------------------------------------


def compare_trajectory(scene_dir, d: int, material: str, integrator: str,
                       mass: str = "consistent") -> None:
    """20 steps of the pinned beam on both sides; positions and displacements agree."""
    scene = write_scene(scene_dir, d, material, mass=mass, integrator=integrator, pinned=True)
    points, cells, domain = beam_mesh(d)
    sim = Simulation(scene, domain.mesh.comm, DOLFINX_NEWTON, domain=domain)
    pinned = pinned_mask(points, d)

    # Both sides pin the same dofs: set_bc zeroes exactly the pinned entries.
    free = compat.petsc_vec(sim.problem.u).duplicate()
    free.set(1.0)
    fem_petsc.set_bc(free, sim.problem.bcs, None, 0.0)
    with free.localForm() as local:
        dolfinx_pinned = local.array[reference_order(domain, sim.problem.V)] == 0.0
    free.destroy()
    np.testing.assert_array_equal(dolfinx_pinned, pinned)

    dt = DT[integrator]
    expected = reference.simulate(points, cells, material, YOUNGS_MODULUS, POISSON_RATIO,
                                  DENSITY, GRAVITY[d], pinned, integrator, dt, STEPS,
                                  lumped=mass == "lumped", **REFERENCE_NEWTON)
    state = sim.initial_state()
    u = []
    for _ in range(STEPS):
        state, _ = sim.step(state, dt)
        u.append(sim.gather.gather(state.u).ravel())
    u = np.array(u)
    X = points.ravel()
    u_expected = expected.x[1:] - X
    assert np.abs(u_expected).max() > 1e-2, "the beam should move"
    assert_close("positions", u + X, expected.x[1:], TRAJECTORY_RTOL)
    assert_close("displacements", u, u_expected, DISPLACEMENT_RTOL)
    sim.minimiser.destroy()


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("d", DIMS)
def test_trajectory(scene_dir, d, integrator):
    """Neo-Hookean beam: every integrator follows the reference trajectory."""
    compare_trajectory(scene_dir, d, "neohookean", integrator)


@pytest.mark.parametrize("integrator", ["newmark", "symplectic_euler"])
@pytest.mark.parametrize("d", DIMS)
def test_trajectory_lumped(scene_dir, d, integrator):
    """With the lumped mass matrix (Newmark's initial acceleration, the explicit scheme)."""
    compare_trajectory(scene_dir, d, "neohookean", integrator, mass="lumped")


@pytest.mark.slow
@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("material", [m for m in MATERIALS if m != "neohookean"])
@pytest.mark.parametrize("d", DIMS)
def test_trajectory_materials(scene_dir, d, material, integrator):
    """The other materials (the neo-Hookean case runs in :func:`test_trajectory`)."""
    compare_trajectory(scene_dir, d, material, integrator)
