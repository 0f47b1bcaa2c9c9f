"""Analytic checks of the discretisation, driven through :class:`fem_anim.simulation.loop.Simulation`.

Three kinds of exact results, each known in closed form for the discrete equations, so the
assertions are at round-off or at the Newton tolerance rather than at a discretisation error:

1. **Momentum of a free spinning body** (no pins, no gravity; initial velocity a rigid rotation
   about the centroid plus a translation). With the consistent mass matrix ``M`` (``M = M_s (x)
   I_d`` for P_k) the momenta of the finite-element fields are

       p = sum_i (M v)_i,        L = int rho x_h x v_h dV = sum_i x_i x (M v)_i,   x = X + u.

   The elastic forces ``f = -grad E`` sum to zero (translation invariance) and, for the
   rotation-invariant materials (everything but ``linear``), have zero torque,
   ``sum_i x_i x f_i = 0``. Every Newton iterate keeps ``sum_i r_i = 0`` (``K`` annihilates
   translations and the first iterate is the predictor), so ``p`` is exact *to round-off* for
   every scheme. Angular momentum is a quadratic invariant, and what the schemes keep is
   (``B(a, b) = sum_i a_i x (M b)_i``, antisymmetric; seed section 3.1):

   * Newmark (trapezoidal rule, seed eqs. (1a)-(1b)): ``L_{n+1} - L_n = h^2/4 (Q_{n+1} - Q_n)``
     with ``Q = B(a, v)``, i.e. it conserves the *modified* angular momentum

         L~ = sum_i (x_i - h^2/4 a_i) x (M v)_i,

     to the Newton tolerance, while ``L`` itself oscillates by ``O(h^2)`` without drifting (the
     trapezoidal rule is conjugate to the midpoint rule, which conserves ``L`` exactly);
   * implicit Euler conserves neither: ``L_{n+1} - L_n = h B(v_{n+1}, v_n)
     = -h^2 sum_i v_{n+1,i} x f_{n+1,i}``, which drains the spin (numerical dissipation). The test
     checks this discrete angular-momentum balance to the Newton tolerance.

2. **Patch tests.** An affine displacement ``u = (A - I) X + b`` is reproduced exactly by P1 and
   P2, so ``F = A`` everywhere: the elastic energy is ``vol psi(A)`` (``psi`` from the
   independent :mod:`fem_anim.reference`) and the nodal forces are those of the constant stress
   ``P(A)``: zero at interior nodes, and on the boundary the consistent load of the traction
   ``P(A) N`` (assembled as ``int_dOmega P(A) N . v dA``). On a mesh with randomly moved interior
   vertices, for every material, P1 and P2, 2D and 3D. A rigid motion ``u = (R - I)(X - c) + b``
   has zero energy and zero forces for every material but ``linear`` (not rotation invariant).

3. **The harmonic oscillator of seed section 1.1, mode by mode.** For the linear material on a
   pinned bar, ``M u'' + K u = 0`` decouples into oscillators ``q'' + omega^2 q = 0`` along the
   generalised eigenvectors ``K phi = omega^2 M phi`` (computed with scipy from the assembled
   ``K = d^2 E/du^2`` and ``M``), and each scheme is a linear map on ``z = omega q + i q'``:

   * implicit Euler: ``z_{n+1} = z_n / (1 + i omega h)``: amplitude ratio
     ``1/sqrt(1 + (omega h)^2)`` and phase ``atan(omega h)`` per step;
   * Newmark: ``z_{n+1} = z_n (1 - i omega h/2) / (1 + i omega h/2)``: modal energy
     ``|z|^2/2`` kept, phase ``2 atan(omega h/2)`` per step instead of ``omega h``, i.e. the
     period lengthens by ``omega h / (2 atan(omega h/2))``.

   Started on a combination of two modes with very different ``omega h``, each modal amplitude
   follows its own factor and no other mode is excited.

Serial only: the checks work on global dof arrays.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc
from scenes import POISSON_RATIO, YOUNGS_MODULUS, beam, make_scene
from test_reference_comparison import rotation

from fem_anim import compat, reference
from fem_anim.mesh.simplex import mesh_from_arrays
from fem_anim.problem.objective import EnergyProblem
from fem_anim.simulation.loop import Simulation

pytestmark = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                reason="serial: the checks work on global dof arrays")

EPS = np.finfo(float).eps
#: Tight Newton tolerances, so that the assertions below see the schemes, not the solver.
NEWTON = {"snes_rtol": "1e-12", "snes_atol": "1e-14"}
MU, LMBDA = reference.lame_parameters(YOUNGS_MODULUS, POISSON_RATIO)


# --- helpers --------------------------------------------------------------------------------------


def write_scene(directory: Path, name: str, d: int, lengths, material: str, *,
                integrator: str = "newmark", degree: int = 1, mass: str = "consistent",
                pin: tuple | None = None):
    """A scene for a mesh given as arrays (its ``[mesh]`` is validated but not built)."""
    floats = [float(v) for v in lengths]
    return make_scene(directory, beam(
        name, d, mesh={"size": floats, "element_size": min(lengths)}, element={"degree": degree},
        material={"model": material, "mass": mass}, time={"integrator": integrator},
        pin=None if pin is None else [{"min": list(map(float, pin[0])),
                                       "max": list(map(float, pin[1]))}]))


def box(divisions, lengths, perturb: float = 0.0, seed: int = 0):
    """:func:`fem_anim.reference.box_mesh`, interior vertices moved by up to ``perturb`` cells."""
    points, cells = reference.box_mesh(divisions, lengths)
    if perturb:
        lengths = np.asarray(lengths, dtype=float)
        spacing = lengths / np.asarray(divisions)
        inside = np.all((points > 1e-9) & (points < lengths - 1e-9), axis=1)
        rng = np.random.default_rng(seed)
        points[inside] += perturb * spacing * rng.uniform(-1.0, 1.0, (inside.sum(), len(lengths)))
    domain = mesh_from_arrays(MPI.COMM_WORLD, points, cells, None, f"box {divisions}")
    return domain


def scipy_matrix(form) -> sp.csr_matrix:
    A = fem_petsc.assemble_matrix(form)
    A.assemble()
    indptr, indices, values = A.getValuesCSR()
    out = sp.csr_matrix((values, indices, indptr), shape=A.getSize())
    A.destroy()
    return out


def assembled_vector(form) -> np.ndarray:
    b = fem_petsc.assemble_vector(form)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    with b.localForm() as local:
        out = local.array.copy()
    b.destroy()
    return out


def set_displacement(problem, u: np.ndarray) -> None:
    """``u`` through the solver entry point (ghosts and quadrature data refreshed)."""
    work = compat.petsc_vec(problem.u).copy()
    with work.localForm() as local:
        local.array[:] = u
    problem.set_state(work)
    work.destroy()


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross product; the scalar z component in 2D."""
    if a.shape[1] == 2:
        return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    return np.cross(a, b)


# --- 1. momentum of a free spinning body ----------------------------------------------------------

SPIN_LENGTHS = {2: (1.0, 0.25), 3: (1.0, 0.25, 0.25)}
SPIN_DIVISIONS = {2: (4, 2), 3: (4, 2, 2)}
SPIN_OMEGA = 2.0  # rad/s: centrifugal strain rho omega^2 l^2 / E = 0.1 (l the half-length)
SPIN_AXIS = np.array([1.0, 2.0, 3.0]) / np.sqrt(14.0)  # 3D; 2D spins about z
DRIFT = (0.3, -0.2, 0.1)  # m/s, the translation added to the rotation
SPIN_DT = 0.05  # s
SPIN_STEPS = 20  # 2 rad of rotation, while the body stretches and wobbles
#: Linear momentum: exact up to round-off. Measured <= 8e-15 relative to |p_0|.
MOMENTUM_RTOL = 1e-12
#: Conserved (Newmark) or balanced (implicit Euler) angular momentum, to the Newton tolerance
#: (snes_rtol 1e-12) accumulated over the steps. Measured <= 5e-14 relative to |L_0|.
ANGULAR_RTOL = 1e-11


class Spin:
    """A free body spinning about its centroid, its consistent mass matrix and momenta."""

    def __init__(self, directory: Path, d: int, material: str, integrator: str, degree: int):
        name = f"spin_{d}d_{material}_{integrator}_p{degree}"
        scene = write_scene(directory, name, d, SPIN_LENGTHS[d], material,
                            integrator=integrator, degree=degree)
        assert not scene["pin"] and "gravity" not in scene.data, "a free body"
        domain = box(SPIN_DIVISIONS[d], SPIN_LENGTHS[d])
        self.sim = Simulation(scene, MPI.COMM_WORLD, cli_options=NEWTON, domain=domain)
        self.d = d
        self.M = scipy_matrix(self.sim.problem.mass_form)
        self.X = self.sim.problem.V.tabulate_dof_coordinates()[:, :d]

    def initial_state(self):
        """v = omega x (X - c) + drift, c the centre of mass."""
        d, X = self.d, self.X
        Ms = self.M[::d, ::d]  # the scalar mass matrix M_s
        nodal_mass = Ms @ np.ones(X.shape[0])
        c = nodal_mass @ X / nodal_mass.sum()
        r = X - c
        if d == 2:
            v = SPIN_OMEGA * np.stack([-r[:, 1], r[:, 0]], axis=1)
        else:
            v = np.cross(SPIN_OMEGA * SPIN_AXIS, r)
        v += np.asarray(DRIFT[:d])
        state = self.sim.initial_state()
        state.v[:] = v.ravel()
        if self.sim.integrator.name == "newmark":
            state.a = self.sim.acceleration(state.u, state.v)
        return state

    def momenta(self, state, h: float) -> dict[str, np.ndarray]:
        """p, L and Newmark's L~ of a state, and M v (by node) for implicit Euler's balance."""
        d = self.d
        x = self.X + state.u.reshape(-1, d)
        a = state.a.reshape(-1, d)
        Mv = (self.M @ state.v).reshape(-1, d)
        return {"p": Mv.sum(axis=0),
                "L": cross(x, Mv).sum(axis=0),
                "L~": cross(x - h * h / 4 * a, Mv).sum(axis=0),
                "Mv": Mv}

    def run(self):
        state = self.initial_state()
        history = [self.momenta(state, SPIN_DT)]
        velocities = [state.v.reshape(-1, self.d)]
        for _ in range(SPIN_STEPS):
            state, _ = self.sim.step(state, SPIN_DT)
            history.append(self.momenta(state, SPIN_DT))
            velocities.append(state.v.reshape(-1, self.d))
        assert np.abs(state.u).max() > 0.5, "the body should have turned"
        return history, velocities


def max_relative(history: np.ndarray, initial: np.ndarray) -> float:
    """``max_n |y_n - y_0| / |y_0|`` (max norms) of a vector or (2D) scalar history."""
    return float(np.abs(history - initial).max() / np.abs(initial).max())


SPIN_CASES = [(d, material, integrator, 1) for d in (2, 3) for material in ("neohookean", "stvk")
              for integrator in ("newmark", "implicit_euler")]
SPIN_CASES += [(3, "neohookean", "newmark", 2), (2, "stvk", "implicit_euler", 2)]


@pytest.mark.parametrize("d, material, integrator, degree", SPIN_CASES)
def test_free_spinning_body_momenta(tmp_path, d, material, integrator, degree):
    """p exact to round-off; Newmark keeps L~ = sum (x - h^2/4 a) x Mv, implicit Euler drains L."""
    spin = Spin(tmp_path, d, material, integrator, degree)
    history, velocities = spin.run()
    p = np.array([m["p"] for m in history])
    L = np.array([m["L"] for m in history])
    p0, L0 = p[0], L[0]
    assert np.abs(p0).max() > 1.0 and np.abs(L0).max() > 0.1

    drift_p = max_relative(p, p0)
    assert drift_p <= MOMENTUM_RTOL, f"linear momentum drifts by {drift_p:.2e}"

    scale = np.abs(L0).max()
    drift_L = max_relative(L, L0)
    if integrator == "newmark":
        L_tilde = np.array([m["L~"] for m in history])
        drift_tilde = max_relative(L_tilde, L_tilde[0])
        assert drift_tilde <= ANGULAR_RTOL, f"L~ drifts by {drift_tilde:.2e}"
        # L itself is not an invariant of the trapezoidal rule: it oscillates by O(h^2)
        # (measured up to 1.9% in 2D, 0.7% in 3D) but, L - L~ being h^2/4 B(a, v), does not
        # drift.
        assert 1e-4 < drift_L < 0.05, f"L varies by {drift_L:.2e}"
    else:
        # discrete balance L_{n+1} - L_n = h B(v_{n+1}, v_n) = h sum_i v_{n+1,i} x (M v_n)_i
        balance = [SPIN_DT * cross(v_next, m["Mv"]).sum(axis=0)
                   for v_next, m in zip(velocities[1:], history[:-1], strict=True)]
        error = np.abs(np.diff(L, axis=0) - np.array(balance))
        assert error.max() <= ANGULAR_RTOL * scale, \
            f"angular momentum balance off by {error.max() / scale:.2e}"
        # ... and the balance is a real loss: implicit Euler spins the body down
        # (measured over the 20 steps: 11% of |L| lost in 3D, 64% in 2D).
        assert np.linalg.norm(L[-1]) < 0.95 * np.linalg.norm(L0)
    spin.sim.minimiser.destroy()


# --- 2. patch tests -------------------------------------------------------------------------------

PATCH_LENGTHS = {2: (1.0, 0.5), 3: (1.0, 0.5, 0.5)}
PATCH_DIVISIONS = {2: (4, 2), 3: (4, 2, 2)}
PATCH_PERTURB = 0.3  # interior vertices moved by up to 30% of a cell
MATERIALS = ("linear", "stvk", "corotated", "neohookean", "stable_neohookean",
             "corotated_lagged")
#: Energies: sums of equal cell values in another order; measured <= 1e-14 relative.
ENERGY_RTOL = 1e4 * EPS
#: Nodal forces relative to the largest one (affine patch), or to mu h^(d-1), the nodal force
#: of a unit strain on cells of size h (rigid motion). Measured <= 5e-15 for P1; for P2
#: <= 1.3e-13 in 2D and <= 3.1e-13 in 3D, where the force at an interior P2 node is a sum of
#: cell terms much larger than the result (in 3D the default degree-2 tetrahedron rule,
#: exact only to ~5e-15, adds to it: the degree-4 rule gives 3-5 times less).
FORCE_RTOL = {1: 1e4 * EPS, 2: 1e5 * EPS}


@pytest.fixture(scope="module")
def patch_problem(tmp_path_factory):
    """``patch_problem(d, degree, material)``: an EnergyProblem on the distorted box, cached."""
    directory = tmp_path_factory.mktemp("patch")
    cache = {}

    def get(d: int, degree: int, material: str):
        key = (d, degree, material)
        if key not in cache:
            scene = write_scene(directory, f"patch_{d}d_p{degree}_{material}", d,
                                PATCH_LENGTHS[d], material, degree=degree)
            domain = box(PATCH_DIVISIONS[d], PATCH_LENGTHS[d], perturb=PATCH_PERTURB)
            problem = EnergyProblem(scene, domain)
            gradient = fem.form(ufl.derivative(problem.ufl_elastic, problem.u,
                                               ufl.TestFunction(problem.V)))
            cache[key] = problem, gradient
        return cache[key]

    return get


#: (dimension, degree) of the patch tests; 3D P2 compiles the largest kernels of the suite
#: (5-13 s per material with a cold FFCx cache) and runs in the slow tier.
PATCH_CASES = [(2, 1), (2, 2), (3, 1), pytest.param(3, 2, marks=pytest.mark.slow)]


def interior_nodes(problem, d: int) -> np.ndarray:
    X = problem.V.tabulate_dof_coordinates()[:, :d]
    L = np.asarray(PATCH_LENGTHS[d])
    return np.all((X > 1e-9) & (X < L - 1e-9), axis=1)


def traction_load(problem, P: np.ndarray) -> np.ndarray:
    """Consistent nodal load of the traction ``P N`` of a constant stress, by node."""
    mesh = problem.domain.mesh
    P_const = fem.Constant(mesh, PETSc.ScalarType(P))
    N = ufl.FacetNormal(mesh)
    form = fem.form(ufl.inner(ufl.dot(P_const, N), ufl.TestFunction(problem.V)) * ufl.ds)
    return assembled_vector(form).reshape(-1, problem.d)


@pytest.mark.parametrize("material", MATERIALS)
@pytest.mark.parametrize("d, degree", PATCH_CASES)
def test_affine_patch(patch_problem, d, degree, material):
    """u = (A - I) X + b: energy vol psi(A), nodal forces those of the constant stress P(A)."""
    problem, gradient = patch_problem(d, degree, material)
    rng = np.random.default_rng(10 * d + degree)
    A = np.eye(d) + 0.2 * rng.uniform(-1.0, 1.0, (d, d))
    b = rng.uniform(-1.0, 1.0, d)
    X = problem.V.tabulate_dof_coordinates()[:, :d]
    set_displacement(problem, (X @ (A - np.eye(d)).T + b).ravel())

    model = "corotated" if material == "corotated_lagged" else material  # same psi at R(F)
    vol = np.prod(PATCH_LENGTHS[d])
    psi_A = reference.psi(model, A[None], MU, LMBDA)[0]
    energy = problem.assemble_scalar(problem.energy_forms["elastic"])
    assert abs(energy - vol * psi_A) <= ENERGY_RTOL * abs(vol * psi_A), \
        f"energy {energy!r} != vol psi(A) = {vol * psi_A!r}"

    forces = assembled_vector(gradient).reshape(-1, d)
    scale = np.abs(forces).max()
    inside = interior_nodes(problem, d)
    assert inside.sum() >= 3
    interior = np.abs(forces[inside]).max() / scale
    assert interior <= FORCE_RTOL[degree], f"interior nodal forces {interior:.2e}"
    P_A = reference.first_piola(model, A[None], MU, LMBDA)[0]
    boundary = np.abs(forces - traction_load(problem, P_A)).max() / scale
    assert boundary <= FORCE_RTOL[degree], f"nodal forces differ from P(A) N by {boundary:.2e}"


#: Rigid motion: energy relative to mu vol, the energy of a unit strain. Measured <= 3e-16
#: for the rotation-invariant materials; ``linear`` gives 0.28 (and forces >= 0.38 mu h^(d-1)).
RIGID_ENERGY_RTOL = 1e4 * EPS


@pytest.mark.parametrize("material", MATERIALS)
@pytest.mark.parametrize("d, degree", PATCH_CASES)
def test_rigid_motion_patch(patch_problem, d, degree, material):
    """A finite rotation plus translation stores no energy and makes no force (but ``linear``)."""
    problem, gradient = patch_problem(d, degree, material)
    R = rotation(d, 0.7)
    c, b = np.full(d, 0.4), np.arange(1.0, d + 1.0)
    X = problem.V.tabulate_dof_coordinates()[:, :d]
    set_displacement(problem, ((X - c) @ (R - np.eye(d)).T + b).ravel())
    vol = np.prod(PATCH_LENGTHS[d])
    cell = min(np.asarray(PATCH_LENGTHS[d]) / np.asarray(PATCH_DIVISIONS[d]))
    energy = problem.assemble_scalar(problem.energy_forms["elastic"]) / (MU * vol)
    force = np.abs(assembled_vector(gradient)).max() / (MU * cell ** (d - 1))
    if material == "linear":  # small strain sym(R) - I != 0: rotations cost energy
        assert energy > 1e-2 and force > 1e-2
    else:
        assert abs(energy) <= RIGID_ENERGY_RTOL, f"rigid motion energy {energy:.2e} mu vol"
        assert force <= FORCE_RTOL[degree], f"rigid motion forces {force:.2e} mu h^(d-1)"


# --- 3. the harmonic oscillator, mode by mode -----------------------------------------------------

BAR_LENGTHS = {2: (1.0, 0.2), 3: (1.0, 0.2, 0.2)}
BAR_DIVISIONS = {2: (6, 2), 3: (6, 2, 2)}
WALL = {2: ((-1e-6, -1.0), (1e-6, 1.0)), 3: ((-1e-6, -1.0, -1.0), (1e-6, 1.0, 1.0))}
OMEGA_H = 0.5  # omega_1 h of the lowest mode; the second mode has omega h >= 4 x that
MODAL_STEPS = {"newmark": 20, "implicit_euler": 10}
MODAL_AMPLITUDE = 1.0e-3  # m (the material is linear: any amplitude is exact)
#: Per-step amplification factors, relative: measured <= 2e-12 for Newmark; for implicit Euler
#: <= 1.2e-10, in the last steps of the second mode, decayed to 1e-4 of its initial amplitude
#: (round-off of u relative to what is left of the mode; <= 2e-13 while it is large).
FACTOR_RTOL = 1e-8
#: Newmark's modal energy: measured <= 2.3e-12 relative.
MODAL_ENERGY_RTOL = 1e-10
#: Displacement outside the two modes, relative to their amplitude: measured <= 4e-13.
OFF_MODES_RTOL = 1e-10


class ModalBar:
    """Pinned bar of linear material, its generalised eigenpairs and a simulation per scheme."""

    def __init__(self, directory: Path, d: int, mass: str):
        self.directory, self.d, self.mass = directory, d, mass
        self.sims: dict[str, Simulation] = {}
        problem = self.simulation("newmark").problem
        V = problem.V
        du, dv = ufl.TrialFunction(V), ufl.TestFunction(V)
        hessian = fem.form(ufl.derivative(ufl.derivative(problem.ufl_elastic, problem.u, dv),
                                          problem.u, du))
        set_displacement(problem, np.zeros(problem.u.x.array.size))  # K at rest
        K = scipy_matrix(hessian).toarray()
        self.M = scipy_matrix(problem.mass_form).toarray()
        free = np.ones(K.shape[0], dtype=bool)
        for bc in problem.bcs:
            free[bc.dof_indices()[0]] = False
        assert 0 < free.sum() < free.size
        lam, phi = scipy.linalg.eigh(K[np.ix_(free, free)], self.M[np.ix_(free, free)])
        omega = np.sqrt(lam)
        second = int(np.argmax(omega >= 4.0 * omega[0]))
        self.omega = omega[[0, second]]
        self.phi = np.zeros((free.size, 2))
        self.phi[free] = phi[:, [0, second]]
        self.phi /= np.abs(self.phi).max(axis=0)
        self.Mphi = self.M @ self.phi
        self.norms = np.einsum("ij,ij->j", self.phi, self.Mphi)

    def simulation(self, integrator: str) -> Simulation:
        if integrator not in self.sims:
            d = self.d
            scene = write_scene(self.directory, f"bar_{d}d_{self.mass}_{integrator}", d,
                                BAR_LENGTHS[d], "linear", integrator=integrator,
                                mass=self.mass, pin=WALL[d])
            domain = box(BAR_DIVISIONS[d], BAR_LENGTHS[d])
            self.sims[integrator] = Simulation(scene, MPI.COMM_WORLD, cli_options=NEWTON,
                                               domain=domain)
        return self.sims[integrator]

    def z(self, state) -> np.ndarray:
        """``omega q + i q'`` of the two modes (``q = phi^T M u / phi^T M phi``)."""
        q = self.Mphi.T @ state.u / self.norms
        q_dot = self.Mphi.T @ state.v / self.norms
        return self.omega * q + 1j * q_dot

    def off_modes(self, state) -> float:
        """Largest displacement outside the two modes, relative to the initial amplitude."""
        rest = state.u - self.phi @ (self.Mphi.T @ state.u / self.norms)
        return np.abs(rest).max() / MODAL_AMPLITUDE


@pytest.fixture(scope="module")
def modal_bar(tmp_path_factory):
    cache = {}

    def get(d: int, mass: str) -> ModalBar:
        if (d, mass) not in cache:
            cache[d, mass] = ModalBar(tmp_path_factory.mktemp(f"bar{d}{mass}"), d, mass)
        return cache[d, mass]

    return get


@pytest.mark.parametrize("integrator", ["newmark", "implicit_euler"])
@pytest.mark.parametrize("mass", ["consistent", "lumped"])
@pytest.mark.parametrize("d", [2, 3])
def test_modal_oscillator(modal_bar, d, mass, integrator):
    """Each mode is the harmonic oscillator with the scheme's exact amplification factor."""
    bar = modal_bar(d, mass)
    sim = bar.simulation(integrator)
    h = OMEGA_H / bar.omega[0]
    theta = bar.omega * h
    assert theta[1] >= 4 * theta[0]
    if integrator == "newmark":
        factor = (1 - 0.5j * theta) / (1 + 0.5j * theta)  # Cayley: |factor| = 1
    else:
        factor = 1 / (1 + 1j * theta)

    state = sim.initial_state()
    state.u[:] = MODAL_AMPLITUDE * bar.phi.sum(axis=1)
    if integrator == "newmark":
        state.a = sim.acceleration(state.u, state.v)
    z = [bar.z(state)]
    off = 0.0
    for _ in range(MODAL_STEPS[integrator]):
        state, _ = sim.step(state, h)
        z.append(bar.z(state))
        off = max(off, bar.off_modes(state))
    z = np.array(z)
    ratio = z[1:] / z[:-1]

    assert np.abs(ratio / factor - 1).max() <= FACTOR_RTOL, \
        f"amplification factor off by {np.abs(ratio / factor - 1).max():.2e}"
    phase = -np.angle(ratio)
    amplitude = np.abs(ratio)
    if integrator == "newmark":
        energy = 0.5 * np.abs(z) ** 2
        assert np.abs(energy / energy[0] - 1).max() <= MODAL_ENERGY_RTOL
        # the period lengthens: the phase advance per step is 2 atan(omega h/2) < omega h
        np.testing.assert_allclose(phase, 2 * np.arctan(theta / 2) * np.ones_like(phase),
                                   rtol=FACTOR_RTOL)
        assert np.all(phase < theta)
    else:
        np.testing.assert_allclose(amplitude, np.ones_like(amplitude) / np.sqrt(1 + theta**2),
                                   rtol=FACTOR_RTOL)
        np.testing.assert_allclose(phase, np.arctan(theta) * np.ones_like(phase),
                                   rtol=FACTOR_RTOL)
    assert off <= OFF_MODES_RTOL, f"other modes excited: {off:.2e}"
