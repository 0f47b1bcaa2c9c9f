"""Hyperelastic energy densities ``psi(F)``, stresses ``P = dpsi/dF`` and ``dP/dF``.

Seed section 4.4. Each model acts on a stack of deformation gradients ``F`` of shape
``(n, d, d)`` (``d`` = 2 is plane strain, ``d`` = 3 solid) and returns

* ``psi``: ``(n,)`` energy per unit reference volume,
* ``P``: ``(n, d, d)`` first Piola-Kirchhoff stress,
* ``dP/dF``: ``(n, d*d, d*d)`` in the column-major ``vec`` convention of seed eq. (30), i.e.
  the Hessian ``d^2 psi / d vec(F)^2`` used in the element Hessian ``w G^T (dP/dF) G``.

The Lame parameters ``mu``, ``lmbda`` are scalars or per-matrix arrays of shape ``(n,)``.
Notation: ``I_C = tr(F^T F)``, ``J = det F``, ``cof F = dJ/dF``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from fem_anim.reference.tensor import (
    cofactor,
    cofactor_derivative,
    identity_tensor,
    polar_rotation,
    polar_rotation_derivative,
    tensor_to_matrix,
)

__all__ = [
    "MATERIALS",
    "first_piola",
    "first_piola_derivative",
    "lame_parameters",
    "psi",
    "stable_neohookean_parameters",
]

Array = np.ndarray


def lame_parameters(E, nu) -> tuple:
    """Lame parameters from Young's modulus and Poisson's ratio (scalars or per-cell arrays).

    ``mu = E / (2 (1 + nu))``, ``lmbda = E nu / ((1 + nu)(1 - 2 nu))``; plane strain (``d`` = 2)
    uses the same values with a 2x2 ``F``.

    Args:
        E: Young's modulus (Pa).
        nu: Poisson's ratio.

    Returns:
        ``(mu, lmbda)`` (Pa).

    Raises:
        ValueError: If ``E <= 0`` or ``nu`` is outside ``(-1, 0.5)``.
    """
    if not np.all(np.asarray(E) > 0.0):
        raise ValueError(f"E must be positive, got {E}")
    if not np.all((-1.0 < np.asarray(nu)) & (np.asarray(nu) < 0.5)):
        raise ValueError(f"nu must be in (-1, 0.5), got {nu}")
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


def stable_neohookean_parameters(mu, lmbda, d: int) -> tuple:
    """Remapped parameters ``(mu', lmbda', alpha, c0)`` of the stable neo-Hookean model.

    Chosen so that the energy of :func:`psi` with ``material="stable_neohookean"`` has
    ``psi(I) = 0``, ``P(I) = 0`` and the rest Hessian of linear elasticity with ``(mu, lmbda)``
    (Smith, de Goes and Kim 2018, section 3.4). Matching
    ``dP/dF(I) = mu' d/(d+1) 1 + mu' d/(d+1) 1^T + (lmbda' + 2 mu'/(d+1)^2 - mu' d/(d+1)) I x I``
    with linear elasticity ``mu 1 + mu 1^T + lmbda I x I`` gives

        mu' = (d+1)/d mu,   lmbda' = lmbda + mu - 2 mu / (d (d+1)),

    i.e. ``mu' = 4/3 mu``, ``lmbda' = lmbda + 5/6 mu`` in 3D and ``mu' = 3/2 mu``,
    ``lmbda' = lmbda + 2/3 mu`` in 2D; ``alpha = 1 + d/(d+1) mu'/lmbda'`` makes ``P(I) = 0`` and
    ``c0 = lmbda'/2 (1 - alpha)^2 - mu'/2 ln(d+1)`` makes ``psi(I) = 0``.

    Args:
        mu: The shear modulus (Pa).
        lmbda: The first Lame parameter (Pa).
        d: The dimension (2 or 3).

    Returns:
        ``(mu', lmbda', alpha, c0)``.
    """
    mu_ = (d + 1) / d * mu
    lmbda_ = lmbda + mu - 2.0 * mu / (d * (d + 1))
    alpha = 1.0 + d / (d + 1) * mu_ / lmbda_
    c0 = 0.5 * lmbda_ * (1.0 - alpha) ** 2 - 0.5 * mu_ * np.log(d + 1.0)
    return mu_, lmbda_, alpha, c0


def _per_matrix(value, ndim: int) -> Array:
    """Broadcast a scalar or ``(n,)`` parameter against arrays with ``ndim`` trailing axes."""
    return np.asarray(value, dtype=float).reshape((-1,) + (1,) * ndim)


def _delta_tensors(d: int) -> tuple[Array, Array, Array]:
    """``delta_kl delta_ab``, ``delta_kb delta_la``, ``delta_ka delta_lb`` as ``[k, a, l, b]``."""
    delta = np.eye(d)
    transpose = np.einsum("kb,la->kalb", delta, delta)
    return identity_tensor(d), transpose, np.einsum("ka,lb->kalb", delta, delta)


# --- linear elasticity (seed 4.4.1, small-strain form) ----------------------------------------
# eps = sym(F) - I,  psi = mu eps:eps + lmbda/2 tr(eps)^2,  P = 2 mu eps + lmbda tr(eps) I


def _small_strain(F: Array) -> tuple[Array, Array]:
    """``eps = sym(F) - I`` and ``tr(eps)``."""
    eps = 0.5 * (F + F.transpose(0, 2, 1)) - np.eye(F.shape[-1])
    return eps, np.trace(eps, axis1=1, axis2=2)


def _linear_psi(F: Array, mu, lmbda) -> Array:
    eps, tr = _small_strain(F)
    mu, lmbda = _per_matrix(mu, 0), _per_matrix(lmbda, 0)
    return mu * np.sum(eps * eps, axis=(1, 2)) + 0.5 * lmbda * tr**2


def _linear_P(F: Array, mu, lmbda) -> Array:
    eps, tr = _small_strain(F)
    mu, lmbda = _per_matrix(mu, 2), _per_matrix(lmbda, 2)
    return 2.0 * mu * eps + lmbda * tr[:, None, None] * np.eye(F.shape[-1])


def _linear_dP(F: Array, mu, lmbda) -> Array:
    n, d, _ = F.shape
    I4, I4t, IxI = _delta_tensors(d)
    T = _per_matrix(mu, 4) * (I4 + I4t) + _per_matrix(lmbda, 4) * IxI
    return tensor_to_matrix(np.broadcast_to(T, (n, d, d, d, d)))


# --- Saint Venant-Kirchhoff (seed eq. (37)) -----------------------------------------------
# E = (F^T F - I)/2,  psi = mu E:E + lmbda/2 tr(E)^2,  P = F S,  S = 2 mu E + lmbda tr(E) I


def _green_strain(F: Array) -> tuple[Array, Array]:
    """``E = (F^T F - I)/2`` and ``tr(E)``."""
    E = 0.5 * (F.transpose(0, 2, 1) @ F - np.eye(F.shape[-1]))
    return E, np.trace(E, axis1=1, axis2=2)


def _stvk_S(F: Array, mu, lmbda) -> Array:
    E, tr = _green_strain(F)
    mu, lmbda = _per_matrix(mu, 2), _per_matrix(lmbda, 2)
    return 2.0 * mu * E + lmbda * tr[:, None, None] * np.eye(F.shape[-1])


def _stvk_psi(F: Array, mu, lmbda) -> Array:
    E, tr = _green_strain(F)
    mu, lmbda = _per_matrix(mu, 0), _per_matrix(lmbda, 0)
    return mu * np.sum(E * E, axis=(1, 2)) + 0.5 * lmbda * tr**2


def _stvk_P(F: Array, mu, lmbda) -> Array:
    return F @ _stvk_S(F, mu, lmbda)


def _stvk_dP(F: Array, mu, lmbda) -> Array:
    # dP_ka/dF_lb = delta_kl S_ab + mu (F_kb F_la + (F F^T)_kl delta_ab) + lmbda F_ka F_lb
    S = _stvk_S(F, mu, lmbda)
    FFt = F @ F.transpose(0, 2, 1)
    delta = np.eye(F.shape[-1])
    T = (np.einsum("kl,nab->nkalb", delta, S)
         + _per_matrix(mu, 4) * (np.einsum("nkb,nla->nkalb", F, F)
                                 + np.einsum("nkl,ab->nkalb", FFt, delta))
         + _per_matrix(lmbda, 4) * np.einsum("nka,nlb->nkalb", F, F))
    return tensor_to_matrix(T)


# --- corotated (seed 4.4.3) ---------------------------------------------------------------
# psi = mu ||F - R||^2 + lmbda/2 (J - 1)^2,  P = 2 mu (F - R) + lmbda (J - 1) cof F


def _corotated_psi(F: Array, mu, lmbda) -> Array:
    R = polar_rotation(F)
    J = np.linalg.det(F)
    mu, lmbda = _per_matrix(mu, 0), _per_matrix(lmbda, 0)
    return mu * np.sum((F - R) ** 2, axis=(1, 2)) + 0.5 * lmbda * (J - 1.0) ** 2


def _corotated_P(F: Array, mu, lmbda) -> Array:
    R = polar_rotation(F)
    J = np.linalg.det(F)[:, None, None]
    mu, lmbda = _per_matrix(mu, 2), _per_matrix(lmbda, 2)
    return 2.0 * mu * (F - R) + lmbda * (J - 1.0) * cofactor(F)


def _corotated_dP(F: Array, mu, lmbda) -> Array:
    # dP/dF = 2 mu (1 - dR/dF) + lmbda (cof F x cof F + (J - 1) d cof F / dF)
    d = F.shape[-1]
    J = np.linalg.det(F)[:, None, None, None, None]
    cof = cofactor(F)
    mu, lmbda = _per_matrix(mu, 4), _per_matrix(lmbda, 4)
    T = (2.0 * mu * (identity_tensor(d) - polar_rotation_derivative(F))
         + lmbda * (np.einsum("nka,nlb->nkalb", cof, cof) + (J - 1.0) * cofactor_derivative(F)))
    return tensor_to_matrix(T)


# --- neo-Hookean ----------------------------------------------------------------------------
# psi = mu/2 (I_C - d) - mu ln J + lmbda/2 (ln J)^2,  P = mu F + (lmbda ln J - mu) F^{-T}
# Defined for J > 0 only: psi = +inf and P, dP/dF = NaN where J <= 0.


def _neohookean_parts(F: Array) -> tuple[Array, Array, Array]:
    """``(valid, ln J, F^{-T})`` with ``valid = J > 0``; invalid entries get ``ln J = 0``."""
    d = F.shape[-1]
    J = np.linalg.det(F)
    valid = J > 0.0
    safe = np.where(valid[:, None, None], F, np.eye(d))
    return valid, np.log(np.where(valid, J, 1.0)), np.linalg.inv(safe).transpose(0, 2, 1)


def _neohookean_psi(F: Array, mu, lmbda) -> Array:
    d = F.shape[-1]
    valid, logJ, _ = _neohookean_parts(F)
    I_C = np.sum(F * F, axis=(1, 2))
    mu, lmbda = _per_matrix(mu, 0), _per_matrix(lmbda, 0)
    psi = 0.5 * mu * (I_C - d) - mu * logJ + 0.5 * lmbda * logJ**2
    return np.where(valid, psi, np.inf)


def _neohookean_P(F: Array, mu, lmbda) -> Array:
    valid, logJ, FinvT = _neohookean_parts(F)
    mu, lmbda = _per_matrix(mu, 2), _per_matrix(lmbda, 2)
    P = mu * F + (lmbda * logJ[:, None, None] - mu) * FinvT
    return np.where(valid[:, None, None], P, np.nan)


def _neohookean_dP(F: Array, mu, lmbda) -> Array:
    # dP_ka/dF_lb = mu delta_kl delta_ab + lmbda F^-T_ka F^-T_lb - (lmbda ln J - mu) F^-T_kb F^-T_la
    d = F.shape[-1]
    valid, logJ, FinvT = _neohookean_parts(F)
    logJ = logJ[:, None, None, None, None]
    mu, lmbda = _per_matrix(mu, 4), _per_matrix(lmbda, 4)
    T = (mu * identity_tensor(d)
         + lmbda * np.einsum("nka,nlb->nkalb", FinvT, FinvT)
         - (lmbda * logJ - mu) * np.einsum("nkb,nla->nkalb", FinvT, FinvT))
    return np.where(valid[:, None, None], tensor_to_matrix(T), np.nan)


# --- stable neo-Hookean (Smith, de Goes and Kim 2018) ---------------------------------------
# psi = mu'/2 (I_C - d) + lmbda'/2 (J - alpha)^2 - mu'/2 ln(I_C + 1) - c0, defined for all F
# P = mu' (1 - 1/(I_C + 1)) F + lmbda' (J - alpha) cof F


def _remapped(mu, lmbda, d: int, ndim: int) -> tuple[Array, Array, Array, Array]:
    """:func:`stable_neohookean_parameters` broadcast against ``ndim`` trailing axes."""
    return tuple(_per_matrix(p, ndim) for p in stable_neohookean_parameters(mu, lmbda, d))


def _stable_neohookean_psi(F: Array, mu, lmbda) -> Array:
    d = F.shape[-1]
    mu_, lmbda_, alpha, c0 = _remapped(mu, lmbda, d, 0)
    I_C = np.sum(F * F, axis=(1, 2))
    J = np.linalg.det(F)
    return (0.5 * mu_ * (I_C - d) + 0.5 * lmbda_ * (J - alpha) ** 2
            - 0.5 * mu_ * np.log(I_C + 1.0) - c0)


def _stable_neohookean_P(F: Array, mu, lmbda) -> Array:
    mu_, lmbda_, alpha, _ = _remapped(mu, lmbda, F.shape[-1], 2)
    I_C = np.sum(F * F, axis=(1, 2))[:, None, None]
    J = np.linalg.det(F)[:, None, None]
    return mu_ * (1.0 - 1.0 / (I_C + 1.0)) * F + lmbda_ * (J - alpha) * cofactor(F)


def _stable_neohookean_dP(F: Array, mu, lmbda) -> Array:
    # dP/dF = mu' (1 - 1/(I_C+1)) 1 + 2 mu'/(I_C+1)^2 F x F
    #         + lmbda' cof F x cof F + lmbda' (J - alpha) d cof F / dF
    d = F.shape[-1]
    mu_, lmbda_, alpha, _ = _remapped(mu, lmbda, d, 4)
    I_C = np.sum(F * F, axis=(1, 2))[:, None, None, None, None]
    J = np.linalg.det(F)[:, None, None, None, None]
    cof = cofactor(F)
    T = (mu_ * (1.0 - 1.0 / (I_C + 1.0)) * identity_tensor(d)
         + 2.0 * mu_ / (I_C + 1.0) ** 2 * np.einsum("nka,nlb->nkalb", F, F)
         + lmbda_ * np.einsum("nka,nlb->nkalb", cof, cof)
         + lmbda_ * (J - alpha) * cofactor_derivative(F))
    return tensor_to_matrix(T)


class _Model(NamedTuple):
    psi: Callable[[Array, object, object], Array]
    P: Callable[[Array, object, object], Array]
    dP: Callable[[Array, object, object], Array]


_MODELS = {
    "linear": _Model(_linear_psi, _linear_P, _linear_dP),
    "stvk": _Model(_stvk_psi, _stvk_P, _stvk_dP),
    "corotated": _Model(_corotated_psi, _corotated_P, _corotated_dP),
    "neohookean": _Model(_neohookean_psi, _neohookean_P, _neohookean_dP),
    "stable_neohookean": _Model(
        _stable_neohookean_psi, _stable_neohookean_P, _stable_neohookean_dP
    ),
}

MATERIALS: tuple[str, ...] = tuple(_MODELS)
"""Names of the available material models."""


def _model(material: str, F: Array) -> _Model:
    if material not in _MODELS:
        raise ValueError(f"material must be one of {MATERIALS}, got {material!r}")
    if F.ndim != 3 or F.shape[1] != F.shape[2] or F.shape[1] not in (2, 3):
        raise ValueError(f"F must have shape (n, d, d) with d in (2, 3), got {F.shape}")
    return _MODELS[material]


def psi(material: str, F: Array, mu, lmbda) -> Array:
    """Energy density ``psi(F)`` per unit reference volume (seed eq. (21), section 4.4).

    Args:
        material: One of :data:`MATERIALS`.
        F: Deformation gradients, shape ``(n, d, d)``.
        mu: First Lame parameter, scalar or ``(n,)``.
        lmbda: Second Lame parameter, scalar or ``(n,)``.

    Returns:
        ``(n,)`` energy densities; ``+inf`` for ``"neohookean"`` where ``J <= 0``.
    """
    return _model(material, F).psi(F, mu, lmbda)


def first_piola(material: str, F: Array, mu, lmbda) -> Array:
    """First Piola-Kirchhoff stress ``P = dpsi/dF``, shape ``(n, d, d)``.

    ``"neohookean"`` gives NaN where ``J <= 0``. Arguments as in :func:`psi`.
    """
    return _model(material, F).P(F, mu, lmbda)


def first_piola_derivative(material: str, F: Array, mu, lmbda) -> Array:
    """Stress derivative ``d vec(P) / d vec(F) = d^2 psi / d vec(F)^2``, shape ``(n, d*d, d*d)``.

    Column-major ``vec`` (seed eq. (30)); symmetric. ``"neohookean"`` gives NaN where
    ``J <= 0``; ``"corotated"`` is undefined where two signed singular values sum to zero.
    Arguments as in :func:`psi`.
    """
    return _model(material, F).dP(F, mu, lmbda)
