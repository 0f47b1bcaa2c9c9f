"""The mixed (u, p) energy of :mod:`fem_anim.forms.incompressible` on a P1/P1 mesh, in numpy.

The perturbed Lagrangian (Taylor-Hood in the solver; here both fields are P1, so that every
integral is exact with the reference's one-point kinematics)

    Pi(x, p) = sum_e |e| [ psi_dev(F_e) + g(J_e) pbar_e ] - 1/(2 kappa) p^T M_p p,

``pbar_e`` the mean of the element's vertex pressures and ``M_p`` the P1 mass matrix
(``|e| (1 + delta_ij) / ((d+1)(d+2))`` per element). ``psi_dev`` is written in the
invariants ``(I_C, II_C, J)`` of seed section 4.4, so one chain rule serves every model:

    P = psi_I 2F + psi_II dII + psi_J cof F,
    dP/dF = sum_ab psi_ab dX_a (x) dX_b + psi_I 2 1 + psi_II d2II + psi_J dcof/dF,

with ``dII = 2 (I_C F - F C)`` and
``d2II_kalb = 4 F_ka F_lb + 2 I_C d_kl d_ab - 2 d_kl C_ab - 2 F_kb F_la - 2 (F F^T)_kl d_ab``.
Gradient and Hessian are returned for the unknown ``(x, p)`` stacked as
``[x (vertex-major, d per vertex), p (one per vertex)]``.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_anim.reference.geometry import cell_dofs, cell_volumes, check_mesh, gradient_operator
from fem_anim.reference.tensor import (
    cofactor,
    cofactor_derivative,
    identity_tensor,
    tensor_to_matrix,
    unvec,
    vec,
)

__all__ = ["MIXED_MODELS", "mixed_energy", "mixed_gradient", "mixed_hessian"]

MIXED_MODELS = ("neohookean", "stable_neohookean", "mooney_rivlin")


def _partials(model: str, I, II, J, mu: float, ratio: float, d: int) -> dict:
    """psi_dev and its first and second partial derivatives in (I = I_C, II = II_C, J)."""
    z = np.zeros_like(J)
    out = dict.fromkeys(("I", "II", "J", "I_I", "I_II", "I_J", "II_II", "II_J", "J_J"), z)
    if model == "neohookean":  # mu/2 (I - d) - mu ln J
        out |= {"psi": 0.5 * mu * (I - d) - mu * np.log(J), "I": z + 0.5 * mu, "J": -mu / J,
                "J_J": mu / J**2}
    elif model == "stable_neohookean":  # mu'/2 (I - d) - mu'/2 ln((I + 1)/(d + 1)) - mu (J - 1)
        m = (d + 1) / d * mu
        out |= {"psi": 0.5 * m * (I - d) - 0.5 * m * np.log((I + 1) / (d + 1)) - mu * (J - 1),
                "I": 0.5 * m * (1 - 1 / (I + 1)), "I_I": 0.5 * m / (I + 1) ** 2, "J": z - mu}
    elif model == "mooney_rivlin":  # c10 (J^-2/3 I1 - 3) + c01 (J^-4/3 I2 - 3)
        c10, c01 = (1 - ratio) * mu / 2, ratio * mu / 2
        I1, I2 = (I + 1, II + I) if d == 2 else (I, II)
        dI2_dI = 1.0 if d == 2 else 0.0
        a, b = J ** (-2 / 3), J ** (-4 / 3)
        out |= {"psi": c10 * (a * I1 - 3) + c01 * (b * I2 - 3),
                "I": c10 * a + c01 * b * dI2_dI, "II": c01 * b,
                "J": -2 / 3 * c10 * a / J * I1 - 4 / 3 * c01 * b / J * I2,
                "I_J": -2 / 3 * c10 * a / J - 4 / 3 * c01 * b / J * dI2_dI,
                "II_J": -4 / 3 * c01 * b / J,
                "J_J": 10 / 9 * c10 * a / J**2 * I1 + 28 / 9 * c01 * b / J**2 * I2}
    else:
        raise ValueError(f"model must be one of {MIXED_MODELS}, got {model!r}")
    return out


def _constraint(model: str, J):
    """``(g, g', g'')`` of the volumetric constraint: ln J for neo-Hookean, else J - 1."""
    if model == "neohookean":
        return np.log(J), 1 / J, -1 / J**2
    return J - 1, np.ones_like(J), np.zeros_like(J)


def _kinematics(points, cells, x):
    points, cells = check_mesh(points, cells)
    d = points.shape[1]
    G = gradient_operator(points, cells)
    dofs = cell_dofs(cells, d)
    F = unvec(np.einsum("nij,nj->ni", G, np.asarray(x, dtype=float)[dofs]), d)
    return points, cells, d, G, dofs, F, cell_volumes(points, cells)


def _invariant_derivatives(F):
    """``(I, II, J)``, their first derivatives ``(n, d, d)`` and second ``(n, d, d, d, d)``."""
    n, d, _ = F.shape
    C = np.einsum("nka,nkb->nab", F, F)
    I = np.einsum("naa->n", C)
    II = 0.5 * (I**2 - np.einsum("nab,nab->n", C, C))
    J = np.linalg.det(F)
    first = {"I": 2 * F, "II": 2 * (I[:, None, None] * F - F @ C), "J": cofactor(F)}
    delta = np.eye(d)
    FFt = F @ F.transpose(0, 2, 1)
    d2II = (4 * np.einsum("nka,nlb->nkalb", F, F)
            + 2 * I[:, None, None, None, None] * identity_tensor(d)
            - 2 * np.einsum("kl,nab->nkalb", delta, C)
            - 2 * np.einsum("nkb,nla->nkalb", F, F)
            - 2 * np.einsum("nkl,ab->nkalb", FFt, delta))
    second = {"I": np.broadcast_to(2 * identity_tensor(d), (n, d, d, d, d)), "II": d2II,
              "J": cofactor_derivative(F)}
    return (I, II, J), first, second


def _p1_mass(w, d):
    m = d + 1
    return w[:, None, None] * (np.ones((m, m)) + np.eye(m)) / ((d + 1) * (d + 2))


def mixed_energy(points, cells, model, mu, inv_kappa, x, p, ratio=0.0) -> float:
    """The perturbed Lagrangian ``Pi(x, p)`` (J).

    Args:
        points: Rest positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d + 1)``.
        model: ``"neohookean"``, ``"stable_neohookean"`` or ``"mooney_rivlin"``.
        mu: The shear modulus (Pa).
        inv_kappa: The compliance ``1/kappa`` (1/Pa).
        x: Deformed positions ``(n_vertices * d,)``, vertex-major.
        p: Vertex pressures ``(n_vertices,)`` (Pa).
        ratio: The Mooney ratio r (Mooney-Rivlin only).
    """
    points, cells, d, _, _, F, w = _kinematics(points, cells, x)
    (I, II, J), _, _ = _invariant_derivatives(F)
    psi = _partials(model, I, II, J, mu, ratio, d)["psi"]
    g = _constraint(model, J)[0]
    pe = np.asarray(p, dtype=float)[cells]
    quadratic = np.einsum("ni,nij,nj->n", pe, _p1_mass(w, d), pe)
    return float(np.sum(w * (psi + g * pe.mean(axis=1))) - 0.5 * inv_kappa * quadratic.sum())


def _stress_parts(model, F, mu, ratio, pbar):
    """``vec(P + pbar g' cof F)`` ``(n, d*d)``, its derivative ``(n, d*d, d*d)`` and
    ``vec(g' cof F)`` (the coupling)."""
    d = F.shape[-1]
    (I, II, J), first, second = _invariant_derivatives(F)
    s = _partials(model, I, II, J, mu, ratio, d)
    g, dg, d2g = _constraint(model, J)
    names = ("I", "II", "J")

    def key(a, b):
        return f"{a}_{b}" if names.index(a) <= names.index(b) else f"{b}_{a}"

    P = sum(s[a][:, None, None] * first[a] for a in names)
    T = sum(s[a][:, None, None, None, None] * second[a] for a in names)
    for a in names:
        for b in names:
            T = T + s[key(a, b)][:, None, None, None, None] * np.einsum(
                "nka,nlb->nkalb", first[a], first[b])
    coupling = dg[:, None, None] * first["J"]
    P = P + pbar[:, None, None] * coupling
    T = T + pbar[:, None, None, None, None] * (
        d2g[:, None, None, None, None] * np.einsum("nka,nlb->nkalb", first["J"], first["J"])
        + dg[:, None, None, None, None] * second["J"])
    return vec(P), tensor_to_matrix(T), vec(coupling), g


def mixed_gradient(points, cells, model, mu, inv_kappa, x, p, ratio=0.0) -> np.ndarray:
    """``[dPi/dx, dPi/dp]`` as one dense vector (arguments as in :func:`mixed_energy`)."""
    points, cells, d, G, dofs, F, w = _kinematics(points, cells, x)
    pe = np.asarray(p, dtype=float)[cells]
    vP, _, _, g = _stress_parts(model, F, mu, ratio, pe.mean(axis=1))
    n_x = points.size
    grad_x = np.bincount(dofs.ravel(), weights=np.einsum("n,nij,ni->nj", w, G, vP).ravel(),
                         minlength=n_x)
    local_p = (w * g / (d + 1))[:, None] - inv_kappa * np.einsum("nij,nj->ni", _p1_mass(w, d), pe)
    grad_p = np.bincount(cells.ravel(), weights=local_p.ravel(), minlength=points.shape[0])
    return np.concatenate([grad_x, grad_p])


def mixed_hessian(points, cells, model, mu, inv_kappa, x, p, ratio=0.0) -> sp.csr_matrix:
    """The symmetric indefinite Hessian in ``(x, p)`` (arguments as in :func:`mixed_energy`)."""
    points, cells, d, G, dofs, F, w = _kinematics(points, cells, x)
    pe = np.asarray(p, dtype=float)[cells]
    _, A, coupling, _ = _stress_parts(model, F, mu, ratio, pe.mean(axis=1))
    n_x, m = points.size, d + 1
    xx = np.einsum("n,npi,npq,nqj->nij", w, G, A, G, optimize=True)
    xp = np.repeat((np.einsum("n,npi,np->ni", w, G, coupling) / m)[:, :, None], m, axis=2)
    pp = -inv_kappa * _p1_mass(w, d)
    pdofs = cells + n_x
    blocks = [(dofs, dofs, xx), (dofs, pdofs, xp), (pdofs, dofs, xp.transpose(0, 2, 1)),
              (pdofs, pdofs, pp)]
    rows = np.concatenate([np.repeat(r, c.shape[1], axis=1).ravel() for r, c, _ in blocks])
    cols = np.concatenate([np.tile(c, (1, r.shape[1])).ravel() for r, c, _ in blocks])
    values = np.concatenate([v.ravel() for _, _, v in blocks])
    n = n_x + points.shape[0]
    return sp.coo_matrix((values, (rows, cols)), shape=(n, n)).tocsr()
