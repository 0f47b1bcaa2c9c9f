"""The standard IPC step as a user would write it: ipctk + numpy + scipy, no DOLFINx.

The "what a user would write" baseline of the contact benchmarks
(:mod:`fem_anim.bench.contact_set`). It steps the same tetrahedra as fem_anim (the arrays
fem_anim's mesh was built from) with Incremental Potential Contact (Li et al. 2020) in its
textbook form, implicit Euler (seed eq. 4 with w = h^2 and the lumped mass):

    x_{n+1} = argmin_x  1/2 ||x - y||_M^2 + h^2 (Psi(x) - f.x + O(x) + D(x)) + kappa B(x),
    y = x_n + h v_n,

with Psi the compressible neo-Hookean energy (seed section 4.4; the numpy model of
:mod:`fem_anim.reference.materials`, vectorised over the elements), f gravity, O the
obstacles' vertex barrier (:mod:`fem_anim.reference.obstacle_barrier`, fem_anim's fixed
obstacle stiffness), B the IPC Toolkit's area-weighted physical barrier between surfaces
(``BarrierPotential(dhat, 1, True)``, as :mod:`fem_anim.contact.ipc`) and D the lagged
friction (IPC section 5: normal forces and tangent bases at x_n, ipctk's
``FrictionPotential`` between surfaces, the obstacles' own as fem_anim's). Newton's method:

* the Hessian is the sum of the per-element Hessians each projected to PSD (eigenvalues
  clamped at 0), the barrier's and friction's per-pair projections (ipctk's ``CLAMP``) and
  the lumped mass; the Newton direction p solves it on the free dofs (scipy's SuperLU);
* the line search starts from the largest collision-free step along p (ipctk's
  tight-inclusion CCD between surfaces; a vertex may close at most 90 % of its gap to a
  plane, fem_anim's :data:`~fem_anim.contact.obstacles.KEEP_FRACTION`) and halves it until
  the objective does not increase (a neo-Hookean element inverted is +inf);
* it stops when ||p||_inf / h < ``tol`` * (the rest bounding-box diagonal), IPC's test;
* kappa is IPC's adaptive stiffness: ``initial_barrier_stiffness`` at each step start (never
  below the value in use), ``update_barrier_stiffness`` after each Newton iteration.

Pinned vertices (``[[pin]]`` boxes, animated handles by :class:`~fem_anim.problem.handles.
PinMotion`) are moved to their targets at the step start and held. Each step records its
wall time, Newton iterations and the time spent in ipctk (detection, barrier, friction, CCD).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import ipctk
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fem_anim.contact.intersection import surface_collision_mesh
from fem_anim.reference.geometry import cell_dofs, cell_volumes, gradient_operator
from fem_anim.reference.materials import first_piola, first_piola_derivative, psi
from fem_anim.reference.obstacle_barrier import (
    barrier,
    barrier_derivatives,
    boundary_facets,
    smoothed_slip,
    vertex_areas,
)
from fem_anim.reference.tensor import unvec, vec

__all__ = ["IPCBaseline", "BaselineStep", "KEEP_FRACTION", "psd_project"]

#: A vertex may close at most 1 - KEEP_FRACTION of its gap to a plane in one trial step.
KEEP_FRACTION = 0.1
#: Newton iterations before a step is declared failed.
MAX_NEWTON = 200


@dataclass
class BaselineStep:
    """What one baseline step did: wall time (s), Newton iterations, time in ipctk (s),
    the barrier stiffness at its end (kappa of the objective, J), the active pairs between
    surfaces at its end and whether IPC's test was met."""

    wall_s: float
    newton_its: int
    ipc_s: float
    kappa: float
    pairs: int
    converged: bool
    timers: dict = field(default_factory=dict)


def psd_project(H: np.ndarray) -> np.ndarray:
    """Each matrix of the stack ``H`` (n, k, k), symmetric, with its negative eigenvalues
    set to 0 (IPC's per-element projection)."""
    lam, Q = np.linalg.eigh(H)
    return np.einsum("nij,nj,nkj->nik", Q, np.maximum(lam, 0.0), Q, optimize=True)


class IPCBaseline:
    """IPC on a tetrahedral mesh, stepped by implicit Euler (module docstring).

    Args:
        points: Rest vertex positions, (n, 3) (m).
        cells: Tetrahedra, (m, 4).
        mu, lmbda, rho: Lame parameters (Pa) and density (kg/m^3), scalars or per cell.
        gravity: The acceleration (m/s^2), (3,).
        obstacles: fem_anim's validated ``[[obstacle]]`` tables (planes).
        contact: fem_anim's validated ``[contact]`` table (``dhat``, ``friction``,
            ``epsv``, ``self``), or None for no contact between surfaces.
        pins: (vertex indices, motion) per pin; ``motion`` has ``displacement(t)`` giving
            the pinned vertices' displacement (k, 3) at time t, or is None for a fixed pin.
        tol: IPC's Newton tolerance relative to the bounding-box diagonal.
    """

    def __init__(self, points, cells, mu, lmbda, rho, gravity, obstacles, contact, pins=(),
                 tol: float = 1e-3):
        self.X = np.asarray(points, float)
        self.cells = np.asarray(cells, np.int64)
        n, m = self.X.shape[0], self.cells.shape[0]
        self.ndof = 3 * n
        self.mu = np.broadcast_to(np.asarray(mu, float), (m,)).copy()
        self.lmbda = np.broadcast_to(np.asarray(lmbda, float), (m,)).copy()
        rho = np.broadcast_to(np.asarray(rho, float), (m,))
        self.vol = cell_volumes(self.X, self.cells)
        self.G = gradient_operator(self.X, self.cells)  # (m, 9, 12): vec F = G x_e
        self.dofs = cell_dofs(self.cells, 3)  # (m, 12)
        self.rows = np.repeat(self.dofs, 12, axis=1).ravel()
        self.cols = np.tile(self.dofs, (1, 12)).ravel()
        mass = np.bincount(self.cells.ravel(), weights=np.repeat(rho * self.vol / 4.0, 4),
                           minlength=n)  # lumped (row sums; seed footnote 4)
        self.mass = np.repeat(mass, 3)
        self.force = (mass[:, None] * np.asarray(gravity, float)[None, :]).ravel()
        self.diagonal = float(np.linalg.norm(np.ptp(self.X, axis=0)))
        self.tol = tol
        facets = boundary_facets(self.cells)
        self.surface_vertices = np.unique(facets)
        self.surface_areas = vertex_areas(self.X, facets)[self.surface_vertices]
        self.obstacles = [dict(o, normal=np.asarray(o["normal"], float)
                               / np.linalg.norm(o["normal"]),
                               point=np.asarray(o["point"] if o.get("point") is not None
                                                else [0.0, 0.0, 0.0], float),
                               stiffness=float(o["stiffness"])) for o in obstacles]
        self.contact = contact
        if contact is not None:
            self.cmesh, self.used = surface_collision_mesh(self.X, self.cells)
            if not contact["self"]:
                self.cmesh.can_collide = ipctk.make_connected_components_filter(
                    self.cmesh.faces)
            self.sdofs = (3 * self.used[:, None] + np.arange(3)).ravel()
            self.dhat = float(contact["dhat"])
            self.potential = ipctk.BarrierPotential(self.dhat, 1.0, True)
            self.collisions = ipctk.NormalCollisions()
            self.collisions.use_area_weighting = True
            self.ccd = ipctk.TightInclusionCCD(1e-6, 10_000)
            self.kappa = 0.0
            self.kappa_max = np.inf
            # ipctk's lower bound on kappa uses the mass per unit of barrier weight
            self.average_mass = float(np.mean(mass)) / (
                np.mean(self.cmesh.vertex_areas) / self.dhat ** 3)
        self.pins = list(pins)
        fixed = np.zeros(self.ndof, bool)
        for vertices, _ in self.pins:
            fixed[(3 * np.asarray(vertices)[:, None] + np.arange(3)).ravel()] = True
        self.free = np.flatnonzero(~fixed)
        self.x = self.X.ravel().copy()
        self.v = np.zeros(self.ndof)
        self.t = 0.0
        self.timers = {"detection_s": 0.0, "barrier_s": 0.0, "friction_s": 0.0, "ccd_s": 0.0}

    # -- energies ---------------------------------------------------------------------------
    def _F(self, x):
        return unvec(np.einsum("nij,nj->ni", self.G, x[self.dofs]), 3)

    def elastic(self, x) -> float:
        """Psi(x), +inf if an element is inverted."""
        with np.errstate(invalid="ignore", divide="ignore"):
            value = float(np.sum(self.vol * psi("neohookean", self._F(x), self.mu,
                                                 self.lmbda)))
        return value if np.isfinite(value) else np.inf

    def _obstacle_terms(self, x, order: int):
        """O(x) (order 0), its gradient (1) or (gradient, Hessian blocks) (2), plus the
        lagged friction's when staged."""
        y = x.reshape(-1, 3)[self.surface_vertices]
        value, grad, blocks = 0.0, np.zeros_like(y), np.zeros((len(y), 3, 3))
        for k, ob in enumerate(self.obstacles):
            d = (y - ob["point"]) @ ob["normal"]
            if np.any(d <= 0.0):
                return np.inf if order == 0 else None
            scale = ob["stiffness"] / ob["dhat"] * self.surface_areas
            n = ob["normal"]
            if order == 0:
                value += float(np.sum(scale * barrier(d, ob["dhat"])))
            else:
                db, d2b = barrier_derivatives(d, ob["dhat"])
                grad += (scale * db)[:, None] * n
                blocks += (scale * d2b)[:, None, None] * np.outer(n, n)
            lag = self._obstacle_lag[k] if self._obstacle_lag else None
            if lag is not None and ob["friction"] > 0:
                weight, eps = lag
                du = y - self._y_lagged
                u_T = du - np.outer(du @ n, n)
                s = np.linalg.norm(u_T, axis=1)
                f0, f1_over_y = smoothed_slip(s, eps)
                if order == 0:
                    value += float(np.sum(weight * f0))
                else:
                    grad += (weight * f1_over_y)[:, None] * u_T
                    # IPC's PSD approximation: f1(y)/y on the tangent plane
                    blocks += (weight * f1_over_y)[:, None, None] * (np.eye(3) - np.outer(n, n))
        if order == 0:
            return value
        return grad, blocks

    def _ipc_update(self, x):
        start = time.perf_counter()
        xs = x.reshape(-1, 3)[self.used]
        self.collisions.build(self.cmesh, xs, self.dhat)
        self.timers["detection_s"] += time.perf_counter() - start
        return xs

    def objective(self, x) -> float:
        """The step objective at x (+inf if inadmissible)."""
        e = self.elastic(x)
        if not np.isfinite(e):
            return np.inf
        o = self._obstacle_terms(x, 0)
        if not np.isfinite(o):
            return np.inf
        r = x - self.y
        value = 0.5 * float(np.sum(self.mass * r * r)) + self.h2 * (e - self.force @ x + o)
        if self.contact is not None:
            xs = self._ipc_update(x)
            start = time.perf_counter()
            value += self.kappa * self.potential(self.collisions, self.cmesh, xs)
            self.timers["barrier_s"] += time.perf_counter() - start
            if self.friction is not None:
                start = time.perf_counter()
                value += self.h2 * self.friction(self.tangential, self.cmesh,
                                                 xs - self._xs_lagged)
                self.timers["friction_s"] += time.perf_counter() - start
        return value

    def gradient_hessian(self, x):
        """The objective's gradient and its projected Hessian (CSR) at x."""
        F = self._F(x)
        P = first_piola("neohookean", F, self.mu, self.lmbda)
        A = first_piola_derivative("neohookean", F, self.mu, self.lmbda)
        local_g = np.einsum("n,nij,ni->nj", self.vol, self.G, vec(P))
        local_H = psd_project(np.einsum("n,npi,npq,nqj->nij", self.vol, self.G, A, self.G,
                                        optimize=True))
        grad = self.mass * (x - self.y) + self.h2 * (
            np.bincount(self.dofs.ravel(), weights=local_g.ravel(), minlength=self.ndof)
            - self.force)
        H = sp.coo_matrix((self.h2 * local_H.ravel(), (self.rows, self.cols)),
                          shape=(self.ndof, self.ndof)).tocsr()
        H = H + sp.diags(self.mass)
        og, ob = self._obstacle_terms(x, 2)
        sd = (3 * self.surface_vertices[:, None] + np.arange(3)).ravel()
        grad[sd] += self.h2 * og.ravel()
        r = np.repeat(sd.reshape(-1, 3), 3, axis=1).ravel()
        c = np.tile(sd.reshape(-1, 3), (1, 3)).ravel()
        H = H + sp.csr_matrix((self.h2 * ob.ravel(), (r, c)), shape=H.shape)
        if self.contact is not None:
            xs = self._ipc_update(x)
            start = time.perf_counter()
            gb = self.kappa * self.potential.gradient(self.collisions, self.cmesh, xs)
            Hb = self.kappa * self.potential.hessian(self.collisions, self.cmesh, xs,
                                                     ipctk.PSDProjectionMethod.CLAMP)
            self.timers["barrier_s"] += time.perf_counter() - start
            if self.friction is not None:
                start = time.perf_counter()
                du = xs - self._xs_lagged
                gb = gb + self.h2 * self.friction.gradient(self.tangential, self.cmesh, du)
                Hb = Hb + self.h2 * self.friction.hessian(self.tangential, self.cmesh, du,
                                                          ipctk.PSDProjectionMethod.CLAMP)
                self.timers["friction_s"] += time.perf_counter() - start
            grad[self.sdofs] += gb
            Hb = Hb.tocoo()
            H = H + sp.csr_matrix((Hb.data, (self.sdofs[Hb.row], self.sdofs[Hb.col])),
                                  shape=H.shape)
        return grad, H

    def _step_bound(self, x, p) -> float:
        """The largest alpha <= 1 keeping x + alpha' p admissible for alpha' <= alpha."""
        alpha = 1.0
        y, dy = x.reshape(-1, 3)[self.surface_vertices], p.reshape(-1, 3)[self.surface_vertices]
        for ob in self.obstacles:
            d, dd = (y - ob["point"]) @ ob["normal"], dy @ ob["normal"]
            closing = dd < 0
            if np.any(closing):
                alpha = min(alpha, float(np.min((1 - KEEP_FRACTION) * d[closing]
                                                / -dd[closing])))
        if self.contact is not None:
            start = time.perf_counter()
            xs = x.reshape(-1, 3)[self.used]
            alpha = min(alpha, float(ipctk.compute_collision_free_stepsize(
                self.cmesh, xs, xs + alpha * p.reshape(-1, 3)[self.used],
                narrow_phase_ccd=self.ccd)) * alpha)
            self.timers["ccd_s"] += time.perf_counter() - start
        return alpha

    # -- the step ---------------------------------------------------------------------------
    def _stage(self, h: float) -> None:
        """Predictor, weights, kappa and the lagged friction at x_n."""
        self.h2 = h * h
        self.y = self.x + h * self.v
        self._obstacle_lag = []
        y = self.x.reshape(-1, 3)[self.surface_vertices]
        self._y_lagged = y.copy()
        for ob in self.obstacles:
            d = (y - ob["point"]) @ ob["normal"]
            db, _ = barrier_derivatives(d, ob["dhat"])
            pressure = -ob["stiffness"] / ob["dhat"] * db
            self._obstacle_lag.append((ob["friction"] * self.surface_areas * pressure,
                                       ob["epsv"] * h) if ob["friction"] > 0 else None)
        self.friction = None
        if self.contact is None:
            return
        xs = self._ipc_update(self.x)
        start = time.perf_counter()
        grad_rest = self.h2 * (self._elastic_gradient(self.x) - self.force)
        og, _ = self._obstacle_terms(self.x, 2)
        grad_rest[(3 * self.surface_vertices[:, None] + np.arange(3)).ravel()] += \
            self.h2 * og.ravel()
        kappa, self.kappa_max = ipctk.initial_barrier_stiffness(
            self.diagonal, self.potential.barrier, self.dhat, self.average_mass,
            grad_rest[self.sdofs], self.potential.gradient(self.collisions, self.cmesh, xs))
        self.kappa = max(self.kappa, kappa)
        self.timers["barrier_s"] += time.perf_counter() - start
        if self.contact["friction"] > 0 and len(self.collisions):
            start = time.perf_counter()
            normal = ipctk.BarrierPotential(self.dhat, self.kappa / self.h2, True)
            self.tangential = ipctk.TangentialCollisions()
            self.tangential.build(self.cmesh, xs, self.collisions, normal,
                                  float(self.contact["friction"]))
            self.friction = ipctk.FrictionPotential(float(self.contact["epsv"]) * h)
            self._xs_lagged = xs.copy()
            self.timers["friction_s"] += time.perf_counter() - start

    def _elastic_gradient(self, x):
        P = first_piola("neohookean", self._F(x), self.mu, self.lmbda)
        local = np.einsum("n,nij,ni->nj", self.vol, self.G, vec(P))
        return np.bincount(self.dofs.ravel(), weights=local.ravel(), minlength=self.ndof)

    def step(self, h: float) -> BaselineStep:
        """One implicit Euler step of size h (s): x, v and t advance in place."""
        for key in self.timers:
            self.timers[key] = 0.0
        start = time.perf_counter()
        x_n = self.x.copy()
        self._stage(h)
        x = x_n.copy()
        for vertices, motion in self.pins:
            if motion is not None:
                dofs = (3 * np.asarray(vertices)[:, None] + np.arange(3)).ravel()
                x[dofs] = (self.X[vertices] + motion.displacement(self.t + h)).ravel()
        f = self.objective(x)
        its, converged = 0, False
        min_distance = self._min_distance(x)
        while its < MAX_NEWTON:
            grad, H = self.gradient_hessian(x)
            free = self.free
            p = np.zeros(self.ndof)
            p[free] = spla.splu(H[free][:, free].tocsc()).solve(-grad[free])
            its += 1
            if np.max(np.abs(p)) / h < self.tol * self.diagonal:
                converged = True
                break
            alpha = self._step_bound(x, p)
            while True:
                trial = x + alpha * p
                f_trial = self.objective(trial)
                if f_trial <= f or alpha < 1e-12:
                    break
                alpha *= 0.5
            x, f = trial, f_trial
            if self.contact is not None:
                distance = self._min_distance(x)
                if np.isfinite(distance) and np.isfinite(min_distance):
                    self.kappa = ipctk.update_barrier_stiffness(
                        min_distance, distance, self.kappa_max, self.kappa, self.diagonal)
                    f = self.objective(x)
                min_distance = distance
        self.v = (x - x_n) / h
        self.x = x
        self.t += h
        wall = time.perf_counter() - start
        pairs = len(self.collisions) if self.contact is not None else 0
        return BaselineStep(wall, its, sum(self.timers.values()),
                            self.kappa if self.contact is not None else 0.0, pairs, converged,
                            dict(self.timers))

    def _min_distance(self, x) -> float:
        if self.contact is None:
            return np.inf
        xs = self._ipc_update(x)
        if not len(self.collisions):
            return np.inf
        start = time.perf_counter()
        d = float(self.collisions.compute_minimum_distance(self.cmesh, xs))
        self.timers["barrier_s"] += time.perf_counter() - start
        return d
