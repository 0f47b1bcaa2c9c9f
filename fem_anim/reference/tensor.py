"""Stacked small-matrix algebra for the reference implementation.

Every function acts on a stack of ``n`` square ``d x d`` matrices, shape ``(n, d, d)``, with
``d`` = 2 or 3, and never loops over the stack.

Conventions (seed section 4.3):

* ``vec`` stacks the columns of a matrix (column-major, seed eq. (30)), so entry ``F[k, a]``
  sits at ``vec(F)[a * d + k]``.
* A fourth-order tensor ``T[n, k, a, l, b] = dP_ka / dF_lb`` becomes the matrix
  ``d vec(P) / d vec(F)`` of shape ``(n, d*d, d*d)`` with :func:`tensor_to_matrix`.
"""

from __future__ import annotations

import itertools

import numpy as np

__all__ = [
    "cofactor",
    "cofactor_derivative",
    "identity_tensor",
    "levi_civita",
    "polar_rotation",
    "polar_rotation_derivative",
    "signed_svd",
    "tensor_to_matrix",
    "unvec",
    "vec",
]


def vec(A: np.ndarray) -> np.ndarray:
    """Column-major vectorisation ``vec(A)`` of a stack (seed eq. (30)).

    Args:
        A: Matrices, shape ``(n, d, d)``.

    Returns:
        ``(n, d*d)`` array with ``vec(A)[:, a*d + k] = A[:, k, a]``.
    """
    n, d, _ = A.shape
    return A.transpose(0, 2, 1).reshape(n, d * d)


def unvec(v: np.ndarray, d: int) -> np.ndarray:
    """Inverse of :func:`vec`: column-major vectors to matrices.

    Args:
        v: ``(n, d*d)`` column-major vectors.
        d: The matrix size.

    Returns:
        ``(n, d, d)`` matrices.
    """
    return v.reshape(-1, d, d).transpose(0, 2, 1)


def tensor_to_matrix(T: np.ndarray) -> np.ndarray:
    """Turn ``T[n, k, a, l, b] = dP_ka/dF_lb`` into ``d vec(P) / d vec(F)``.

    Args:
        T: Fourth-order tensors, shape ``(n, d, d, d, d)``.

    Returns:
        ``(n, d*d, d*d)`` matrices ``A`` with ``A[:, a*d + k, b*d + l] = T[:, k, a, l, b]``.
    """
    n, d = T.shape[:2]
    return T.transpose(0, 2, 1, 4, 3).reshape(n, d * d, d * d)


def identity_tensor(d: int) -> np.ndarray:
    """The fourth-order identity ``I[k, a, l, b] = delta_kl delta_ab`` (``dF/dF``).

    Args:
        d: The dimension.
    """
    delta = np.eye(d)
    return np.einsum("kl,ab->kalb", delta, delta)


def levi_civita(d: int) -> np.ndarray:
    """The permutation symbol ``epsilon`` with ``d`` indices.

    Args:
        d: 2 or 3.
    """
    eps = np.zeros((d,) * d)
    for perm in itertools.permutations(range(d)):
        # sign of a permutation = parity of its inversions
        inversions = sum(p > q for i, p in enumerate(perm) for q in perm[i + 1:])
        eps[perm] = -1.0 if inversions % 2 else 1.0
    return eps


def cofactor(F: np.ndarray) -> np.ndarray:
    """Cofactor matrix ``cof F = dJ/dF`` (equal to ``J F^{-T}`` where ``F`` is invertible).

    Computed from the permutation symbol, so it is polynomial in ``F`` and defined for
    singular and inverted ``F``: ``cof(F)_ia = eps_ij eps_ab F_jb`` in 2D and
    ``cof(F)_ia = 1/2 eps_ijk eps_abc F_jb F_kc`` in 3D.

    Args:
        F: Matrices, shape ``(n, d, d)``.

    Returns:
        Cofactor matrices, shape ``(n, d, d)``.
    """
    d = F.shape[-1]
    eps = levi_civita(d)
    if d == 2:
        return np.einsum("ij,ab,njb->nia", eps, eps, F)
    return 0.5 * np.einsum("ijk,abc,njb,nkc->nia", eps, eps, F, F, optimize=True)


def cofactor_derivative(F: np.ndarray) -> np.ndarray:
    """Second derivative of ``J = det F``: ``d cof(F)_ia / dF_jb``.

    It is ``eps_ij eps_ab`` (constant) in 2D and ``eps_ijk eps_abc F_kc`` in 3D.

    Args:
        F: Matrices, shape ``(n, d, d)``.

    Returns:
        Tensors ``T[n, i, a, j, b]``, shape ``(n, d, d, d, d)``.
    """
    n, d, _ = F.shape
    eps = levi_civita(d)
    if d == 2:
        return np.broadcast_to(np.einsum("ij,ab->iajb", eps, eps), (n, d, d, d, d)).copy()
    return np.einsum("ijk,abc,nkc->niajb", eps, eps, F, optimize=True)


def signed_svd(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotation-variant SVD ``F = U diag(sigma) V^T`` with ``U, V`` in SO(d).

    Where ``det F < 0`` the smallest singular value (the last one, numpy sorts them in
    decreasing order) is negated together with the matching column of ``U`` or ``V``
    (seed section 4.4.3; Irving, Teran and Fedkiw 2004).

    Args:
        F: Matrices, shape ``(n, d, d)``.

    Returns:
        ``(U, sigma, V)`` of shapes ``(n, d, d)``, ``(n, d)``, ``(n, d, d)``.
    """
    U, sigma, Vt = np.linalg.svd(F)
    V = Vt.transpose(0, 2, 1).copy()
    sigma = sigma.copy()
    for Q in (U, V):
        flip = np.linalg.det(Q) < 0.0
        Q[flip, :, -1] *= -1.0
        sigma[flip, -1] *= -1.0
    return U, sigma, V


def polar_rotation(F: np.ndarray) -> np.ndarray:
    """Rotation ``R = U V^T`` of the polar decomposition ``F = R S`` with ``det R = +1``.

    Args:
        F: ``(n, d, d)`` deformation gradients.

    Returns:
        ``(n, d, d)`` rotations.
    """
    U, _, V = signed_svd(F)
    return U @ V.transpose(0, 2, 1)


def polar_rotation_derivative(F: np.ndarray) -> np.ndarray:
    """Exact derivative ``dR/dF`` of the polar rotation.

    Differentiating ``F = U Sigma V^T`` gives ``dR = U Omega V^T`` with ``Omega`` skew and
    ``Omega_ij = (M_ij - M_ji) / (sigma_i + sigma_j)``, ``M = U^T dF V``. With the twist
    matrices ``Q_ij = U (e_i e_j^T - e_j e_i^T) V^T`` (``i < j``) this is the rank-``d(d-1)/2``
    form of Kim and Eberle, "Dynamic Deformables" (2022), section 5.5:

        dR_ka / dF_lb = sum_{i<j} Q_ij[k, a] Q_ij[l, b] / (sigma_i + sigma_j).

    Undefined (division by zero) where ``sigma_i + sigma_j = 0`` for some pair.

    Args:
        F: Matrices, shape ``(n, d, d)``.

    Returns:
        Tensors ``T[n, k, a, l, b] = dR_ka / dF_lb``, shape ``(n, d, d, d, d)``.
    """
    n, d, _ = F.shape
    U, sigma, V = signed_svd(F)
    dR = np.zeros((n, d, d, d, d))
    for i, j in itertools.combinations(range(d), 2):
        Q = (np.einsum("nk,na->nka", U[:, :, i], V[:, :, j])
             - np.einsum("nk,na->nka", U[:, :, j], V[:, :, i]))
        scale = 1.0 / (sigma[:, i] + sigma[:, j])
        dR += np.einsum("n,nka,nlb->nkalb", scale, Q, Q)
    return dR
