"""Independent checks of the physical terms and the solver's safeguards.

Each check compares with something the library does not compute itself:

* friction: the lagged friction energy and gradient against the numpy oracle
  (:func:`fem_anim.reference.friction_energy`), whose gradient is checked by central
  differences; the sphere barrier's PSD-projected Hessian (barrier Hessian + curvature
  correction) against the oracle's Hessian without its b' Hess d term;
* Rayleigh damping: a linear-elastic cantilever started in one eigenmode of (K, M)
  decays by the closed-form amplification of the trapezoidal rule applied to
  q'' + (alpha + beta omega^2) q' + omega^2 q = 0 (Newmark is the trapezoidal rule, and
  C = alpha M + beta K keeps the mode decoupled), alpha and beta separately;
* consistent mass: mass, first, second and fourth moments of a box, f^T M g = int rho f g
  for f, g the interpolants of 1, x_i, x_i x_j (exact for P2), against the integrals of
  monomials over the box in closed form;
* the inversion filter: a step whose full Newton point x - y inverts elements; the number
  of halvings is the smallest k with det F(x - y/2^k) > 0 in every cell, with det F from
  the numpy oracle; in a solve from an inverted predictor every Newton iterate has
  det F > 0;
* stopping: Newton's tolerances are the documented ones, and every step of a hanging-beam
  run meets ``residual_norm <= max(atol, rtol initial_residual_norm)``, read from its stats
  rows (:func:`conftest.assert_rows_meet_the_test`, also applied to the default CLI run and
  to every preset's run); the round-off polish either meets the norm or decrement test or
  reports ``POLISH_FAILED_REASON``, which the energy report lists.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
import ufl
from conftest import README_ATOL, README_RTOL, assert_rows_meet_the_test
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from test_contact import GAP, near_contact_positions, reference_scene
from test_reference_comparison import Comparison, beam_mesh, reference_order, write_scene

from fem_anim import compat, reference
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation

serial = pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial: reference dof map")


# -- friction and barriers against the numpy oracle ---------------------------------------------
#: DOLFINx against the oracle: the same sums in another order. Measured <= 2.3e-16 relative
#: (friction energy) and 7.4e-16 (gradient, relative to its largest entry).
ORACLE_RTOL = 5e-14


@serial
@pytest.mark.parametrize("kind", ["plane", "sphere"])
def test_friction_matches_reference(tmp_path, kind):
    """D and grad D of the lagged friction, with slips on both sides of eps."""
    mu, h = 0.4, 0.3  # eps = eps_v h = 3e-4 m (the scene's eps_v = 1e-3); slips to 6e-4 m
    scene, obstacle = reference_scene(tmp_path, kind, 3, friction=mu)
    c = Comparison(scene)
    p = c.problem
    eps = p.contact.obstacles[0]["epsv"] * h
    p.contact.stage(h)
    x_prev = near_contact_positions(c.points, seed=7)
    x = x_prev + 0.3 * GAP * np.random.default_rng(8).uniform(-1, 1, x_prev.size)
    c.set_function(p.u_prev, x_prev - c.X)
    c.set_positions(x)
    args = (c.points, c.cells, x, x_prev, obstacle, eps)
    slips = np.linalg.norm((x - x_prev).reshape(-1, 3)[:, :2], axis=1)
    assert np.any(slips < 0.8 * eps) and np.any(slips > 1.2 * eps)  # both branches of f0
    energy = reference.friction_energy(*args)
    assert energy > 0
    assert c.scalar(fem.form(p.contact.friction)) == pytest.approx(energy, rel=ORACLE_RTOL)
    g_ref = reference.friction_gradient(*args)
    g = c.vector(fem.form(ufl.derivative(p.contact.friction, p.u, ufl.TestFunction(p.V))))
    assert np.abs(g - g_ref).max() <= ORACLE_RTOL * np.abs(g_ref).max()


def test_reference_friction_gradient_by_finite_differences():
    """The oracle's friction gradient is the derivative of its energy (central differences)."""
    points, cells = reference.box_mesh((4, 2, 2), (1.0, 0.25, 0.25))
    obstacle = {"type": "sphere", "center": [0.5, 0.125, -5.0], "radius": 5.0 - GAP,
                "dhat": 0.01, "stiffness": 3.0e3, "friction": 0.4}
    eps = 3e-4
    x_prev = near_contact_positions(points, seed=9)
    x = x_prev + 0.3 * GAP * np.random.default_rng(10).uniform(-1, 1, x_prev.size)
    args = (points, cells)
    g = reference.friction_gradient(*args, x, x_prev, obstacle, eps)
    v = np.random.default_rng(11).uniform(-1, 1, x.size)
    h = 1e-8
    D = [reference.friction_energy(*args, x + s * h * v, x_prev, obstacle, eps) for s in (-1, 1)]
    # central differences of a C^2 function: error O(h^2) ~ 1e-10 of g.v, round-off ~1e-8
    assert (D[1] - D[0]) / (2 * h) == pytest.approx(g @ v, rel=1e-6)
    # and the closed form at y = 0 (f1(y)/y -> 2/eps) and across y = eps: f0 is C^1 there
    f0, f1_over_y = reference.obstacle_barrier.smoothed_slip(np.array([0.0, eps * (1 - 1e-9),
                                                              eps * (1 + 1e-9)]), eps)
    assert f0[0] == pytest.approx(eps / 3) and f1_over_y[0] == pytest.approx(2 / eps)
    assert f0[1] == pytest.approx(f0[2], rel=1e-8)
    assert f1_over_y[1] == pytest.approx(f1_over_y[2], rel=1e-8)


@serial
def test_projected_sphere_hessian_matches_reference(tmp_path):
    """Barrier Hessian + curvature correction = the oracle's Hessian without b' Hess d."""
    scene, obstacle = reference_scene(tmp_path, "sphere", 3)
    c = Comparison(scene)
    p = c.problem
    x = near_contact_positions(c.points, seed=12)
    c.set_positions(x)
    dv, du = ufl.TestFunction(p.V), ufl.TrialFunction(p.V)
    hessian = ufl.derivative(ufl.derivative(p.contact.energy, p.u, dv), p.u, du)
    projected = c.matrix(fem.form(hessian + p.contact.curvature_correction(du, dv)))
    args = (c.points, c.cells, x, obstacle)
    H_ref = reference.contact_hessian(*args, projected=True)
    assert abs(projected - H_ref).max() <= ORACLE_RTOL * abs(H_ref).max()
    # the projection matters here: the unprojected Hessian differs by far more
    full = reference.contact_hessian(*args)
    assert abs(full - H_ref).max() > 1e3 * ORACLE_RTOL * abs(H_ref).max()
    # and it is positive semidefinite
    assert np.linalg.eigvalsh(projected.toarray()).min() >= -ORACLE_RTOL * abs(H_ref).max()


# -- consistent mass: moments of a box in closed form -------------------------------------------
BOX_ORIGIN = np.array([0.2, -0.1, 0.3])
BOX_SIZE = np.array([0.6, 0.2, 0.3])
RHO = 1000.0


def to_scipy(A) -> sp.csr_matrix:
    indptr, indices, data = A.getValuesCSR()
    return sp.csr_matrix((data, indices, indptr), shape=A.getSize())


def box_monomial_integral(powers) -> float:
    """int over the box of x^p y^q z^r, in closed form."""
    lo, hi = BOX_ORIGIN, BOX_ORIGIN + BOX_SIZE
    return float(np.prod([(hi[i] ** (k + 1) - lo[i] ** (k + 1)) / (k + 1)
                          for i, k in enumerate(powers)]))


@serial
@pytest.mark.parametrize("degree", [1, 2])
def test_consistent_mass_moments_are_exact(degree):
    """f^T M g = int rho f g and k(v) = 1/2 int rho |v|^2 for the monomials of degree <= k.

    P1: f, g in {1, x, y, z} (mass, first and second moments); P2 adds x_i x_j, so the
    products reach degree 4 (fourth moments): exact only with quadrature degree 2k.
    """
    overrides = ["mesh.size=" + str(BOX_SIZE.tolist()), "mesh.origin=" + str(BOX_ORIGIN.tolist()),
                 "mesh.element_size=0.15", f"element.degree={degree}", f"material.density={RHO}",
                 "pin.0.min=[0.19, -1, -1]", "pin.0.max=[0.21, 1, 1]"]
    p = Simulation(load_scene(None, overrides), MPI.COMM_WORLD).problem
    X = p.V.tabulate_dof_coordinates()
    exponents = [np.zeros(3, int)] + [np.eye(3, dtype=int)[i] for i in range(3)]
    if degree == 2:
        exponents += [np.eye(3, dtype=int)[i] + np.eye(3, dtype=int)[j]
                      for i in range(3) for j in range(i, 3)]
    fields = np.array([np.prod(X ** e, axis=1) for e in exponents])  # nodal interpolants
    M = fem_petsc.assemble_matrix(p.mass_form)
    M.assemble()
    M = to_scipy(M)
    n = X.shape[0]
    F = np.zeros((len(exponents), 3 * n))
    F[:, 0::3] = fields  # the x component
    gram = F @ (M @ F.T)
    exact = RHO * np.array([[box_monomial_integral(a + b) for b in exponents]
                            for a in exponents])
    # measured <= 4e-16 relative to the largest entry (the box's mass)
    np.testing.assert_allclose(gram, exact, rtol=0, atol=1e-14 * exact.max())
    assert gram[0, 0] == pytest.approx(RHO * np.prod(BOX_SIZE), rel=1e-14)
    # the kinetic energy form: v = (f_a, f_b, 1) gives 1/2 int rho (f_a^2 + f_b^2 + 1)
    a, b = len(exponents) - 1, 1
    p.u.x.array[:] = 0.0
    p.v.x.array[:] = np.column_stack([fields[a], fields[b], fields[0]]).ravel()
    kinetic = 0.5 * (exact[a, a] + exact[b, b] + exact[0, 0])
    assert p.energies()["kinetic"] == pytest.approx(kinetic, rel=5e-14)  # measured 2e-15


# -- Rayleigh damping: closed-form modal decay --------------------------------------------------
def free_dofs(p) -> np.ndarray:
    pinned = np.zeros(p.u.x.array.size, bool)
    for bc in p.bcs:
        pinned[bc.dof_indices()[0]] = True
    return np.flatnonzero(~pinned)


def lowest_mode(p) -> tuple[float, np.ndarray]:
    """omega_1 and phi_1 (M-normalised, zero on pins) of K phi = omega^2 M phi at rest."""
    dv, du = ufl.TestFunction(p.V), ufl.TrialFunction(p.V)
    K = fem_petsc.assemble_matrix(fem.form(ufl.derivative(ufl.derivative(
        p.ufl_elastic, p.u, dv), p.u, du)))
    K.assemble()
    M = fem_petsc.assemble_matrix(p.mass_form)
    M.assemble()
    free = free_dofs(p)
    K, M = (to_scipy(A)[free][:, free].toarray() for A in (K, M))
    omega2, modes = scipy.linalg.eigh(K, M, subset_by_index=[0, 0])
    phi = np.zeros(p.u.x.array.size)
    phi[free] = modes[:, 0]
    return float(np.sqrt(omega2[0])), phi


def trapezoidal_amplification(omega: float, damping: float, h: float) -> np.ndarray:
    """T with (q, q')_{n+1} = T (q, q')_n for q'' + damping q' + omega^2 q = 0 (trapezoidal)."""
    A = np.array([[0.0, 1.0], [-omega ** 2, -damping]])
    eye = np.eye(2)
    return np.linalg.solve(eye - 0.5 * h * A, eye + 0.5 * h * A)


@serial
@pytest.mark.parametrize("term", ["alpha", "beta"])
def test_rayleigh_damping_decays_a_mode_at_the_closed_form_rate(tmp_path, term):
    """A linear cantilever started in its first mode stays in it and decays as predicted.

    C = alpha M + beta K maps the mode to itself with modal damping alpha + beta omega^2;
    Newmark is the trapezoidal rule, so q_n = (T^n (q_0, 0))_0 exactly, up to Newton's
    tolerance. The library's dissipation function plays no part in the prediction.
    """
    from test_damping_and_handles import bar as damped_bar

    probe, _ = damped_bar(tmp_path)
    omega, _ = lowest_mode(probe.problem)
    modal = 2.0 * 0.15 * omega  # 15 % of critical damping
    alpha, beta = (modal, 0.0) if term == "alpha" else (0.0, modal / omega ** 2)
    sim, state = damped_bar(tmp_path, alpha=alpha or None, beta=beta or None)
    p = sim.problem
    omega, phi = lowest_mode(p)
    h, steps, q0 = 2 * np.pi / omega / 20, 30, 0.02  # 20 steps a period, 1.5 periods
    state.u = q0 * phi / np.abs(phi).max()
    state.v = np.zeros_like(state.u)
    state.a = -omega ** 2 * state.u  # M^-1 (-K u - C 0) for a mode
    T = trapezoidal_amplification(omega, alpha + beta * omega ** 2, h)
    z = np.array([1.0, 0.0])
    errors = []
    for _ in range(steps):
        state, _ = sim.step(state, h)
        z = T @ z
        errors.append(np.abs(state.u - z[0] * q0 * phi / np.abs(phi).max()).max() / q0)
    amplitude = np.hypot(z[0], z[1] / omega)  # exp(-0.15 omega t) = 0.24 after 1.5 periods
    assert amplitude < 0.3  # the damping is visible: a factor 2 on it is too
    assert max(errors) <= 1e-9, max(errors)  # measured 2.5e-11 (snes_rtol 1e-12)


# -- the inversion filter -----------------------------------------------------------------------
def reference_min_det(points, cells, x) -> float:
    return float(np.linalg.det(reference.deformation_gradient(points, cells, x)).min())


@serial
def test_inversion_filter_halves_a_constructed_step(tmp_path):
    """x - y inverts elements: the pre-check halves y exactly k times, k the smallest with
    det F(x - y/2^k) > 0 in every cell (numpy oracle); a step whose predictor inverts
    elements is solved with det F > 0 at every Newton iterate."""
    points, cells, domain = beam_mesh(3)
    scene = write_scene(tmp_path, 3, "neohookean", integrator="implicit_euler", pinned=True)
    sim = Simulation(scene, MPI.COMM_WORLD, {"snes_rtol": "1e-10"}, domain=domain)
    p, minimiser = sim.problem, sim.minimiser
    assert p.filter_inversion
    order = reference_order(domain, p.V)
    X = points.ravel()
    y_ref = np.zeros_like(X)  # a non-uniform squash along z (more at larger x)
    y_ref[2::3] = 7.0 * points[:, 2] * (0.5 + points[:, 0])
    y_ref[np.repeat(points[:, 0] < 1e-6, 3)] = 0.0  # the pinned wall does not move
    dets = [reference_min_det(points, cells, X - y_ref / 2 ** k) for k in range(8)]
    expected = next(k for k, det in enumerate(dets) if det > 0)
    assert expected >= 3, dets  # several halvings, and a wrong trial point shows
    assert reference_min_det(points, cells, X + y_ref) > 0  # x + y would pass at once
    x = compat.petsc_vec(p.u).duplicate()
    y = x.duplicate()
    x.set(0.0)
    with y.localForm() as local:
        local.array[order] = y_ref
    minimiser.b.set(0.0)
    assert minimiser._precheck(x, y) is True
    halvings = np.log2(np.linalg.norm(y_ref) / y.norm())
    assert halvings == pytest.approx(expected, abs=1e-12)
    # a full solve: the predictor X + h v is inverted; no Newton iterate ever is
    h = 0.1
    state = sim.initial_state()
    state.v[order] = -0.5 * y_ref / h
    iterates = []

    def monitor(snes, it, norm):  # serial: every dof; read-only (PETSc 3.22 locks it here)
        iterates.append(reference_min_det(points, cells, X + snes.getSolution().array_r[order]))

    negative = []
    library_min_det = p.min_det_F

    def counted_min_det():
        value = library_min_det()
        negative.append(value <= 0)
        return value

    p.min_det_F = counted_min_det
    minimiser.snes.setMonitor(monitor)
    assert reference_min_det(points, cells, X + state.v[order] * h) < 0  # the predictor
    state, stats = sim.step(state, h)
    assert any(negative)  # an inverted trial point was met, and rejected
    assert reference_min_det(points, cells, X + state.u[order]) > 0
    assert stats.newton_its >= 3 and len(iterates) == stats.newton_its + 1
    assert min(iterates) > 0, iterates


# -- stopping tests -----------------------------------------------------------------------------
def test_every_accepted_step_meets_the_residual_test():
    """A short hanging-beam run with the library defaults: every row meets the documented
    residual test."""
    sim = Simulation(load_scene(None, ["mesh.size=[1.0, 0.1, 0.1]", "mesh.element_size=0.1",
                                       "time.steps=6"]), MPI.COMM_WORLD)
    rtol, atol, _, _ = sim.minimiser.snes.getTolerances()
    assert (rtol, atol) == (README_RTOL, README_ATOL)
    result = sim.run(None)
    assert len(result.rows) == 6
    assert_rows_meet_the_test(result.rows)
    # the relative test decided (r0 large enough): a swapped atol would have stopped sooner
    assert all(r["initial_residual_norm"] * README_RTOL > README_ATOL for r in result.rows)


@serial
def test_polish_meets_the_test_or_reports_it(tmp_path):
    """_polish: full Newton steps from near the solution meet a reachable test (reason 2/3),
    an unreachable one is reported as POLISH_FAILED_REASON, in stats and the energy report."""
    from fem_anim.simulation.energy_report import describe_energy, energy_report, initial_energies
    from fem_anim.solver.stopping import POLISH_FAILED_REASON, polish

    scene = write_scene(tmp_path, 3, "neohookean", integrator="implicit_euler", pinned=True)
    # an unreachable test: the line search stalls at the round-off floor of g, the polish
    # cannot reach 1e-30 relative either
    sim = Simulation(scene, MPI.COMM_WORLD, {"snes_rtol": "1e-30", "snes_atol": "0"})
    state, row = sim.timed_step(sim.initial_state(), 1 / 60)
    assert row["snes_reason"] == POLISH_FAILED_REASON
    assert row["residual_norm"] > 1e-30 * row["initial_residual_norm"]
    report = energy_report([row], initial_energies(sim), sim.scene)
    assert report["unconverged_steps"] == [1]
    assert "without meeting the stopping test" in describe_energy(report, sim.scene)
    # a reachable test, from a point off the solution: the polish's full steps meet it
    m = sim.minimiser
    x = compat.petsc_vec(sim.problem.u).copy()
    x.array[:] = state.u[: x.array.size]  # the step's minimiser (serial: no ghosts)
    solution = x.copy()
    x.array[:] += 1e-6 * np.random.default_rng(13).uniform(-1, 1, x.array.size)
    for bc in sim.problem.bcs:
        x.array[bc.dof_indices()[0]] = solution.array[bc.dof_indices()[0]]
    m.snes.setTolerances(rtol=1e-10, atol=0.0)
    m.stop.history = [(1.0, 0.0)]  # r0 = 1: the target is 1e-10
    reason, norm = polish(m, x)
    assert reason == 3 and norm <= 1e-10
    assert np.abs(x.array - solution.array).max() < 1e-9
    # ... and unreachable from there (max 5 full steps cannot reach 1e-30)
    m.snes.setTolerances(rtol=1e-30, atol=0.0)
    reason, norm = polish(m, x)
    assert reason == POLISH_FAILED_REASON and norm > 1e-30
    # the decrement test: reachable (lambda^2/2 of the next direction <= 1e-20 J) or not
    m.stop.stopping = "decrement"
    x.array[:] += 1e-6 * np.random.default_rng(14).uniform(-1, 1, x.array.size)
    for bc in sim.problem.bcs:
        x.array[bc.dof_indices()[0]] = solution.array[bc.dof_indices()[0]]
    m.stop.decrement_tol = 1e-20
    reason, _ = polish(m, x)
    assert reason == 5 and m.stop.decrements[-1] <= 1e-20
    m.stop.decrement_tol = 0.0
    reason, _ = polish(m, x)
    assert reason == POLISH_FAILED_REASON
