"""Self-checks of the numpy reference implementation (``fem_anim.reference``).

Material derivatives and assembled gradients/Hessians are checked against central finite
differences, the mass matrices against the seed's closed forms (eqs. (17)-(20)), and the
integrators against exact solutions: free fall (Newmark is exact for constant acceleration),
one linear vibration mode (implicit Euler damping factor, Newmark energy conservation,
fitted orders of accuracy).
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from fem_anim.reference import (
    INTEGRATORS,
    MATERIALS,
    ConvergenceError,
    box_mesh,
    build_problem,
    cell_volumes,
    deformation_gradient,
    deformed_shape_matrix,
    elastic_energy,
    elastic_gradient,
    elastic_hessian,
    first_piola,
    first_piola_derivative,
    gravity_energy,
    gravity_gradient,
    initial_state,
    lame_parameters,
    mass_matrix,
    psi,
    rest_shape_matrix,
    simulate,
    stable_neohookean_parameters,
)
from fem_anim.reference.tensor import polar_rotation, vec

MU, LMBDA = 1.3, 2.1
DIMS = (2, 3)
ROTATION_INVARIANT = tuple(m for m in MATERIALS if m != "linear")


def random_rotation(rng: np.random.Generator, d: int, n: int = 1) -> np.ndarray:
    """``n`` random rotations in SO(d)."""
    Q, _ = np.linalg.qr(rng.standard_normal((n, d, d)))
    Q[np.linalg.det(Q) < 0, :, 0] *= -1.0
    return Q


def sample_F(d: int, kind: str, seed: int = 0, n: int = 4) -> np.ndarray:
    """Deformation gradients near the identity, rotated, or inverted (``det F < 0``)."""
    rng = np.random.default_rng(seed)
    F = np.eye(d) + 0.15 * rng.standard_normal((n, d, d))
    if kind == "rotated":
        F = random_rotation(rng, d, n) @ F
    elif kind == "inverted":
        F = np.diag([1.0] * (d - 1) + [-1.0]) @ F
    return F


def relative_error(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.max(np.abs(a - b)) / np.max(np.abs(b)))


def fd_first_piola(material: str, F: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of ``psi`` with respect to each ``F_ka``."""
    d = F.shape[-1]
    P = np.zeros_like(F)
    for k in range(d):
        for a in range(d):
            dF = np.zeros((d, d))
            dF[k, a] = h
            plus, minus = psi(material, F + dF, MU, LMBDA), psi(material, F - dF, MU, LMBDA)
            P[:, k, a] = (plus - minus) / (2 * h)
    return P


def fd_first_piola_derivative(material: str, F: np.ndarray, h: float = 1e-6) -> np.ndarray:
    """Central differences of ``vec(P)`` with respect to ``vec(F)`` (column-major)."""
    d = F.shape[-1]
    A = np.zeros((len(F), d * d, d * d))
    for k in range(d):
        for a in range(d):
            dF = np.zeros((d, d))
            dF[k, a] = h
            plus = vec(first_piola(material, F + dF, MU, LMBDA))
            minus = vec(first_piola(material, F - dF, MU, LMBDA))
            A[:, :, a * d + k] = (plus - minus) / (2 * h)
    return A


def material_states(material: str) -> tuple[str, ...]:
    """Neo-Hookean is undefined for inverted elements; the others are checked there too."""
    return ("near_identity", "rotated") + (() if material == "neohookean" else ("inverted",))


# --- materials ------------------------------------------------------------------------------


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("material", MATERIALS)
def test_first_piola_matches_finite_differences(material, d):
    for kind in material_states(material):
        F = sample_F(d, kind)
        P = first_piola(material, F, MU, LMBDA)
        assert relative_error(P, fd_first_piola(material, F)) < 1e-6, kind


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("material", MATERIALS)
def test_first_piola_derivative_matches_finite_differences(material, d):
    for kind in material_states(material):
        F = sample_F(d, kind, seed=1)
        A = first_piola_derivative(material, F, MU, LMBDA)
        assert A.shape == (len(F), d * d, d * d)
        assert relative_error(A, fd_first_piola_derivative(material, F)) < 1e-6, kind
        np.testing.assert_allclose(A, A.transpose(0, 2, 1), atol=1e-12 * np.abs(A).max())


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("material", MATERIALS)
def test_rest_state_is_stress_free(material, d):
    identity = np.eye(d)[None]
    assert abs(psi(material, identity, MU, LMBDA)[0]) < 1e-14
    assert np.abs(first_piola(material, identity, MU, LMBDA)).max() < 1e-14


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("material", ROTATION_INVARIANT)
def test_rotation_invariance(material, d):
    F = sample_F(d, "near_identity", seed=2)
    Q = random_rotation(np.random.default_rng(3), d, len(F))
    np.testing.assert_allclose(psi(material, Q @ F, MU, LMBDA), psi(material, F, MU, LMBDA),
                               rtol=1e-10, atol=1e-14)
    np.testing.assert_allclose(first_piola(material, Q @ F, MU, LMBDA),
                               Q @ first_piola(material, F, MU, LMBDA), atol=1e-12)


@pytest.mark.parametrize("d", DIMS)
def test_linear_elasticity_is_not_rotation_invariant(d):
    """Seed eq. (36): a rigid rotation stores energy in linear elasticity."""
    Q = random_rotation(np.random.default_rng(4), d)
    assert psi("linear", Q, MU, LMBDA)[0] > 1e-3


@pytest.mark.parametrize("d", DIMS)
def test_stvk_reflection_problem_and_corotated_fix(d):
    """Seed 4.4.2: StVK does not see a reflection; corotated (4.4.3) does."""
    reflection = np.diag([1.0] * (d - 1) + [-1.0])[None]
    assert psi("stvk", reflection, MU, LMBDA)[0] == pytest.approx(0.0, abs=1e-15)
    assert psi("corotated", reflection, MU, LMBDA)[0] > 1.0


@pytest.mark.parametrize("d", DIMS)
def test_stable_neohookean_rest_hessian_equals_linear(d):
    identity = np.eye(d)[None]
    np.testing.assert_allclose(first_piola_derivative("stable_neohookean", identity, MU, LMBDA),
                               first_piola_derivative("linear", identity, MU, LMBDA), atol=1e-13)


def test_stable_neohookean_lame_remap():
    """Smith et al. 2018 in 3D; the same derivation gives mu' = 3/2 mu, lmbda' = lmbda + 2/3 mu
    in 2D."""
    mu_, lmbda_, _, _ = stable_neohookean_parameters(MU, LMBDA, 3)
    assert (mu_, lmbda_) == pytest.approx((4 / 3 * MU, LMBDA + 5 / 6 * MU))
    mu_, lmbda_, _, _ = stable_neohookean_parameters(MU, LMBDA, 2)
    assert (mu_, lmbda_) == pytest.approx((3 / 2 * MU, LMBDA + 2 / 3 * MU))


@pytest.mark.parametrize("d", DIMS)
def test_neohookean_inverted_energy_is_infinite(d):
    F = sample_F(d, "inverted")
    assert np.all(psi("neohookean", F, MU, LMBDA) == np.inf)
    assert np.all(np.isfinite(psi("stable_neohookean", F, MU, LMBDA)))


@pytest.mark.parametrize("d", DIMS)
def test_polar_rotation_is_proper(d):
    F = np.concatenate([sample_F(d, "rotated"), sample_F(d, "inverted")])
    R = polar_rotation(F)
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(d), R.shape),
                               atol=1e-13)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-13)
    S = R.transpose(0, 2, 1) @ F
    np.testing.assert_allclose(S, S.transpose(0, 2, 1), atol=1e-13)


def test_lame_parameters():
    mu, lmbda = lame_parameters(1e5, 0.3)
    assert mu == pytest.approx(1e5 / 2.6)
    assert lmbda == pytest.approx(1e5 * 0.3 / (1.3 * 0.4))
    with pytest.raises(ValueError, match="nu must be in"):
        lame_parameters(1e5, 0.5)
    with pytest.raises(ValueError, match="material must be one of"):
        psi("rubber", np.eye(3)[None], MU, LMBDA)


# --- geometry and assembly --------------------------------------------------------------------


def small_mesh(d: int) -> tuple[np.ndarray, np.ndarray]:
    """A 3x2 rectangle (12 triangles) or a 2x2x2 box (48 tetrahedra)."""
    return box_mesh((3, 2)) if d == 2 else box_mesh((2, 2, 2))


def deformed(points: np.ndarray, seed: int = 0) -> np.ndarray:
    """A rotated, stretched and jiggled (but not inverted) configuration."""
    rng = np.random.default_rng(seed)
    d = points.shape[1]
    A = random_rotation(rng, d)[0] @ (np.eye(d) + 0.1 * rng.standard_normal((d, d)))
    return (points @ A.T + 0.03 * rng.standard_normal(points.shape)).ravel()


@pytest.mark.parametrize("d", DIMS)
def test_mesh_volume_and_orientation(d):
    points, cells = small_mesh(d)
    assert cell_volumes(points, cells).sum() == pytest.approx(1.0)
    X = points[cells]
    edges = (X[:, 1:] - X[:, :1]).transpose(0, 2, 1)
    assert np.all(np.linalg.det(edges) > 0)


@pytest.mark.parametrize("d", DIMS)
def test_deformation_gradient(d):
    """``vec(F) = G_e x_e`` agrees with ``D_s D_m^{-1}`` (seed eqs. (26), (34)) and is exact for
    affine maps."""
    points, cells = small_mesh(d)
    x = deformed(points)
    F = deformation_gradient(points, cells, x)
    Dm, Ds = rest_shape_matrix(points, cells), deformed_shape_matrix(x, cells, d)
    np.testing.assert_allclose(F, Ds @ np.linalg.inv(Dm), atol=1e-13)
    A = np.random.default_rng(5).standard_normal((d, d))
    F_affine = deformation_gradient(points, cells, (points @ A.T + 1.0).ravel())
    np.testing.assert_allclose(F_affine, np.broadcast_to(A, F_affine.shape), atol=1e-13)


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("material", MATERIALS)
def test_assembled_derivatives_match_finite_differences(material, d):
    points, cells = small_mesh(d)
    x = deformed(points, seed=6)
    mu = MU * (1.0 + np.arange(len(cells)) / len(cells))  # per-cell parameters
    args = (points, cells, material, mu, LMBDA)
    grad, H = elastic_gradient(*args, x), elastic_hessian(*args, x).toarray()
    h = 1e-6
    grad_fd = np.empty_like(x)
    H_fd = np.empty_like(H)
    for i in range(x.size):
        dx = np.zeros_like(x)
        dx[i] = h
        grad_fd[i] = (elastic_energy(*args, x + dx) - elastic_energy(*args, x - dx)) / (2 * h)
        H_fd[:, i] = (elastic_gradient(*args, x + dx) - elastic_gradient(*args, x - dx)) / (2 * h)
    assert relative_error(grad, grad_fd) < 1e-6
    assert relative_error(H, H_fd) < 1e-6
    np.testing.assert_allclose(H, H.T, atol=1e-12 * np.abs(H).max())


@pytest.mark.parametrize("d", DIMS)
def test_energy_taylor_remainder(d):
    """``|E(x + e p) - E(x) - e g.p - e^2/2 p.Hp|`` falls as ``O(e^3)``."""
    points, cells = small_mesh(d)
    args = (points, cells, "stable_neohookean", MU, LMBDA)
    x = deformed(points, seed=7)
    p = np.random.default_rng(8).standard_normal(x.size)
    E0, gp, pHp = elastic_energy(*args, x), elastic_gradient(*args, x) @ p, p @ (
        elastic_hessian(*args, x) @ p)
    eps = 1e-2 * 0.5 ** np.arange(4)
    first = [abs(elastic_energy(*args, x + e * p) - E0 - e * gp) for e in eps]
    second = [abs(elastic_energy(*args, x + e * p) - E0 - e * gp - e**2 / 2 * pHp) for e in eps]
    assert np.polyfit(np.log(eps), np.log(first), 1)[0] == pytest.approx(2.0, abs=0.1)
    assert np.polyfit(np.log(eps), np.log(second), 1)[0] == pytest.approx(3.0, abs=0.1)


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("material", MATERIALS)
def test_rigid_motion_has_zero_energy(material, d):
    points, cells = small_mesh(d)
    x = (points + 0.5).ravel()
    assert elastic_energy(points, cells, material, MU, LMBDA, x) == pytest.approx(0.0, abs=1e-14)
    assert np.abs(elastic_gradient(points, cells, material, MU, LMBDA, x)).max() < 1e-13
    if material != "linear":
        x = deformed(points)
        Q = random_rotation(np.random.default_rng(9), d)[0]
        x_rot = (x.reshape(-1, d) @ Q.T).ravel()
        assert elastic_energy(points, cells, material, MU, LMBDA, x_rot) == pytest.approx(
            elastic_energy(points, cells, material, MU, LMBDA, x), rel=1e-10)


# --- mass and gravity -------------------------------------------------------------------------


@pytest.mark.parametrize("d", DIMS)
def test_single_element_mass_matches_seed(d):
    """Seed eq. (17): area/6, area/12 on triangles; volume/10, volume/20 on tetrahedra."""
    points = np.vstack([np.zeros(d), 2.0 * np.eye(d)])
    cells = np.arange(d + 1)[None]
    volume = cell_volumes(points, cells)[0]
    M = mass_matrix(points, cells, 3.0).toarray()
    diagonal, off = (1 / 6, 1 / 12) if d == 2 else (1 / 10, 1 / 20)
    P = np.full((d + 1, d + 1), off) + (diagonal - off) * np.eye(d + 1)
    np.testing.assert_allclose(M, 3.0 * volume * np.kron(P, np.eye(d)), atol=1e-14)


@pytest.mark.parametrize("d", DIMS)
def test_consistent_and_lumped_mass_totals(d):
    points, cells = small_mesh(d)
    rho = 1.0 + np.arange(len(cells)) % 3  # per-cell density
    total = np.sum(rho * cell_volumes(points, cells))
    ones_x = np.tile(np.eye(d)[0], len(points))  # unit translation along the first axis
    for lumped in (False, True):
        M = mass_matrix(points, cells, rho, lumped=lumped)
        assert ones_x @ (M @ ones_x) == pytest.approx(total, rel=1e-13)
        np.testing.assert_allclose((M - M.T).toarray(), 0.0, atol=1e-15)
    np.testing.assert_allclose(mass_matrix(points, cells, rho, lumped=True).diagonal(),
                               mass_matrix(points, cells, rho) @ np.ones(points.size), rtol=1e-13)


@pytest.mark.parametrize("d", DIMS)
def test_gravity_energy(d):
    points, cells = small_mesh(d)
    g = -9.81 * np.eye(d)[-1]
    x = deformed(points)
    M = mass_matrix(points, cells, 2.0)
    expected = -(M @ np.tile(g, len(points))) @ x
    assert gravity_energy(points, cells, 2.0, g, x) == pytest.approx(expected, rel=1e-13)
    np.testing.assert_allclose(gravity_gradient(points, cells, 2.0, g),
                               -(M @ np.tile(g, len(points))), rtol=1e-13, atol=1e-15)


# --- integrators ------------------------------------------------------------------------------


@pytest.mark.parametrize("material", ["stable_neohookean", "neohookean", "corotated"])
def test_newmark_free_fall_is_exact(material):
    points, cells = box_mesh((1, 1, 2), (0.5, 0.5, 1.0))
    g, v0, dt, steps = np.array([0.0, 0.0, -9.81]), np.array([1.0, 0.5, 2.0]), 0.01, 10
    v0_dofs = np.tile(v0, len(points))
    trajectory = simulate(points, cells, material, 1e5, 0.3, 1000.0, g, None, "newmark", dt,
                          steps, v0=v0_dofs)
    t = trajectory.t[:, None, None]
    exact = points[None] + v0 * t + 0.5 * g * t**2
    np.testing.assert_allclose(trajectory.x, exact.reshape(steps + 1, -1), atol=1e-12)
    np.testing.assert_allclose(trajectory.v[-1], np.tile(v0 + g * trajectory.t[-1],
                                                         len(points)), atol=1e-10)
    assert trajectory.iterations.max() <= 2


def linear_mode(d: int = 2):
    """Lowest vibration mode of a linear-elastic cantilever (left edge pinned)."""
    points, cells = box_mesh((4, 2), (2.0, 1.0)) if d == 2 else box_mesh((2, 1, 1), (2, 1, 1))
    pinned = np.repeat(points[:, 0] == 0.0, d)
    problem = build_problem(points, cells, "linear", 1e3, 0.3, 1.0, pinned=pinned)
    x_rest = points.ravel()
    free = problem.free
    K = problem.hessian(x_rest).toarray()[np.ix_(free, free)]
    M = problem.mass.toarray()[np.ix_(free, free)]
    omega2, modes = scipy.linalg.eigh(K, M)
    phi = np.zeros(x_rest.size)
    phi[free] = modes[:, 0]  # M-orthonormal
    return problem, x_rest, phi, np.sqrt(omega2[0])


def modal_coordinates(problem, x_rest, phi, state):
    """``(q, dq/dt)`` of the mode ``phi``."""
    M_phi = problem.mass @ phi
    return M_phi @ (state.x - x_rest), M_phi @ state.v


def integrate_mode(integrator: str, steps: int, t_end: float, amplitude: float = 1e-2):
    problem, x_rest, phi, omega = linear_mode()
    state = initial_state(problem, x_rest + amplitude * phi)
    for _ in range(steps):
        state, _ = INTEGRATORS[integrator](problem, state, t_end / steps, atol=1e-14, rtol=1e-12)
    q, dq = modal_coordinates(problem, x_rest, phi, state)
    return q, dq, omega


def test_implicit_euler_amplitude_ratio():
    """Backward Euler multiplies ``omega q + i dq/dt`` by ``1/(1 + i omega h)`` each step."""
    problem, x_rest, phi, omega = linear_mode()
    state = initial_state(problem, x_rest + 1e-2 * phi)
    for h in (0.1 / omega, 1.0 / omega, 3.0 / omega):
        next_state, iterations = INTEGRATORS["implicit_euler"](problem, state, h, rtol=1e-12)
        q0, p0 = modal_coordinates(problem, x_rest, phi, state)
        q1, p1 = modal_coordinates(problem, x_rest, phi, next_state)
        ratio = abs(omega * q1 + 1j * p1) / abs(omega * q0 + 1j * p0)
        assert ratio == pytest.approx(1.0 / np.sqrt(1.0 + (omega * h) ** 2), rel=1e-9)
        assert iterations == 1


def test_newmark_conserves_energy_of_linear_system():
    problem, x_rest, phi, omega = linear_mode(d=3)
    rng = np.random.default_rng(10)
    v0 = np.where(problem.pinned, 0.0, 0.01 * rng.standard_normal(x_rest.size))
    state = initial_state(problem, x_rest + 1e-2 * phi, v0)

    def total_energy(s):
        return 0.5 * s.v @ (problem.mass @ s.v) + problem.energy(s.x)

    E0 = total_energy(state)
    for _ in range(20):
        state, _ = INTEGRATORS["newmark"](problem, state, 0.5 / omega, atol=1e-14, rtol=1e-12)
    assert total_energy(state) == pytest.approx(E0, rel=1e-9)


@pytest.mark.parametrize("integrator, order", [("newmark", 2), ("implicit_euler", 1),
                                               ("bdf2", 2), ("symplectic_euler", 1)])
def test_order_of_accuracy(integrator, order):
    """Fitted convergence order on one vibration mode, exact ``q = A cos(omega t)``."""
    _, _, _, omega = linear_mode()
    t_end, amplitude = 2.0 / omega, 1e-2
    steps = np.array([40, 80, 160])
    errors = []
    for n in steps:
        q, dq, _ = integrate_mode(integrator, n, t_end, amplitude)
        exact_q = amplitude * np.cos(omega * t_end)
        exact_dq = -amplitude * omega * np.sin(omega * t_end)
        errors.append(np.hypot(q - exact_q, (dq - exact_dq) / omega))
    fitted = -np.polyfit(np.log(steps), np.log(errors), 1)[0]
    assert fitted == pytest.approx(order, abs=0.15)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_pinned_dofs_stay_fixed_under_gravity(integrator):
    points, cells = box_mesh((4, 1), (2.0, 0.5))
    pinned = np.repeat(points[:, 0] == 0.0, 2)
    dt = 1e-3 if integrator == "symplectic_euler" else 1e-2
    trajectory = simulate(points, cells, "stable_neohookean", 1e4, 0.3, 100.0, [0.0, -9.81],
                          pinned, integrator, dt, 5)
    assert np.all(trajectory.x[:, pinned] == points.ravel()[pinned])
    np.testing.assert_array_equal(trajectory.v[:, pinned], 0.0)
    assert np.all(trajectory.x[-1, 1::2][points[:, 0] > 0] < points[points[:, 0] > 0, 1])


@pytest.mark.parametrize("material", ROTATION_INVARIANT)
def test_newton_converges_for_large_deformation(material):
    """A very soft cantilever sagging under gravity with large steps: the line search and the
    Hessian shift must keep Newton converging (and neo-Hookean elements uninverted)."""
    points, cells = box_mesh((8, 2), (4.0, 0.5))
    pinned = np.repeat(points[:, 0] == 0.0, 2)
    problem = build_problem(points, cells, material, 3e2, 0.3, 100.0, [0.0, -9.81], pinned)
    state = initial_state(problem, points.ravel())
    for _ in range(2):
        state, iterations = INTEGRATORS["implicit_euler"](problem, state, 0.5)
        assert iterations > 2
    assert np.isfinite(problem.energy(state.x))
    assert np.all(state.x[1::2][~pinned[1::2]] < points[~pinned[1::2], 1])


def test_input_validation():
    points, cells = box_mesh((1, 1))
    with pytest.raises(ValueError, match="integrator must be one of"):
        simulate(points, cells, "linear", 1.0, 0.3, 1.0, None, None, "rk4", 0.1, 1)
    with pytest.raises(ValueError, match="pinned must be a boolean mask"):
        build_problem(points, cells, "linear", 1.0, 0.3, 1.0, pinned=np.zeros(3, bool))
    with pytest.raises(ValueError, match="cells must have shape"):
        build_problem(points, cells[:, :2], "linear", 1.0, 0.3, 1.0)


def test_newton_reports_non_convergence():
    points, cells = box_mesh((4, 1), (2.0, 0.5))
    pinned = np.repeat(points[:, 0] == 0.0, 2)
    problem = build_problem(points, cells, "neohookean", 3e2, 0.3, 100.0, [0.0, -9.81], pinned)
    state = initial_state(problem, points.ravel())
    with pytest.raises(ConvergenceError, match="did not converge in 1 iterations"):
        INTEGRATORS["implicit_euler"](problem, state, 0.5, max_iterations=1)
