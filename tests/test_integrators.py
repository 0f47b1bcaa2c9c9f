"""Time integrators on a vibrating bar, driven through :class:`fem_anim.simulation.loop.Simulation`.

The body is a coarse 1 x 0.1 x 0.1 m bar (``mesh.element_size = 0.1``, 86 vertices) pinned at
x = 0, without gravity, so the motion is the undamped free vibration of

    M u'' + K u = 0   (linear material; StVK linearises to the same K at u = 0).

The checks follow seed section 3.1 (every scheme is one minimisation of eq. (4)):

* fitted order of accuracy in h against a fine-step Newmark reference (newmark 2,
  implicit_euler 1, bdf2 2), starting from the two lowest *discrete* bending modes so that no
  unresolved high mode pollutes the error;
* energy: Newmark (the trapezoidal rule, eqs. (1a)-(1b)) keeps k + E of a linear system;
  implicit Euler loses it at every step; BDF2 loses less;
* symplectic Euler is stable below h = 2/omega_max and blows up above it, with omega_max
  computed exactly from the generalised eigenproblem K phi = omega^2 M phi of this mesh;
* free fall without pins: Newmark is exact for constant acceleration, u = g t^2/2 to round-off.

The modal analysis assembles K and M densely, so the tests using it are serial only.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from scenes import bar, make_scene

from fem_anim.errors import ConvergenceError
from fem_anim.simulation.loop import Simulation

serial_only = pytest.mark.skipif(MPI.COMM_WORLD.size > 1,
                                 reason="serial only: dense modal analysis on global dof arrays")

#: Tight Newton tolerances: the time-discretisation error, not the solver, must dominate.
SOLVER = {"snes_rtol": "1e-12", "snes_atol": "1e-15"}

ORDERS = {"newmark": 2, "implicit_euler": 1, "bdf2": 2}


# --- building and driving the bar -------------------------------------------------------------


class Bars:
    """Simulations of the bar scene, built once per configuration and module."""

    def __init__(self, directory: Path):
        self.directory = directory
        self.cache: dict[tuple, Simulation] = {}

    def __call__(self, integrator: str, model: str = "linear",
                 mass: str = "consistent") -> Simulation:
        key = (integrator, model, mass)
        if key not in self.cache:
            scene = make_scene(self.directory, bar(
                f"bar_{integrator}_{model}_{mass}", material={"model": model, "mass": mass},
                time={"integrator": integrator}))
            self.cache[key] = Simulation(scene, MPI.COMM_WORLD, cli_options=SOLVER)
        return self.cache[key]


@pytest.fixture(scope="module")
def bars(tmp_path_factory) -> Bars:
    return Bars(tmp_path_factory.mktemp("bars"))


def dense(A) -> np.ndarray:
    indptr, indices, values = A.getValuesCSR()
    return scipy.sparse.csr_matrix((values, indices, indptr), shape=A.getSize()).toarray()


def free_dofs(problem) -> np.ndarray:
    """Boolean mask of the dofs that are not pinned."""
    free = np.ones(problem.u.x.array.size, dtype=bool)
    for bc in problem.bcs:
        free[bc.dof_indices()[0]] = False
    return free


def stiffness_and_mass(problem) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Dense K (Hessian of the elastic energy at u = 0) and M on the free dofs, and the mask.

    K is compiled here from the scene's own ``psi`` (independent of the integrator, whose step
    objective for symplectic Euler is linear in u), M is the problem's ``mass_form``.
    """
    V, d = problem.V, problem.d
    assert not problem.material.needs(d), "material needs quadrature data"
    u0 = fem.Function(V)
    psi = problem.material.psi(ufl.Identity(d) + ufl.grad(u0), problem.mu, problem.lmbda)
    energy = psi * problem.dx_elastic
    du, dv = ufl.TrialFunction(V), ufl.TestFunction(V)
    hessian = fem.form(ufl.derivative(ufl.derivative(energy, u0, dv), u0, du))
    K_mat = fem_petsc.assemble_matrix(hessian)
    K_mat.assemble()
    M_mat = fem_petsc.assemble_matrix(problem.mass_form)
    M_mat.assemble()
    free = free_dofs(problem)
    K, M = dense(K_mat)[np.ix_(free, free)], dense(M_mat)[np.ix_(free, free)]
    K_mat.destroy()
    M_mat.destroy()
    return K, M, free


def normal_modes(problem) -> tuple[np.ndarray, np.ndarray]:
    """Angular frequencies (ascending) and mode shapes (full dof vectors, zero on pins)."""
    K, M, free = stiffness_and_mass(problem)
    lam, phi = scipy.linalg.eigh(K, M)
    shapes = np.zeros((free.size, lam.size))
    shapes[free] = phi
    return np.sqrt(lam), shapes


def energies(sim: Simulation, state) -> dict[str, float]:
    p = sim.problem
    p.u.x.array[:] = state.u
    p.v.x.array[:] = state.v
    return p.energies()


def smooth_velocity(sim: Simulation, v0: float) -> np.ndarray:
    """A velocity field exciting many modes: v = v0 (0, x/2, x^2) (x along the bar, in m)."""
    x = sim.problem.V.tabulate_dof_coordinates()[:, 0]
    v = np.zeros((x.size, 3))
    v[:, 1] = 0.5 * v0 * x
    v[:, 2] = v0 * x**2
    return v.ravel()


def run_energy(sim: Simulation, v0: float, h: float, steps: int) -> np.ndarray:
    """Total energy after each of ``steps`` steps from the rest shape with velocity field v0."""
    state = sim.initial_state()
    state.v[:] = smooth_velocity(sim, v0)
    total = [energies(sim, state)["total_energy"]]
    for _ in range(steps):
        state, _ = sim.step(state, h)
        total.append(sim.problem.energies()["total_energy"])
    return np.array(total)


# --- order of accuracy --------------------------------------------------------------------------

T_FINAL = 2.0  # s, about half the period of the lowest bending mode (omega_1 = 1.5 rad/s)
AMPLITUDE = 1.0e-4  # m, tip amplitude of each mode: small enough for StVK to be linear


class ModalProblem:
    """Initial data on the two lowest bending modes and the fine-step Newmark reference.

    u_0 = A phi_1, v_0 = A omega_2 phi_2 (each mode scaled to unit max-norm), whose exact
    semi-discrete solution is u(t) = A (phi_1 cos omega_1 t + phi_2 sin omega_2 t).
    """

    def __init__(self, bars: Bars, model: str, h_ref: float):
        self.bars, self.model = bars, model
        omega, phi = normal_modes(bars("newmark", model).problem)
        self.omega = omega[:2]
        self.phi = phi[:, :2] / np.abs(phi[:, :2]).max(axis=0)
        self.reference = self.run("newmark", h_ref)

    def initial_state(self, sim: Simulation):
        state = sim.initial_state()
        state.u[:] = AMPLITUDE * self.phi[:, 0]
        state.v[:] = AMPLITUDE * self.omega[1] * self.phi[:, 1]
        if sim.integrator.name == "newmark":
            state.a = sim.acceleration(state.u)
        return state

    def exact(self, t: float) -> np.ndarray:
        return AMPLITUDE * (self.phi[:, 0] * np.cos(self.omega[0] * t)
                            + self.phi[:, 1] * np.sin(self.omega[1] * t))

    def run(self, integrator: str, h: float) -> np.ndarray:
        sim = self.bars(integrator, self.model)
        state = self.initial_state(sim)
        for _ in range(round(T_FINAL / h)):
            state, _ = sim.step(state, h)
        assert state.time == pytest.approx(T_FINAL)
        return state.u.copy()

    def error(self, integrator: str, h: float) -> float:
        return np.linalg.norm(self.run(integrator, h) - self.reference) / np.linalg.norm(
            self.reference)


@pytest.fixture(scope="module")
def modal_linear(bars) -> ModalProblem:
    return ModalProblem(bars, "linear", h_ref=0.0025)


@pytest.fixture(scope="module")
def modal_stvk(bars) -> ModalProblem:
    return ModalProblem(bars, "stvk", h_ref=0.00125)


def fitted_order(steps, errors) -> float:
    return np.polyfit(np.log(steps), np.log(errors), 1)[0]


@serial_only
def test_reference_is_the_modal_solution(modal_linear):
    """The fine Newmark run reproduces the exact semi-discrete solution (validates the setup)."""
    exact = modal_linear.exact(T_FINAL)
    assert np.linalg.norm(modal_linear.reference - exact) < 1e-4 * np.linalg.norm(exact)


@serial_only
@pytest.mark.parametrize("integrator", list(ORDERS))
def test_order_of_accuracy_linear(modal_linear, integrator):
    """log(error) against log(h) at T = 2 s has slope = the scheme's order (+-0.3)."""
    steps = [0.04, 0.02, 0.01]
    errors = [modal_linear.error(integrator, h) for h in steps]
    order = fitted_order(steps, errors)
    assert abs(order - ORDERS[integrator]) < 0.3, (integrator, errors, order)
    assert errors[-1] < 0.05  # in the asymptotic range, not saturated


@serial_only
@pytest.mark.slow
@pytest.mark.parametrize("integrator", list(ORDERS))
def test_order_of_accuracy_stvk(modal_stvk, integrator):
    """Same with small-amplitude StVK (Newton does real work) and four step sizes."""
    steps = [0.04, 0.02, 0.01, 0.005]
    errors = [modal_stvk.error(integrator, h) for h in steps]
    order = fitted_order(steps, errors)
    assert abs(order - ORDERS[integrator]) < 0.3, (integrator, errors, order)


# --- energy behaviour ---------------------------------------------------------------------------

ENERGY_STEPS, ENERGY_DT = 200, 0.01


@pytest.fixture(scope="module")
def linear_energy(bars) -> dict[str, np.ndarray]:
    """Total energy histories of the linear bar, 200 steps of 0.01 s, v0 = 0.05 m/s."""
    return {name: run_energy(bars(name), 0.05, ENERGY_DT, ENERGY_STEPS)
            for name in ("newmark", "implicit_euler", "bdf2")}


def test_newmark_conserves_energy_linear(linear_energy):
    """The trapezoidal rule conserves 1/2 v.Mv + 1/2 u.Ku exactly for a linear system."""
    total = linear_energy["newmark"]
    drift = np.abs(total / total[0] - 1.0).max()
    assert drift < 1e-3
    assert drift < 1e-9  # exact up to the Newton tolerance


def test_newmark_conserves_energy_stvk(bars):
    """Small-amplitude StVK (tip amplitude ~3 mm): nearly linear, drift within 1e-3."""
    total = run_energy(bars("newmark", "stvk"), 0.005, ENERGY_DT, ENERGY_STEPS)
    assert np.abs(total / total[0] - 1.0).max() < 1e-3


def test_implicit_euler_dissipates_monotonically(linear_energy):
    """Implicit Euler: E_{n+1} - E_n = -1/2 |dv|_M^2 - 1/2 |du|_K^2 < 0 at every step."""
    total = linear_energy["implicit_euler"]
    assert np.all(np.diff(total) < 0.0)
    assert total[-1] < 0.99 * total[0]


def test_bdf2_dissipates_less_than_implicit_euler(linear_energy):
    """BDF2's numerical damping is O(h^3) per unit time against O(h) for implicit Euler."""
    lost_bdf2 = linear_energy["bdf2"][0] - linear_energy["bdf2"][-1]
    lost_euler = linear_energy["implicit_euler"][0] - linear_energy["implicit_euler"][-1]
    assert 0.0 < lost_bdf2 < 0.5 * lost_euler


# --- symplectic Euler stability -----------------------------------------------------------------


@pytest.fixture(scope="module")
def omega_max(bars) -> dict[str, float]:
    """Highest natural frequency of the bar for each mass matrix (rad/s).

    Exact for this mesh: the largest generalised eigenvalue of K phi = omega^2 M phi on the free
    dofs: 1254 rad/s (consistent), 641 rad/s (lumped), so h_crit = 2/omega_max = 1.60 ms and
    3.12 ms. The a-priori estimate c_p / element size of forms/time_schemes.py gives 116 rad/s
    here, an order of magnitude too low (c_p = 11.6 m/s; the shortest edge is 0.07 m).
    """
    out = {}
    for mass in ("consistent", "lumped"):
        omega, _ = normal_modes(bars("symplectic_euler", "linear", mass).problem)
        out[mass] = omega[-1]
    return out


def run_symplectic(sim: Simulation, h: float, steps: int, growth_stop: float = 1e12) -> np.ndarray:
    """Energy history from a smooth velocity plus seeded 1 um noise (excites omega_max)."""
    state = sim.initial_state()
    state.v[:] = smooth_velocity(sim, 0.05)
    noise = np.random.default_rng(0).standard_normal(state.u.size)
    state.u[:] = 1e-6 * noise * free_dofs(sim.problem)
    total = [energies(sim, state)["total_energy"]]
    try:
        for _ in range(steps):
            state, _ = sim.step(state, h)
            total.append(sim.problem.energies()["total_energy"])
            if not np.isfinite(total[-1]) or total[-1] > growth_stop * total[0]:
                break
    except ConvergenceError:
        total.append(np.inf)
    return np.array(total)


@serial_only
@pytest.mark.parametrize("mass", ["consistent", "lumped"])
@pytest.mark.parametrize("fraction", [0.5, 0.9])
def test_symplectic_euler_stable_below_limit(bars, omega_max, mass, fraction):
    """h = fraction * 2/omega_max: 200 steps with the energy bounded (within 1 %)."""
    h = fraction * 2.0 / omega_max[mass]
    total = run_symplectic(bars("symplectic_euler", "linear", mass), h, 200)
    assert total.size == 201
    assert np.all(np.isfinite(total))
    assert np.abs(total / total[0] - 1.0).max() < 1e-2


@serial_only
@pytest.mark.parametrize("mass", ["consistent", "lumped"])
@pytest.mark.parametrize("fraction", [1.1, 1.5])
def test_symplectic_euler_blows_up_above_limit(bars, omega_max, mass, fraction):
    """h = fraction * 2/omega_max: |amplification| > 1 for the top mode; energy x 1e6 or worse."""
    h = fraction * 2.0 / omega_max[mass]
    total = run_symplectic(bars("symplectic_euler", "linear", mass), h, 200)
    assert not np.isfinite(total[-1]) or total[-1] > 1e6 * total[0]


# --- free fall ----------------------------------------------------------------------------------


@pytest.mark.parametrize("mass", ["consistent", "lumped"])
def test_newmark_free_fall_is_exact(tmp_path, mass):
    """No pins: a_0 = M^-1 M g = g, and Newmark integrates constant acceleration exactly."""
    scene = make_scene(tmp_path, bar("free_fall", material={"model": "neohookean", "mass": mass},
                                     gravity={"acceleration": [0.0, 0.0, -9.81]}, pin=[]))
    sim = Simulation(scene, MPI.COMM_WORLD, cli_options=SOLVER)
    g = np.array([0.0, 0.0, -9.81])
    state = sim.initial_state()
    assert np.abs(state.a.reshape(-1, 3) - g).max() < 1e-12 * 9.81
    h = 0.01
    for _ in range(50):
        state, _ = sim.step(state, h)
        t = state.time
        assert np.abs(state.u.reshape(-1, 3) - 0.5 * g * t * t).max() < 1e-12 * 9.81 * t * t
        assert np.abs(state.v.reshape(-1, 3) - g * t).max() < 1e-12 * 9.81 * t
