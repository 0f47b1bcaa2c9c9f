"""The membrane and hinge-bending energies of a P1 shell, their gradients and Hessians.

The independent oracle of :mod:`fem_anim.forms.shell_membrane` and
:mod:`fem_anim.forms.shell_bending`: no UFL. A shell is ``points`` (``(n, 3)``) and
``cells`` (``(m, 3)`` triangles); the dof vector ``x`` holds deformed positions,
vertex-major (``x.reshape(-1, 3)[i]``). Each cell's energy is written once, as a function of
its vertices' coordinates (seed eq. 26 with a 3x2 ``D_s``: ``F = D_s D_m^{-1}``, ``D_m`` the
rest edges in an orthonormal frame of the rest plane), and each interior edge's hinge energy
as a function of its four vertices, with the two triangles oriented by the mesh's topology
(the shared edge traversed in opposite directions), not by rest normals. Gradients and
Hessians are exact to rounding: every function is evaluated on hyper-dual numbers
(``a + b e1 + c e2 + d e1 e2``, ``e1^2 = e2^2 = 0``), whose ``e1 e2`` part is the second
derivative along the two seeded directions, all pairs of local dofs at once.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

__all__ = ["HyperDual", "interior_hinges", "membrane_psi", "shell_energy", "shell_gradient",
           "shell_hessian"]


class HyperDual:
    """Arrays ``a + b e1 + c e2 + d e1 e2`` with the arithmetic the shell energies use."""

    __array_ufunc__ = None  # numpy arrays defer to these operators

    def __init__(self, a, b=0.0, c=0.0, d=0.0):
        self.a, self.b, self.c, self.d = a, b, c, d

    @staticmethod
    def _wrap(other):
        return other if isinstance(other, HyperDual) else HyperDual(other)

    def __add__(self, other):
        o = self._wrap(other)
        return HyperDual(self.a + o.a, self.b + o.b, self.c + o.c, self.d + o.d)

    __radd__ = __add__

    def __neg__(self):
        return HyperDual(-self.a, -self.b, -self.c, -self.d)

    def __sub__(self, other):
        return self + (-self._wrap(other))

    def __rsub__(self, other):
        return self._wrap(other) - self

    def __mul__(self, other):
        o = self._wrap(other)
        return HyperDual(self.a * o.a, self.a * o.b + self.b * o.a, self.a * o.c + self.c * o.a,
                         self.a * o.d + self.b * o.c + self.c * o.b + self.d * o.a)

    __rmul__ = __mul__

    def _chain(self, f0, f1, f2):
        """``f(self)`` from ``f``, ``f'``, ``f''`` at the real part."""
        return HyperDual(f0, f1 * self.b, f1 * self.c, f1 * self.d + f2 * self.b * self.c)

    def reciprocal(self):
        """``1 / self``."""
        return self._chain(1 / self.a, -1 / self.a**2, 2 / self.a**3)

    def __truediv__(self, other):
        return self * self._wrap(other).reciprocal()

    def __rtruediv__(self, other):
        return self._wrap(other) * self.reciprocal()

    def sqrt(self):
        """``sqrt(self)``."""
        r = np.sqrt(self.a)
        return self._chain(r, 0.5 / r, -0.25 / (r * self.a))

    def log(self):
        """``ln(self)``."""
        return self._chain(np.log(self.a), 1 / self.a, -1 / self.a**2)

    def arctan(self):
        """``atan(self)``."""
        q = 1 + self.a**2
        return self._chain(np.arctan(self.a), 1 / q, -2 * self.a / q**2)


def _dot(p, q):
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]


def _cross(p, q):
    return [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]]


def _sub(p, q):
    return [pi - qi for pi, qi in zip(p, q)]


def membrane_psi(g00, g01, g11, la, b1, h, model, mu, lmbda):
    """The membrane density (per rest volume) of the metric ``g = D_s^T D_s`` of a tangent
    map ``D_s`` (hyper-dual), ``D_m = [[la, b1], [0, h]]`` the rest one in its orthonormal
    frame: ``C = D_m^{-T} g D_m^{-1}``, then StVK or neo-Hookean in plane stress."""
    i00, i01, i11 = 1 / la, -b1 / (la * h), 1 / h  # D_m^{-1} = [[i00, i01], [0, i11]]
    C00 = i00 * i00 * g00
    C01 = i00 * (g00 * i01 + g01 * i11)
    C11 = i01 * i01 * g00 + 2 * i01 * i11 * g01 + i11 * i11 * g11
    ls = 2 * mu * lmbda / (lmbda + 2 * mu)
    if model == "stvk":
        E00, E01, E11 = (C00 - 1) / 2, C01 / 2, (C11 - 1) / 2
        trE = E00 + E11
        return mu * (E00 * E00 + 2 * E01 * E01 + E11 * E11) + ls / 2 * trE * trE
    if model == "neohookean":
        lnJ = (C00 * C11 - C01 * C01).log() / 2
        return mu / 2 * (C00 + C11 - 2) - mu * lnJ + ls / 2 * lnJ * lnJ
    raise ValueError(f"no membrane energy for model {model!r}")


def _membrane_cell(X, x, model, mu, lmbda, thickness):
    """t A psi(F) of each cell; ``X`` real rest vertices ``(3, 3, m)``, ``x`` deformed."""
    a, b = X[1] - X[0], X[2] - X[0]
    la = np.linalg.norm(a, axis=0)
    t1 = a / la
    b1 = np.einsum("im,im->m", b, t1)
    h = np.sqrt(np.einsum("im,im->m", b, b) - b1**2)
    area = la * h / 2
    # D_m = [[la, b1], [0, h]]; F = D_s D_m^{-1}; C = F^T F from the metric g = D_s^T D_s
    ds0, ds1 = _sub(x[1], x[0]), _sub(x[2], x[0])
    g00, g01, g11 = _dot(ds0, ds0), _dot(ds0, ds1), _dot(ds1, ds1)
    psi = membrane_psi(g00, g01, g11, la, b1, h, model, mu, lmbda)
    return psi * (thickness * area)


def interior_hinges(cells: np.ndarray) -> np.ndarray:
    """The interior edges as ``(e0, e1, a, b)``: triangles ``(e0, e1, a)`` and ``(e1, e0, b)``
    are consistently oriented (the edge traversed in opposite directions).

    Args:
        cells: ``(m, 3)`` triangles.

    Raises:
        ValueError: if an edge has more than two triangles, or two triangles sharing an edge
            are oppositely oriented (the surface is non-manifold or non-orientable).
    """
    cells = np.asarray(cells, dtype=np.int64)
    local = np.array([[0, 1, 2], [1, 2, 0], [2, 0, 1]])  # edge (i, j) and opposite k
    half = cells[:, local].reshape(-1, 3)  # directed edges with their opposite vertex
    key = np.sort(half[:, :2], axis=1)
    _, inverse, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    if (counts > 2).any():
        raise ValueError("an edge has more than two triangles (non-manifold surface)")
    order = np.argsort(inverse, kind="stable")
    shared = np.flatnonzero(counts[inverse[order]] == 2)[::2]
    first, second = half[order[shared]], half[order[shared + 1]]
    flip = first[:, 0] == second[:, 0]
    if flip.any():
        raise ValueError("two triangles sharing an edge are oppositely oriented")
    return np.column_stack([first[:, 0], first[:, 1], first[:, 2], second[:, 2]])


def _hinge_angle(e0, e1, a, b):
    """The signed dihedral angle ``2 atan(s / (1 + c))`` of a hinge (hyper-dual vertices)."""
    edge = _sub(e1, e0)
    n1 = _cross(edge, _sub(a, e0))
    n2 = _cross(_sub(b, e0), edge)
    l1, l2 = _dot(n1, n1).sqrt(), _dot(n2, n2).sqrt()
    n1, n2 = [c / l1 for c in n1], [c / l2 for c in n2]
    s = _dot(_cross(n1, n2), edge) / _dot(edge, edge).sqrt()
    return 2 * (s / (1 + _dot(n1, n2))).arctan()


def _hinge_term(X, x, k):
    """k 3 |e|^2 / (A1 + A2) (theta - theta_rest)^2 of each hinge (``(4, 3, m)`` vertices)."""
    theta_rest = _hinge_angle(*[[HyperDual(c) for c in v] for v in X]).a
    edge = X[1] - X[0]
    A1 = np.linalg.norm(np.cross(edge, X[2] - X[0], axis=0), axis=0) / 2
    A2 = np.linalg.norm(np.cross(edge, X[3] - X[0], axis=0), axis=0) / 2
    weight = 3 * k * np.einsum("im,im->m", edge, edge) / (A1 + A2)
    diff = _hinge_angle(*x) - theta_rest
    return diff * diff * weight


def _local_derivatives(points, x, stencils, function, order):
    """Sum of ``function`` over stencils, and its gradient/Hessian entries by hyper-duals."""
    points, x = np.asarray(points, float), np.asarray(x, float).reshape(-1, 3)
    X = points[stencils].transpose(1, 2, 0)  # (nv, 3, m)
    xl = x[stencils].transpose(1, 2, 0)
    nv, m = stencils.shape[1], len(stencils)
    n_local = 3 * nv
    if order == 0:
        return float(np.sum(function(X, [[HyperDual(c) for c in v] for v in xl]).a)), None
    pairs = [(i, j) for i in range(n_local) for j in range(n_local)] if order == 2 \
        else [(i, i) for i in range(n_local)]
    seeds_i = np.array([p[0] for p in pairs])
    seeds_j = np.array([p[1] for p in pairs])
    P = len(pairs)
    xs = []
    for v in range(nv):
        comps = []
        for c in range(3):
            dof = 3 * v + c
            comps.append(HyperDual(np.broadcast_to(xl[v, c], (P, m)),
                                   (seeds_i == dof)[:, None] * np.ones(m),
                                   (seeds_j == dof)[:, None] * np.ones(m), 0.0))
        xs.append(comps)
    value = function(X, xs)
    dofs = (3 * stencils[:, :, None] + np.arange(3)).reshape(m, -1)
    if order == 1:
        return dofs, value.b  # (n_local, m)
    return dofs, value.d.reshape(n_local, n_local, m)


def _terms(points, cells, model, mu, lmbda, thickness, k):
    hinges = interior_hinges(cells) if k else np.empty((0, 4), np.int64)
    membrane = (cells, lambda X, x: _membrane_cell(X, x, model, mu, lmbda, thickness))
    bending = (hinges, lambda X, x: _hinge_term(X, x, k))
    return [t for t in (membrane, bending) if len(t[0])]


def shell_energy(points, cells, model, mu, lmbda, thickness, k, x) -> float:
    """Membrane plus hinge-bending energy (J) at deformed positions ``x``.

    Args:
        points: Rest positions ``(n, 3)``.
        cells: Triangles ``(m, 3)``.
        model: ``"stvk"`` or ``"neohookean"``.
        mu: Shear modulus (Pa).
        lmbda: First Lamé parameter of the 3D material (Pa).
        thickness: Shell thickness (m).
        k: Hinge stiffness (J); 0 for a membrane.
        x: Deformed positions, vertex-major.
    """
    cells = np.asarray(cells, np.int64)
    return sum(_local_derivatives(points, x, s, f, 0)[0]
               for s, f in _terms(points, cells, model, mu, lmbda, thickness, k))


def shell_gradient(points, cells, model, mu, lmbda, thickness, k, x) -> np.ndarray:
    """The energy's gradient with respect to ``x`` (same arguments as :func:`shell_energy`)."""
    cells = np.asarray(cells, np.int64)
    g = np.zeros(np.size(x))
    for stencils, f in _terms(points, cells, model, mu, lmbda, thickness, k):
        dofs, local = _local_derivatives(points, x, stencils, f, 1)
        np.add.at(g, dofs.T, local)
    return g


def shell_hessian(points, cells, model, mu, lmbda, thickness, k, x) -> sp.csr_matrix:
    """The energy's Hessian with respect to ``x`` (same arguments as :func:`shell_energy`)."""
    cells = np.asarray(cells, np.int64)
    n = np.size(x)
    H = sp.csr_matrix((n, n))
    for stencils, f in _terms(points, cells, model, mu, lmbda, thickness, k):
        dofs, local = _local_derivatives(points, x, stencils, f, 2)
        rows = np.broadcast_to(dofs.T[:, None, :], local.shape)
        cols = np.broadcast_to(dofs.T[None, :, :], local.shape)
        H = H + sp.csr_matrix((local.ravel(), (rows.ravel(), cols.ravel())), shape=(n, n))
    return H
