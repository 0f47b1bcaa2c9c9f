"""Eigenvalue filtering of the material tangent and the trust-region choice (fem_anim.solver.hessian_modification).

Numpy only: constructed per-point tangents with known eigensystems, filtered per point, and
the clamp/abs choice of the trust-region filter on a constructed sequence of ratios.
"""

from __future__ import annotations

import numpy as np
import pytest

from fem_anim.solver.hessian_modification import (RHO_TOLERANCE, abs_psd, filter_tangent, model_ratio,
                              positive_definite, project_psd, trust_region_choice)


def _tangents(eigenvalues: np.ndarray, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Symmetric (n, m, m) matrices Q diag(eigenvalues) Q^T with random orthogonal Q."""
    rng = np.random.default_rng(seed)
    n, m = eigenvalues.shape
    q, _ = np.linalg.qr(rng.standard_normal((n, m, m)))
    return np.einsum("nij,nj,nkj->nik", q, eigenvalues, q), q


def _known_spectrum(n: int = 50, m: int = 9, seed: int = 1) -> np.ndarray:
    """Distinct eigenvalues, the first three of each point negative (a 3D d^2 psi/dF^2)."""
    rng = np.random.default_rng(seed)
    lam = np.sort(rng.uniform(0.5, 5.0, (n, m)) * rng.choice([1.0, 1.3], (n, m)), axis=1)
    lam[:, :3] *= -1.0
    return lam + np.arange(m) * 1e-2  # keep them distinct


@pytest.mark.parametrize("how, f", [("abs", np.abs), ("clamp", lambda x: np.maximum(x, 0.0))])
def test_filter_replaces_the_negative_eigenvalues_and_keeps_the_eigenvectors(how, f):
    lam = _known_spectrum()
    tangent, q = _tangents(lam)
    filtered = filter_tangent(tangent, how)
    # the numpy reference: the same eigenvectors, f of the eigenvalues
    reference = np.einsum("nij,nj,nkj->nik", q, f(lam), q)
    np.testing.assert_allclose(filtered, reference, rtol=0, atol=1e-12 * np.abs(lam).max())
    np.testing.assert_array_equal(filtered, np.swapaxes(filtered, 1, 2))
    got = np.linalg.eigvalsh(filtered)
    np.testing.assert_allclose(np.sort(got, axis=1), np.sort(f(lam), axis=1), atol=1e-12 * 5)
    # eigenvectors kept: Q^T A Q is diagonal with f(lambda) on it
    rotated = np.einsum("nji,njk,nkl->nil", q, filtered, q)
    np.testing.assert_allclose(rotated, np.einsum("nj,jk->njk", f(lam), np.eye(lam.shape[1])),
                               atol=1e-12 * 5)


def test_abs_of_a_two_by_two_by_hand():
    """[[0, 2], [2, 0]] has eigenvalues -2, 2: abs gives 2 I, clamp gives [[1, 1], [1, 1]]."""
    a = np.array([[[0.0, 2.0], [2.0, 0.0]]])
    np.testing.assert_allclose(abs_psd(a)[0], 2.0 * np.eye(2), atol=1e-15)
    np.testing.assert_allclose(project_psd(a)[0], np.ones((2, 2)), atol=1e-15)


@pytest.mark.parametrize("how", ["abs", "clamp"])
def test_positive_definite_tangents_pass_unchanged(how):
    rng = np.random.default_rng(3)
    lam = rng.uniform(0.1, 10.0, (40, 9))
    tangent, _ = _tangents(lam, seed=4)
    tangent = 0.5 * (tangent + np.swapaxes(tangent, 1, 2))
    np.testing.assert_array_equal(filter_tangent(tangent, how), tangent)
    # a mix: only the indefinite points change
    mixed = tangent.copy()
    mixed[::3] *= -1.0
    out = filter_tangent(mixed, how)
    keep = np.ones(len(mixed), bool)
    keep[::3] = False
    np.testing.assert_array_equal(out[keep], mixed[keep])
    assert np.all(np.linalg.eigvalsh(out[~keep]) >= -1e-12 * np.abs(lam).max())


def test_model_ratio_of_an_exact_quadratic_is_one():
    """g(x) = 1/2 x^T H x - b^T x, H indefinite: the model along any step is exact."""
    rng = np.random.default_rng(5)
    H = np.diag([3.0, 1.0, -0.5])
    b = rng.standard_normal(3)
    x = rng.standard_normal(3)
    g = lambda z: 0.5 * z @ H @ z - b @ z  # noqa: E731
    r = H @ x - b
    y = np.array([1.0, -2.0, 0.5])
    alpha = 0.3
    rho = model_ratio(g(x) - g(x - alpha * y), r @ y, y @ H @ y, alpha)
    assert rho == pytest.approx(1.0, abs=1e-12)


def test_trust_region_choice_follows_rho():
    rhos = [None, 0.5, 0.995, 1.0, 1.009, 1.011, -2.0, float("nan"), 0.99 + 1e-4]
    expected = ["abs", "abs", "clamp", "clamp", "clamp", "abs", "abs", "abs", "clamp"]
    assert [trust_region_choice(r) for r in rhos] == expected
    assert RHO_TOLERANCE == 0.01


def test_positive_definite_agrees_with_the_eigenvalues():
    rng = np.random.default_rng(7)
    lam = rng.uniform(-1.0, 4.0, (200, 9))
    tangent, _ = _tangents(lam, seed=8)
    np.testing.assert_array_equal(positive_definite(tangent), lam.min(axis=1) > 0)
