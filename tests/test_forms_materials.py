"""Tests of the UFL material library (forms/, seed §4.4).

Each energy density is compiled with FFCx into a ``dolfinx.fem.Expression`` that returns
``psi``, ``P = dpsi/dF`` and ``A = dP/dF`` at one point of a one-cell mesh, with ``F`` (and the
corotated extra data) held in ``dolfinx.fem.Constant`` so that one compilation per material and
dimension serves every state. The results are checked against closed forms, an independent
numpy SVD evaluation of corotated elasticity and central finite differences.
"""

from __future__ import annotations

import dolfinx.fem
import dolfinx.mesh
import numpy as np
import pytest
import ufl
from mpi4py import MPI

from fem_anim import compat
from fem_anim.forms import corotated, kinematics, lame, material, stable_neohookean

MU, LMBDA = 1.3, 2.7
NAMES = list(material.MATERIALS)
DIMS = [2, 3]
H = 1e-6  # finite-difference step


# --- helpers -------------------------------------------------------------------------------------


def one_cell_mesh(d: int) -> dolfinx.mesh.Mesh:
    cell = {2: "triangle", 3: "tetrahedron"}[d]
    x = np.vstack([np.zeros(d), np.eye(d)])
    cells = np.arange(d + 1, dtype=np.int64).reshape(1, -1)
    return compat.create_mesh(MPI.COMM_SELF, cells, x, d, cell)


def eval_at_point(expr: ufl.core.expr.Expr, mesh: dolfinx.mesh.Mesh) -> np.ndarray:
    d = mesh.topology.dim
    X = np.full((1, d), 1.0 / (d + 1))
    return at_cell_zero(compat.expression(expr, X), mesh)


def at_cell_zero(expression, mesh) -> np.ndarray:
    """A compiled expression's values on cell 0 of a one-cell mesh."""
    return compat.evaluate(expression, mesh, np.array([0], dtype=np.int32))[0]


def flat(T: ufl.core.expr.Expr) -> list[ufl.core.expr.Expr]:
    return [T[idx] for idx in np.ndindex(T.ufl_shape)]


class Evaluator:
    """``F -> (psi, P, A)`` for one material in ``d`` dimensions, compiled once."""

    def __init__(self, name: str, d: int):
        self.mat, self.d = material.MATERIALS[name], d
        mesh = one_cell_mesh(d)
        self.F = dolfinx.fem.Constant(mesh, np.eye(d))
        self.extra = {
            key: dolfinx.fem.Constant(mesh, np.zeros(material.EXTRA_DATA[key].value_shape(d)))
            for key in self.mat.needs(d)
        }
        mu, lmbda = dolfinx.fem.Constant(mesh, MU), dolfinx.fem.Constant(mesh, LMBDA)
        Fv = ufl.variable(self.F)
        kwargs = {material.EXTRA_DATA[k].keyword: c for k, c in self.extra.items()}
        psi = self.mat.psi(Fv, mu, lmbda, **kwargs)
        P = ufl.diff(psi, Fv)
        A = ufl.diff(P, Fv)
        X = np.full((1, d), 1.0 / (d + 1))
        self.mesh = mesh
        self.expr = compat.expression(ufl.as_vector([psi] + flat(P) + flat(A)), X)

    def __call__(self, F: np.ndarray, **fixed: np.ndarray):
        """Evaluate at ``F``; extra data is recomputed from ``F`` unless given in ``fixed``."""
        self.F.value = F
        for key, const in self.extra.items():
            value = fixed.get(key)
            const.value = material.EXTRA_DATA[key].evaluate(F[None])[0] if value is None else value
        v = at_cell_zero(self.expr, self.mesh)
        d = self.d
        return v[0], v[1 : 1 + d**2].reshape(d, d), v[1 + d**2 :].reshape(d, d, d, d)


_evaluators: dict[tuple[str, int], Evaluator] = {}


def evaluator(name: str, d: int) -> Evaluator:
    if (name, d) not in _evaluators:
        _evaluators[name, d] = Evaluator(name, d)
    return _evaluators[name, d]


def random_rotation(rng: np.random.Generator, d: int) -> np.ndarray:
    Q, R = np.linalg.qr(rng.standard_normal((d, d)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] *= -1
    return Q


def random_F(rng: np.random.Generator, d: int) -> np.ndarray:
    while True:
        F = np.eye(d) + 0.3 * rng.standard_normal((d, d))
        if np.linalg.det(F) > 0.3:
            return F


def fd_gradient(fun, F: np.ndarray, h: float = H) -> np.ndarray:
    """Central differences of ``fun`` (scalar- or tensor-valued) with respect to ``F``."""
    d = F.shape[0]
    out = None
    for k, l in np.ndindex(d, d):  # noqa: E741 (the index names of the maths)
        E = np.zeros((d, d))
        E[k, l] = h
        g = (np.asarray(fun(F + E)) - np.asarray(fun(F - E))) / (2 * h)
        if out is None:
            out = np.zeros(g.shape + (d, d))
        out[..., k, l] = g
    return out


def linear_rest_hessian(d: int) -> np.ndarray:
    """``mu (δik δjl + δil δjk) + lmbda δij δkl``, the Hessian of linear elasticity."""
    I = np.eye(d)  # noqa: E741 (the identity, as in the maths)
    return (
        MU * (np.einsum("ik,jl->ijkl", I, I) + np.einsum("il,jk->ijkl", I, I))
        + LMBDA * np.einsum("ij,kl->ijkl", I, I)
    )


def corotated_reference(F: np.ndarray) -> tuple[float, np.ndarray]:
    """Independent SVD evaluation of corotated psi and P = 2 mu (F - R) + lmbda (J - 1) cof F."""
    U, sigma, Vt = np.linalg.svd(F)
    if np.linalg.det(U @ Vt) < 0:
        U[:, -1] *= -1
    R = U @ Vt
    J = np.linalg.det(F)
    psi = MU * np.sum((F - R) ** 2) + LMBDA / 2 * (J - 1) ** 2
    return psi, 2 * MU * (F - R) + LMBDA * (J - 1) * cofactor(F)


def cofactor(F: np.ndarray) -> np.ndarray:
    """``dJ/dF = J F^{-T}``, written without the inverse so that singular F are fine."""
    if F.shape == (2, 2):
        return np.array([[F[1, 1], -F[1, 0]], [-F[0, 1], F[0, 0]]])
    return np.column_stack([np.cross(F[:, 1], F[:, 2]), np.cross(F[:, 2], F[:, 0]),
                            np.cross(F[:, 0], F[:, 1])])


def rel_err(a: np.ndarray, b: np.ndarray) -> float:
    return np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300)


# --- registry, Lamé parameters, kinematics ------------------------------------------------------


def test_registry_shape():
    assert set(material.MATERIALS) == {
        "linear", "stvk", "corotated", "neohookean", "stable_neohookean", "corotated_lagged"
    }
    positive = {n for n, m in material.MATERIALS.items() if m.requires_positive_J}
    assert positive == {"neohookean"}
    assert material.MATERIALS["corotated"].needs(3) == ("stretch_trace",)
    assert material.MATERIALS["corotated"].needs(2) == ()
    assert material.MATERIALS["corotated_lagged"].needs(2) == ("rotation",)
    assert not material.MATERIALS["corotated_lagged"].exact_hessian
    with pytest.raises(ValueError, match="material.model must be one of"):
        material.get_material("rubber")


def test_lame_parameters():
    mu, lmbda = lame.lame_parameters(1e5, 0.3)
    assert mu == pytest.approx(1e5 / 2.6)
    assert lmbda + 2 / 3 * mu == pytest.approx(1e5 / (3 * (1 - 0.6)))  # bulk modulus
    mesh = one_cell_mesh(2)
    E, nu = dolfinx.fem.Constant(mesh, 1e5), dolfinx.fem.Constant(mesh, 0.3)
    values = eval_at_point(ufl.as_vector(lame.lame_parameters(E, nu)), mesh)
    np.testing.assert_allclose(values, [mu, lmbda], rtol=1e-14)


def test_stable_neohookean_remap():
    remap = stable_neohookean.remap_lame
    assert remap(MU, LMBDA, 3) == pytest.approx((4 / 3 * MU, LMBDA + 5 / 6 * MU))
    assert remap(MU, LMBDA, 2) == pytest.approx((3 / 2 * MU, LMBDA + 2 / 3 * MU))


def test_deformation_gradient():
    mesh = one_cell_mesh(3)
    V = compat.vector_space(mesh, 1)
    G = np.array([[0.1, 0.2, 0.0], [0.0, -0.3, 0.4], [0.5, 0.0, 0.2]])
    u = dolfinx.fem.Function(V)
    u.interpolate(lambda x: G @ x)
    F = kinematics.deformation_gradient(u)
    values = eval_at_point(ufl.as_vector(flat(F) + flat(kinematics.green_strain(F))), mesh)
    Fn = np.eye(3) + G
    np.testing.assert_allclose(values[:9].reshape(3, 3), Fn, atol=1e-14)
    np.testing.assert_allclose(values[9:].reshape(3, 3), (Fn.T @ Fn - np.eye(3)) / 2, atol=1e-14)


# --- every material, 2D and 3D --------------------------------------------------------------------


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("name", NAMES)
def test_rest_state(name, d):
    """psi(I) = 0 and P(I) = 0 exactly; the rest Hessian is linear elasticity's (§4.4.1)."""
    psi, P, A = evaluator(name, d)(np.eye(d))
    assert np.all(np.isfinite(A))
    assert abs(psi) < 1e-14 * (MU + LMBDA)
    np.testing.assert_allclose(P, 0, atol=1e-14 * (MU + LMBDA))
    if material.MATERIALS[name].exact_hessian:
        np.testing.assert_allclose(A, linear_rest_hessian(d), atol=1e-13 * (MU + LMBDA))
    else:  # lagged R = I: mu |H|^2 + ..., the rotational part of the stiffness is missing
        assert not np.allclose(A, linear_rest_hessian(d))


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("name", NAMES)
def test_rotation_invariance(name, d):
    """psi(QF) = psi(F), P(QF) = Q P(F) for all models but linear (seed eqs. 36-37)."""
    rng = np.random.default_rng(1)
    ev = evaluator(name, d)
    for _ in range(3):
        F, Q = random_F(rng, d), random_rotation(rng, d)
        psi, P, _ = ev(F)
        psi_q, P_q, _ = ev(Q @ F)
        if name == "linear":
            assert abs(psi_q - psi) > 1e-3 * abs(psi)
        else:
            assert psi_q == pytest.approx(psi, rel=1e-12)
            np.testing.assert_allclose(P_q, Q @ P, atol=1e-12 * np.abs(P).max())


REFLECTION = {  # psi(diag(1, .., 1, -1)); psi(I) = 0 for all (seed §4.4.2)
    "linear": lambda d: 4 * MU + 2 * LMBDA,
    "stvk": lambda d: 0.0,  # the reflection problem
    "neohookean": lambda d: np.nan,  # ln J of J = -1 in the compiled kernel
    # 2 lmbda' alpha = 2 lmbda' + 2 d/(d+1) mu' = 2 lmbda + 10/3 mu (2D), 2 lmbda + 11/3 mu (3D)
    "stable_neohookean": lambda d: 2 * LMBDA + (10 / 3 if d == 2 else 11 / 3) * MU,
    # exact value 4 mu + 2 lmbda; F is on the kink (R not unique): in 3D f'(s0) = f(s0) = 0
    "corotated": lambda d: 4 * MU + 2 * LMBDA if d == 2 else np.nan,
    "corotated_lagged": lambda d: 4 * MU + 2 * LMBDA,
}


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("name", NAMES)
def test_reflection_example(name, d):
    F2 = np.diag([1.0] * (d - 1) + [-1.0])
    psi = evaluator(name, d)(F2)[0]
    expected = REFLECTION[name](d)
    if np.isnan(expected):
        assert np.isnan(psi)
    else:
        assert psi == pytest.approx(expected, rel=1e-13, abs=1e-13)
    if name.startswith("corotated"):
        assert corotated_reference(F2)[0] == pytest.approx(4 * MU + 2 * LMBDA)


@pytest.mark.parametrize("d", DIMS)
@pytest.mark.parametrize("name", NAMES)
def test_derivatives_against_finite_differences(name, d):
    """UFL P and A against central differences of psi and P at random and rotated states."""
    rng = np.random.default_rng(2)
    ev = evaluator(name, d)
    F0 = random_F(rng, d)
    for F in (F0, random_rotation(rng, d) @ F0, random_F(rng, d)):
        # the lagged model is differentiated at fixed R; corotated recomputes s0 at each F
        fixed = {"rotation": corotated.polar_rotation(F[None])[0]} if "rotation" in ev.extra else {}
        psi, P, A = ev(F, **fixed)
        assert rel_err(P, fd_gradient(lambda G: ev(G, **fixed)[0], F)) < 1e-6
        assert rel_err(A, fd_gradient(lambda G: ev(G, **fixed)[1], F)) < 1e-6


# --- corotated --------------------------------------------------------------------------------


def corotated_states(d: int) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    Q1, Q2 = random_rotation(rng, d), random_rotation(rng, d)
    if d == 2:
        diag = [[2.0, 2.0], [2.0, 0.5], [2.0, -0.5]]
    else:
        diag = [[2.0, 2.0, 1.5], [2.0, 1.5, 1.5], [1.2, 0.8, -0.3], [2.0, 1.0, 0.0]]
    return [
        random_F(rng, d),
        random_F(rng, d),
        1.3 * Q1,
        np.eye(d) + 0.3 * rng.standard_normal((d, d)),  # any sign of J
        *[Q1 @ np.diag(s) @ Q2 for s in diag],
    ]


@pytest.mark.parametrize("d", DIMS)
def test_corotated_against_svd(d):
    """Value, P and Hessian against an SVD evaluation, including repeated singular values."""
    ev = evaluator("corotated", d)
    for F in corotated_states(d):
        psi, P, A = ev(F)
        psi_ref, P_ref = corotated_reference(F)
        assert psi == pytest.approx(psi_ref, rel=1e-12)
        assert rel_err(P, P_ref) < 1e-12
        assert rel_err(A, fd_gradient(lambda G: corotated_reference(G)[1], F)) < 1e-6
        assert rel_err(A, fd_gradient(lambda G: ev(G)[1], F)) < 1e-6


def test_quartic_roots():
    """The roots of f are ±σ1±σ2±σ3 with an even number of minus signs; s is the largest."""
    rng = np.random.default_rng(4)
    for _ in range(5):
        F = rng.standard_normal((3, 3))
        sigma = np.linalg.svd(F, compute_uv=False) * [1, 1, np.sign(np.linalg.det(F))]
        C = F.T @ F
        I_C, II_C, J = np.trace(C), (np.trace(C) ** 2 - np.trace(C @ C)) / 2, np.linalg.det(F)
        roots = np.sort(np.roots([1, 0, -2 * I_C, -8 * J, I_C**2 - 4 * II_C]).real)
        signs = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]])
        np.testing.assert_allclose(roots, np.sort(signs @ sigma), atol=1e-10)
        assert corotated.stretch_trace(F[None])[0] == pytest.approx(roots[-1], rel=1e-10)


def test_chebyshev_correction_is_second_order_exact():
    """s~ has the exact value, gradient (= R) and Hessian of s; Newton alone gets A wrong."""
    mesh = one_cell_mesh(3)
    Fc, s0 = dolfinx.fem.Constant(mesh, np.eye(3)), dolfinx.fem.Constant(mesh, 0.0)
    Fv = ufl.variable(Fc)
    s = corotated.stretch_trace_expr(Fv, s0)
    f, df, _ = corotated.stretch_quartic(s0, Fv)
    ds = ufl.diff(s, Fv)
    d2s_newton = ufl.diff(ufl.diff(s0 - f / df, Fv), Fv)
    comps = [s] + flat(ds) + flat(ufl.diff(ds, Fv)) + flat(d2s_newton)
    expr = compat.expression(ufl.as_vector(comps), np.full((1, 3), 0.25))

    def stretch(F):
        return corotated.stretch_trace(F[None])[0]

    for F in corotated_states(3):
        Fc.value, s0.value = F, stretch(F)
        v = at_cell_zero(expr, mesh)
        hess_fd = fd_gradient(lambda G: corotated.polar_rotation(G[None])[0], F)
        assert v[0] == pytest.approx(stretch(F), rel=1e-14)
        np.testing.assert_allclose(v[1:10].reshape(3, 3), corotated.polar_rotation(F[None])[0],
                                   atol=1e-12)
        assert rel_err(v[10:91].reshape(3, 3, 3, 3), hess_fd) < 1e-6
        assert rel_err(v[91:].reshape(3, 3, 3, 3), hess_fd) > 1e-3


@pytest.mark.parametrize("d", DIMS)
def test_lagged_rotation_is_quasi_newton(d):
    """At R = polar_rotation(F) the lagged model has the exact psi and P but not the Hessian."""
    rng = np.random.default_rng(5)
    F = random_F(rng, d)
    psi, P, A = evaluator("corotated", d)(F)
    psi_l, P_l, A_l = evaluator("corotated_lagged", d)(F)
    assert psi_l == pytest.approx(psi, rel=1e-12)
    np.testing.assert_allclose(P_l, P, atol=1e-12 * np.abs(P).max())
    assert rel_err(A_l, A) > 1e-2
