"""The membrane and Kirchhoff-Love bending energies of a P2 shell, gradients and Hessians.

The independent oracle of :mod:`fem_anim.forms.shell_kirchhoff_love` (no UFL). A P2 shell is
``points`` (``(n, 3)``, the vertices) and ``cells`` (``(m, 3)`` triangles, consistently
oriented); :func:`p2_nodes` adds the edge midpoints, and the dof vector ``x`` holds the
deformed positions of all nodes, node-major. The displacement is the P2 interpolant of the
nodal ones on each flat rest triangle, with the basis written out on the reference triangle
(barycentric ``l_i``: ``l_i (2 l_i - 1)`` at the vertices, ``4 l_a l_b`` at the edges).

At each point of a cell rule the tangent map ``D_s = dx/dxi`` (3x2) gives the membrane's
metric (:func:`fem_anim.reference.shell_energy.membrane_psi`, seed eq. 26 with a 3x2 ``D_s``)
and the deformed unit normal ``n``; the curvature change in reference coordinates is
``b = sum_k (n . x_k) Hess(phi_k)`` and with the rest metric ``G = J^T J``,
``B : B = tr(b G^-1 b G^-1)``, ``tr B = tr(b G^-1)``, so Koiter's density is
``D/2 [(1 - nu) B:B + nu tr(B)^2]``. Each interior edge couples its two cells (9 nodes): at
each point of an edge rule the signed angle between the two sides' normals (the hinge's
``2 atan(s / (1 + c))`` with the edge taken from vertex ``e0`` to ``e1`` of the cell
``(e0, e1, a)``), minus its rest value, and the moments ``M = D [(1 - nu) k.b.k + nu tr(b
G^-1)]``, ``k = G^-1 J^T nu_e`` the outward conormal in reference coordinates, give
``-{M} Theta + alpha D / (2 h_e) Theta^2`` with ``h_e = (A+ + A-) / |e|``. A clamped boundary
edge is the same with the rest normal as the other side and ``h = 2 A / |e|``. Gradients and
Hessians come from the hyper-dual numbers of :mod:`fem_anim.reference.shell_energy`.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from fem_anim.reference.shell_energy import (
    HyperDual,
    _cross,
    _dot,
    _local_derivatives,
    interior_hinges,
    membrane_psi,
)

__all__ = ["CELL_RULE", "EDGE_RULE", "kl_energy", "kl_gradient", "kl_hessian", "p2_nodes"]

#: The degree-2 rule on the reference triangle (points, weights summing to 1/2).
CELL_RULE = (np.array([[1 / 6, 1 / 6], [2 / 3, 1 / 6], [1 / 6, 2 / 3]]), np.full(3, 1 / 6))
#: The 2-point Gauss rule on [0, 1] (exact to degree 3).
EDGE_RULE = (0.5 + np.array([-0.5, 0.5]) / np.sqrt(3.0), np.array([0.5, 0.5]))

_GRAD_L = np.array([[-1.0, -1.0], [1.0, 0.0], [0.0, 1.0]])  # d l_i / d xi
_EDGES = ((1, 2), (0, 2), (0, 1))  # local edge nodes 3, 4, 5


def p2_nodes(points, cells) -> tuple[np.ndarray, np.ndarray]:
    """The P2 nodes (vertices, then edge midpoints) and each cell's six, ``(v0, v1, v2,
    mid(v1 v2), mid(v0 v2), mid(v0 v1))``."""
    points, cells = np.asarray(points, float), np.asarray(cells, np.int64)
    pairs = np.sort(cells[:, np.array(_EDGES)], axis=2).reshape(-1, 2)
    edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
    nodes = np.vstack([points, (points[edges[:, 0]] + points[edges[:, 1]]) / 2])
    return nodes, np.column_stack([cells, len(points) + inverse.reshape(-1, 3)])


def _basis(xi) -> tuple[np.ndarray, np.ndarray]:
    """Gradients (6, 2) and Hessians (6, 2, 2) of the P2 basis at ``xi``."""
    lam = np.array([1 - xi[0] - xi[1], xi[0], xi[1]])
    grads, hess = np.zeros((6, 2)), np.zeros((6, 2, 2))
    for i in range(3):
        grads[i] = (4 * lam[i] - 1) * _GRAD_L[i]
        hess[i] = 4 * np.outer(_GRAD_L[i], _GRAD_L[i])
    for k, (a, b) in enumerate(_EDGES):
        grads[3 + k] = 4 * (lam[b] * _GRAD_L[a] + lam[a] * _GRAD_L[b])
        hess[3 + k] = 4 * (np.outer(_GRAD_L[a], _GRAD_L[b]) + np.outer(_GRAD_L[b], _GRAD_L[a]))
    return grads, hess


class _Side:
    """A cell's rest geometry (real, ``X`` its six nodes ``(6, 3, m)``) and, at a reference
    point, its deformed tangent map, normal and curvature ``b`` (hyper-dual)."""

    def __init__(self, X, x, sign=1.0):
        self.x, self.sign = x, sign
        J = np.stack([X[1] - X[0], X[2] - X[0]], axis=1)  # (3, 2, m)
        G = np.einsum("iam,ibm->abm", J, J)
        det = G[0, 0] * G[1, 1] - G[0, 1] ** 2
        self.J, self.Gi = J, np.array([[G[1, 1], -G[0, 1]], [-G[0, 1], G[0, 0]]]) / det
        self.dA = np.sqrt(det)  # twice the area
        la = np.sqrt(G[0, 0])
        self.la, self.b1 = la, G[0, 1] / la
        self.h = np.sqrt(G[1, 1] - self.b1**2)
        N = np.cross(J[:, 0], J[:, 1], axis=0)
        self.N_local = N / np.linalg.norm(N, axis=0)
        self.N = [HyperDual(sign * c) for c in self.N_local]

    def at(self, xi):
        grads, hess = _basis(xi)
        self.Ds = [[sum(self.x[k][c] * grads[k, a] for k in range(6)) for a in range(2)]
                   for c in range(3)]
        col = [[self.Ds[c][a] for c in range(3)] for a in range(2)]
        n = _cross(col[0], col[1])
        length = _dot(n, n).sqrt()
        self.n = [self.sign * c / length for c in n]
        nx = [_dot(self.n, self.x[k]) for k in range(6)]
        self.b = [[sum(nx[k] * hess[k, a, b] for k in range(6)) for b in range(2)]
                  for a in range(2)]
        self.g = [[_dot(col[a], col[b]) for b in range(2)] for a in range(2)]
        return self

    def tr_b(self):
        """``tr(b G^-1)`` = tr B."""
        return sum(self.b[a][c] * self.Gi[c, a] for a in range(2) for c in range(2))

    def b_norm2(self):
        """``tr(b G^-1 b G^-1)`` = B:B."""
        bg = [[sum(self.b[a][c] * self.Gi[c, d] for c in range(2)) for d in range(2)]
              for a in range(2)]
        return sum(bg[a][d] * bg[d][a] for a in range(2) for d in range(2))

    def moment(self, conormal, D, nu):
        """``M_nn = D [(1 - nu) nu_e.B.nu_e + nu tr B]`` for a rest conormal ``(3, m)``."""
        k = np.einsum("abm,ibm,im->am", self.Gi, self.J, conormal)
        bkk = sum(self.b[a][c] * (k[a] * k[c]) for a in range(2) for c in range(2))
        return D * ((1 - nu) * bkk + nu * self.tr_b())


def _hinge(n1, n2, edge):
    s = _dot(_cross(n1, n2), edge) / _dot(edge, edge).sqrt()
    return 2 * (s / (1 + _dot(n1, n2))).arctan()


def _cell_term(X, x, model, mu, lmbda, thickness, D, nu, rule):
    side, total = _Side(X, x), 0.0
    for xi, w in zip(*rule):
        side.at(xi)
        g = side.g
        psi = thickness * membrane_psi(g[0][0], g[0][1], g[1][1], side.la, side.b1, side.h,
                                       model, mu, lmbda)
        psi = psi + D / 2 * ((1 - nu) * side.b_norm2() + nu * side.tr_b() * side.tr_b())
        total = total + psi * (w * side.dA)
    return total


def _outward_conormal(side):
    e = side.J[:, 0]
    c = np.cross(e, side.N_local, axis=0)
    return c / np.linalg.norm(c, axis=0)


#: An interior edge's 9 nodes ``(e0, e1, mid(e0 e1), a, mid(e1 a), mid(e0 a), b, mid(e1 b),
#: mid(e0 b))``; each side's six in the cell order of :func:`p2_nodes`.
_PLUS, _MINUS = [0, 1, 3, 4, 5, 2], [0, 1, 6, 7, 8, 2]


def _edge_term(X, x, D, nu, alpha, rule):
    plus = _Side(X[_PLUS], [x[i] for i in _PLUS])
    minus = _Side(X[_MINUS], [x[i] for i in _MINUS], -1.0)  # (e0, e1, b) is reversed
    length = np.linalg.norm(plus.J[:, 0], axis=0)
    height = (plus.dA + minus.dA) / 2 / length
    nu_p, nu_m = _outward_conormal(plus), _outward_conormal(minus)
    rest = _hinge(plus.N, minus.N, [HyperDual(c) for c in plus.J[:, 0]]).a
    total = 0.0
    for s, w in zip(*rule):
        plus.at((s, 0.0))
        minus.at((s, 0.0))
        Theta = _hinge(plus.n, minus.n, [plus.Ds[c][0] for c in range(3)]) - rest
        M = (plus.moment(nu_p, D, nu) + minus.moment(nu_m, D, nu)) / 2
        total = total + (-M * Theta + alpha * D / (2 * height) * Theta * Theta) * (w * length)
    return total


def _clamp_term(X, x, D, nu, alpha, rule):
    side = _Side(X, x)
    length = np.linalg.norm(side.J[:, 0], axis=0)
    height = side.dA / length
    conormal = _outward_conormal(side)
    total = 0.0
    for s, w in zip(*rule):
        side.at((s, 0.0))
        Theta = _hinge(side.n, side.N, [side.Ds[c][0] for c in range(3)])
        M = side.moment(conormal, D, nu)
        total = total + (-M * Theta + alpha * D / (2 * height) * Theta * Theta) * (w * length)
    return total


def _stencils(points, cells, clamped):
    """The cells' six nodes, the interior edges' nine, the clamped edges' cells' six (the
    clamped edge first)."""
    cells = np.asarray(cells, np.int64)
    nodes, cell_nodes = p2_nodes(points, cells)
    n = len(nodes)
    pairs = cell_nodes[:, np.array(_EDGES)]  # (m, 3, 2) vertex pairs of the edge nodes 3..5
    keys = np.sort(pairs, axis=2) @ np.array([n, 1])
    order = np.argsort(keys.ravel())
    sorted_keys, mids = keys.ravel()[order], cell_nodes[:, 3:].ravel()[order]

    def mid(i, j):
        key = np.minimum(i, j) * n + np.maximum(i, j)
        return mids[np.searchsorted(sorted_keys, key)]

    e0, e1, a, b = interior_hinges(cells).T
    edges = np.column_stack([e0, e1, mid(e0, e1), a, mid(e1, a), mid(e0, a), b, mid(e1, b),
                             mid(e0, b)])
    clamped = np.asarray(clamped, np.int64).reshape(-1, 2)
    c0, c1 = clamped.T
    owner = ((cells[None] == c0[:, None, None]).any(2)
             & (cells[None] == c1[:, None, None]).any(2)).argmax(1)
    rest = cells[owner]
    c2 = rest.sum(1) - c0 - c1  # the third vertex
    clamps = np.column_stack([c0, c1, c2, mid(c1, c2), mid(c0, c2), mid(c0, c1)])
    return nodes, cell_nodes, edges.reshape(-1, 9), clamps.reshape(-1, 6)


def _terms(points, cells, model, mu, lmbda, thickness, D, nu, clamped, alpha, cell_rule,
           edge_rule):
    nodes, cell_nodes, edges, clamps = _stencils(points, cells, clamped)
    terms = [(cell_nodes, lambda X, x: _cell_term(X, x, model, mu, lmbda, thickness, D, nu,
                                                  cell_rule)),
             (edges, lambda X, x: _edge_term(X, x, D, nu, alpha, edge_rule)),
             (clamps, lambda X, x: _clamp_term(X, x, D, nu, alpha, edge_rule))]
    return nodes, [t for t in terms if len(t[0])]


def kl_energy(points, cells, model, mu, lmbda, thickness, D, nu, x, clamped=(), alpha=10.0,
              cell_rule=CELL_RULE, edge_rule=EDGE_RULE) -> float:
    """Membrane plus Kirchhoff-Love bending energy (J) at deformed node positions ``x``.

    Args:
        points: Rest vertices ``(n, 3)``.
        cells: Triangles ``(m, 3)``, consistently oriented.
        model: ``"stvk"`` or ``"neohookean"``.
        mu: Shear modulus (Pa).
        lmbda: First Lamé parameter of the 3D material (Pa).
        thickness: Shell thickness (m).
        D: Flexural rigidity (J).
        nu: Poisson's ratio.
        x: Deformed positions of the nodes of :func:`p2_nodes`, node-major.
        clamped: Boundary edges ``(e0, e1)`` (vertex indices) held at their rest normal.
        alpha: The interior-penalty factor.
        cell_rule: The cells' quadrature (reference points, weights).
        edge_rule: The edges' quadrature on [0, 1].
    """
    nodes, terms = _terms(points, cells, model, mu, lmbda, thickness, D, nu, clamped, alpha,
                          cell_rule, edge_rule)
    return sum(_local_derivatives(nodes, x, s, f, 0)[0] for s, f in terms)


def kl_gradient(*args, **kwargs) -> np.ndarray:
    """The gradient of :func:`kl_energy` with respect to ``x`` (same arguments)."""
    nodes, terms = _terms(*_split(args, kwargs))
    x = _x(args, kwargs)
    g = np.zeros(np.size(x))
    for stencils, f in terms:
        dofs, local = _local_derivatives(nodes, x, stencils, f, 1)
        np.add.at(g, dofs.T, local)
    return g


def kl_hessian(*args, **kwargs) -> sp.csr_matrix:
    """The Hessian of :func:`kl_energy` with respect to ``x`` (same arguments)."""
    nodes, terms = _terms(*_split(args, kwargs))
    x = _x(args, kwargs)
    n = np.size(x)
    H = sp.csr_matrix((n, n))
    for stencils, f in terms:
        dofs, local = _local_derivatives(nodes, x, stencils, f, 2)
        rows = np.broadcast_to(dofs.T[:, None, :], local.shape)
        cols = np.broadcast_to(dofs.T[None, :, :], local.shape)
        H = H + sp.csr_matrix((local.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))
    return H


_NAMES = ("points", "cells", "model", "mu", "lmbda", "thickness", "D", "nu", "x", "clamped",
          "alpha", "cell_rule", "edge_rule")
_DEFAULTS = {"clamped": (), "alpha": 10.0, "cell_rule": CELL_RULE, "edge_rule": EDGE_RULE}


def _bind(args, kwargs) -> dict:
    bound = dict(_DEFAULTS, **dict(zip(_NAMES, args)), **kwargs)
    return bound


def _split(args, kwargs) -> tuple:
    b = _bind(args, kwargs)
    return tuple(b[k] for k in _NAMES if k != "x")


def _x(args, kwargs):
    return _bind(args, kwargs)["x"]
