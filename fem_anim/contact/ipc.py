"""Contact between surfaces (bodies with each other and with themselves) by the IPC Toolkit.

Incremental Potential Contact (Li et al. 2020) adds to E(x) in the step objective
g(x) = 1/2 ||x - y||_M^2 + w E(x) (seed eq. 4) the barrier energy

    B(x) = kappa sum_k a_k b(d_k(x)^2, d_hat^2) / d_hat^3,
    b(s, s_hat) = -(s - s_hat)^2 ln(s / s_hat)   for s < s_hat,  0 beyond,

over the point-triangle and edge-edge pairs k of the boundary surface closer than
d_hat (ipctk 1.6: ``BarrierPotential(dhat, kappa, use_physical_barrier=True)`` on
``NormalCollisions`` with ``use_area_weighting``; a_k is the pair's share of the
surface area, so kappa is a pressure in Pa and B is in J, like the obstacles' barrier
of :mod:`fem_anim.forms.obstacle_contact`). B is +inf at contact, so every trial point
of the line search is kept on the collision-free part of the Newton segment by ipctk's
continuous collision detection (:meth:`IPCContact.step_bound`): no accepted state has an
intersection. A shell's surface is its triangles, kept its thickness apart
(:mod:`fem_anim.contact.contact_surface`: the ``offset`` d_min).

ipctk is serial: this module is its MPI wrapper, with the distribution in
:mod:`fem_anim.contact.distribution`. The surface vertices (P1 dofs on the exterior facets;
for P2 also the facets' edge-midpoint dofs, each facet split in four on them:
:mod:`fem_anim.contact.p2_surface`) are numbered by their global dof block. No rank
gathers the surface: each rank builds the collision set of a local mesh (its own facets
and a halo of nearby remote facets, rebuilt under MPI when a vertex has moved past the
halo's margin), evaluates the pairs whose lowest vertex it owns, sends gradient rows and
Hessian rows of remote vertices to their owners, and the energy, the minimum distance,
the pair count and the CCD step bound are reduced over all ranks (the adaptive stiffness
from reduced dot products), so every rank holds the same scalars. On one rank this is
the serial computation to the last digit. The Hessian is
projected to PSD per pair (IPC's projection) and dropped on pinned dofs (they are
Dirichlet rows). Its pattern couples dofs the elastic sparsity does not: the matrix
accepts new nonzeros (``NEW_NONZERO_ALLOCATION_ERR`` off), which PETSc keeps from then
on, so only a step meeting new pairs pays for the reallocation.

Stiffness ``"adaptive"`` is IPC's schedule: at a step start ``initial_barrier_stiffness``
balances the barrier's gradient against w grad E (with ipctk's lower bound from the mass
and the scene size), never below the value ``update_barrier_stiffness`` left after the
previous step (it grows kappa while the minimum distance keeps falling). The balance is
taken at each step start until a step starts with pairs present, and never after: from
then on only ``update_barrier_stiffness`` changes kappa_IPC, so a scene at rest keeps one
barrier. kappa is fixed within a step, so the objective is one function during each
minimisation.

ipctk runs on one thread: its parallel loops (TBB) sum in an order that changes from run to
run, so two runs of one scene (and a run resumed from a checkpoint) would differ in their
last digits. One thread makes every run repeat to the last digit.
"""

from __future__ import annotations

import time

import ipctk
import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim.contact.contact_surface import surface_entities
from fem_anim.contact.distribution import SurfacePartition, owned_collisions, surface_labels
from fem_anim.contact.lagged_friction import LaggedFriction
from fem_anim.contact.p2_surface import surface_faces
from fem_anim.contact.rest_check import rest_problem
from fem_anim.errors import SceneError

__all__ = ["IPCContact", "CCD_MAX_ITERATIONS", "CCD_TOLERANCE", "HALO_GROWTH", "HALO_MARGIN",
           "HALO_MAX_MARGIN", "narrow_phase_ccd"]

#: The halo's least margin m in units of the longest surface edge L: a halo of radius
#: d_hat + 3 L + 8 m is rebuilt once a surface vertex has moved more than m
#: (:mod:`fem_anim.contact.distribution`).
HALO_MARGIN = 0.25
#: A halo rebuilt because a vertex moved d past the old one's margin gets the margin
#: max(HALO_MARGIN L, min(HALO_GROWTH d, HALO_MAX_MARGIN L)): a line search that tries
#: points far out and comes back builds one wider halo instead of one per trial point,
#: and no halo reaches further than d_hat + (3 + 8 HALO_MAX_MARGIN) L.
HALO_GROWTH = 2.0
#: The largest margin of a halo in units of L (see :data:`HALO_GROWTH`).
HALO_MAX_MARGIN = 1.0

#: Tight inclusion's precision of the time of impact (ipctk's default).
CCD_TOLERANCE = 1.0e-6
#: Tight inclusion's cap on interval bisections per candidate pair (ipctk's default is 1e7).
#: Parallel edges or faces approaching each other never shrink to an inclusion and use the
#: whole cap; at the cap tight inclusion returns the lower end of the interval it holds, a
#: conservative time of impact, so the cap bounds the work and never lets a step cross.
CCD_MAX_ITERATIONS = 10_000


def narrow_phase_ccd() -> ipctk.NarrowPhaseCCD:
    """The narrow phase of every continuous collision detection of :class:`IPCContact`.

    Returns:
        ipctk's tight-inclusion CCD (Wang et al. 2021: conservative, no false negatives) with
        :data:`CCD_TOLERANCE` and at most :data:`CCD_MAX_ITERATIONS` bisections per pair.
    """
    return ipctk.TightInclusionCCD(CCD_TOLERANCE, CCD_MAX_ITERATIONS)


class IPCContact:
    """The barrier of ``[contact]`` on the union mesh's boundary surface.

    Args:
        cfg: The validated ``[contact]`` table.
        u: The displacement Function (P1 or P2).
        pinned: Local dof indices (unblocked) held by Dirichlet conditions.
        body_names: Names of the bodies by marker - 1 (for messages).
        cell_body: Body index of each local cell.
        offset: The minimum distance d_min the barrier keeps (m): 0 for solids, a shell's
            thickness (:mod:`fem_anim.contact.contact_surface`); B acts on d^2 - d_min^2
            with activation d_min + d_hat, and the CCD stops at d_min.
        unknown: For a mixed (u, p) unknown, ``(W, u_dofs)``: its space and the map from
            each local dof of ``V`` (unrolled) to the local dof of ``W`` holding it; the
            barrier's gradient and Hessian then go to those rows of the unknown (the
            displacement block only: the barrier does not depend on the pressure). None:
            the unknown is ``u``.

    Raises:
        SceneError: (collectively) if two bodies cross or are within ``dhat`` at rest.
    """

    def __init__(self, cfg: dict, u, pinned: np.ndarray, body_names: list[str],
                 cell_body: np.ndarray, offset: float = 0.0, unknown=None):
        V = u.function_space
        mesh = V.mesh
        self.comm: MPI.Comm = mesh.comm
        ipctk.set_num_threads(1)  # repeatable sums (module docstring)
        self.cfg, self.u = cfg, u
        self.dhat = float(cfg["dhat"])
        self.offset = float(offset)
        self.gdim = g = mesh.geometry.dim
        tdim = mesh.topology.dim
        index_map = V.dofmap.index_map
        self.n_owned = n_owned = index_map.size_local
        mesh.topology.create_connectivity(tdim - 1, tdim)
        mesh.topology.create_connectivity(tdim - 1, 0)
        mesh.topology.create_connectivity(tdim, 0)
        c_to_v = mesh.topology.connectivity(tdim, 0).array.reshape(-1, tdim + 1)
        # the surface (a solid's boundary facets, a shell's triangles), P2 split on midpoints
        entity_vertices, entity_cells = surface_entities(mesh)
        local_faces, parent = surface_faces(V, entity_vertices, c_to_v)
        faces = index_map.local_to_global(local_faces.ravel().astype(np.int32)).reshape(
            local_faces.shape).astype(np.int64)
        face_body = cell_body[entity_cells[parent]].astype(np.int64)
        X = V.tabulate_dof_coordinates()[:, :g]
        is_pinned = np.zeros(V.dofmap.index_map_bs * (n_owned + index_map.num_ghosts), bool)
        is_pinned[pinned] = True
        free = ~is_pinned.reshape(-1, g)[local_faces]
        labels = surface_labels(self.comm, faces) if not cfg["self"] else \
            np.zeros_like(faces)
        start, end = index_map.local_range
        #: each owned block's local and global rows in the unknown, (owned blocks, gdim)
        self.unknown_rows, self.unknown_global = self._unknown_rows(unknown, n_owned, start)
        self.part = SurfacePartition(self.comm, faces, X[local_faces], free, face_body,
                                     labels.astype(np.int64), X[:n_owned], start, end,
                                     bool(cfg["self"]))
        self._start(body_names)

    def _start(self, body_names: list[str]) -> None:
        """The state every evaluation reads, the first halo, and the check of the surfaces
        at rest, once ``part``, ``unknown_rows`` and ``unknown_global`` are set (collective;
        :class:`~fem_anim.contact.joint_surface.JointIPCContact` shares it)."""
        cfg = self.cfg
        self.timers = {"detection_s": 0.0, "barrier_s": 0.0, "ccd_s": 0.0, "exchange_s": 0.0}
        # adaptive: 0 until the first step sets it (initial energies: no pair between bodies)
        self.kappa = float(cfg["stiffness"]) if cfg["stiffness"] != "adaptive" else 0.0
        self.kappa_floor = 0.0
        #: Whether kappa has been balanced against the elastic forces with pairs present
        self.balanced = False
        self.weight = 1.0
        self._distance = np.inf
        #: IPC's per-pair projection of the Hessian (NONE: the exact Hessian, for tests)
        self.projection = ipctk.PSDProjectionMethod.CLAMP
        self.friction: LaggedFriction | None = None  # the step's lagged friction, if any
        self._x = None
        self._drift = 0.0
        self.potential = ipctk.BarrierPotential(self.dhat, 1.0, True)
        self.ccd = narrow_phase_ccd()
        self.collisions = ipctk.NormalCollisions()  # this rank's (distribution.owned_collisions)
        self.collisions.use_area_weighting = True
        rest = self.part.owned_rest
        lo, hi = np.min(rest, axis=0, initial=np.inf), np.max(rest, axis=0, initial=-np.inf)
        self.comm.Allreduce(MPI.IN_PLACE, lo, op=MPI.MIN)
        self.comm.Allreduce(MPI.IN_PLACE, hi, op=MPI.MAX)
        self.diagonal = float(np.linalg.norm(hi - lo))
        #: how many local meshes this rank has built (halos, and wider ones for a CCD sweep)
        self.halo_builds = 0
        self.halo = self._build_halo()
        x = self._update()
        error = rest_problem(self.comm, self.halo, x, self.collisions,
                             np.sqrt(self._min_distance(x)),  # ipctk's is d^2
                             self.offset, self.dhat, body_names)
        if error:
            raise SceneError(error)

    def _unknown_rows(self, unknown, n_owned: int, start: int) -> tuple[np.ndarray,
                                                                         np.ndarray]:
        """The local and global rows of the unknown holding each owned dof block of ``V``
        (vertex-major: x, y(, z) of each block)."""
        g = self.gdim
        rows = np.arange(n_owned, dtype=np.int64)[:, None] * g + np.arange(g)
        if unknown is None:
            return rows, rows + start * g
        W, u_dofs = unknown
        rows = np.asarray(u_dofs)[rows.ravel()].astype(np.int64)
        bs, index_map = W.dofmap.index_map_bs, W.dofmap.index_map
        assert np.all(rows < index_map.size_local * bs)  # owned dofs of V are owned in W
        nodes = index_map.local_to_global((rows // bs).astype(np.int32))
        return rows.reshape(-1, g), (np.asarray(nodes, np.int64) * bs + rows % bs).reshape(-1, g)

    # -- the MPI seam (fem_anim.contact.distribution) ---------------------------------------
    def _u_owned(self) -> np.ndarray:
        return self.u.x.array.reshape(-1, self.gdim)[: self.n_owned]

    def _build_halo(self, reach=None, moved: float = 0.0):
        """This rank's facets and the halo (collective; :mod:`fem_anim.contact.distribution`).

        Default reach: d_hat + 3 L + 8 m with the margin
        m = max(:data:`HALO_MARGIN` L, min(:data:`HALO_GROWTH` ``moved``,
        :data:`HALO_MAX_MARGIN` L)), kept while no surface vertex moves more than m.

        Args:
            reach: The radius as a function of L instead (a CCD sweep's wider mesh).
            moved: How far a vertex moved past the previous halo (m; 0 at set-up).
        """
        start = time.perf_counter()
        margin = lambda L: max(HALO_MARGIN * L, min(HALO_GROWTH * moved,  # noqa: E731
                                                    HALO_MAX_MARGIN * L))
        if reach is None:
            reach = lambda L: self.offset + self.dhat + 3.0 * L + 8.0 * margin(L)  # noqa: E731
        halo = self.part.build(self._u_owned(), reach)
        halo.margin = margin(halo.longest)
        #: the unknown's global row of each local vertex's components (from their owners)
        halo.unknown_global = halo.exchange.fetch(self.unknown_global)
        self.halo_builds += 1
        self.timers["exchange_s"] += time.perf_counter() - start
        return halo

    @property
    def mesh(self) -> ipctk.CollisionMesh:
        """This rank's collision mesh: its facets and the halo (one rank: the whole surface);
        :attr:`collisions` are its pairs on it, ``_update()`` its positions."""
        return self.halo.mesh

    @property
    def num_pairs(self) -> int:
        """The number of collisions of the whole surface at the last evaluation (collective)."""
        return self.comm.allreduce(len(self.collisions))

    def _update(self) -> np.ndarray:
        """Fetch this rank's x and rebuild the halo (when x drifted past its margin) and the
        collision set (when x changed) (collective).

        Returns:
            The positions of the local mesh's vertices.
        """
        start = time.perf_counter()
        x = self.halo.positions(self._u_owned())
        # one rank's local mesh is the whole surface: never rebuilt, so a run's last digits
        # do not depend on when halos were rebuilt (a resumed run repeats an uninterrupted one)
        self._drift = self.halo.drift(x) if self.comm.size > 1 else 0.0
        if self._drift > self.halo.margin:
            self.halo = self._build_halo(moved=self._drift)
            x, self._x, self._drift = self.halo.x_built, None, 0.0
        self.timers["exchange_s"] += time.perf_counter() - start
        start = time.perf_counter()
        if self._x is None or not np.array_equal(x, self._x):
            every = ipctk.NormalCollisions()
            every.use_area_weighting = True
            every.build(self.halo.mesh, x, self.dhat, self.offset)
            self.collisions = owned_collisions(self.halo, every)
            self._x = x
        self.timers["detection_s"] += time.perf_counter() - start
        return x

    def _friction_positions(self, x: np.ndarray) -> np.ndarray:
        """Positions on the mesh the friction was lagged on (collective)."""
        if self.friction.halo is self.halo:
            return x
        return self.friction.halo.positions(self._u_owned())

    def _to_global(self, halo, rows: np.ndarray, cols: np.ndarray, vals: np.ndarray):
        """Triplets of a local mesh's dofs, free rows and columns only, as the unknown's
        global rows, with the rank owning each row."""
        g = self.gdim
        keep = halo.free[rows] & halo.free[cols]
        rows, cols, vals = rows[keep], cols[keep], vals[keep]
        owner = np.searchsorted(self.part.ranges, halo.vertices[rows // g], side="right")
        to_global = halo.unknown_global.ravel()
        return to_global[rows], to_global[cols], vals, owner

    # -- energy, gradient, Hessian -------------------------------------------------------------
    def energy(self, friction: bool = True) -> float:
        """The barrier energy kappa B(x) at the current ``u`` (collective).

        Args:
            friction: Add the step's lagged friction potential D(x), if one is staged.

        Returns:
            kappa B(x) (+ D(x)) in J, the same on every rank; +inf at contact.
        """
        x = self._update()
        start = time.perf_counter()
        value = self.kappa * self.potential(self.collisions, self.halo.mesh, x)
        if friction and self.friction is not None:
            value += self.friction.energy(self._friction_positions(x))
        value = self.comm.allreduce(value)
        self.timers["barrier_s"] += time.perf_counter() - start
        return value

    def _gradient_rows(self, x: np.ndarray, scale: float, friction: bool) -> np.ndarray:
        """scale (kappa grad B (+ grad D)) on the owned dof blocks (collective)."""
        g = self.gdim
        owned = np.zeros((self.n_owned, g))
        grad = (scale * self.kappa) * self.potential.gradient(self.collisions, self.halo.mesh,
                                                              x)
        if friction and self.friction is not None:
            dgrad = scale * self.friction.gradient(self._friction_positions(x))
            if self.friction.halo is self.halo:
                grad += dgrad
            else:
                self.friction.halo.to_owners(dgrad.reshape(-1, g), owned)
        self.halo.to_owners(grad.reshape(-1, g), owned)
        return owned

    def add_gradient(self, b: PETSc.Vec, scale: float) -> None:
        """Add ``scale`` kappa grad B(x) (+ grad D) to ``b`` on the owned surface dofs (collective).

        Args:
            b: The local gradient vector (owned entries are updated in place).
            scale: The factor applied to the barrier's gradient (the integrator weight w).
        """
        x = self._update()
        start = time.perf_counter()
        rows = self._gradient_rows(x, scale, True)
        b.array[self.unknown_rows[self.part.blocks].ravel()] += rows[self.part.blocks].ravel()
        self.timers["barrier_s"] += time.perf_counter() - start

    def add_hessian(self, A: PETSc.Mat, scale: float) -> None:
        """Add ``scale`` kappa Hess B(x)^+ (per-pair PSD projection) to ``A`` (collective).

        Rows and columns of pinned dofs are left out; each rank computes the Hessian of the
        pairs it owns and sends every row to the rank owning it. Call before ``A.assemble()``.

        Args:
            A: The Hessian matrix; it must accept new nonzeros.
            scale: The factor applied to the barrier's Hessian (the integrator weight w).
        """
        self.insert_hessian(A, self.hessian_triplets(scale))

    def hessian_triplets(self, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``scale`` kappa Hess B(x)^+ (+ Hess D) as triplets of this rank's rows (collective).

        Returns:
            Global rows (sorted), columns (sorted within a row) and values; a row and
            column may repeat (pairs sharing dofs: their values are added).
        """
        x = self._update()
        start = time.perf_counter()
        H = self.kappa * self.potential.hessian(self.collisions, self.halo.mesh, x,
                                                self.projection)
        triplets = []
        if self.friction is not None:
            Hf = self.friction.hessian(self._friction_positions(x), self.projection)
            if self.friction.halo is self.halo:
                H = H + Hf
            else:
                Hf = Hf.tocoo()
                triplets.append(self._to_global(self.friction.halo, Hf.row, Hf.col,
                                                scale * Hf.data))
        H = H.tocoo()
        triplets.insert(0, self._to_global(self.halo, H.row, H.col, scale * H.data))
        rows, cols, vals, owner = (np.concatenate(t) for t in zip(*triplets))
        parts = [(rows[owner == r], cols[owner == r], vals[owner == r])
                 for r in range(self.comm.size)]
        got = self.comm.alltoall(parts)
        rows, cols, vals = (np.concatenate(t) for t in zip(*got))
        if rows.size:
            order = np.lexsort((cols, rows))
            rows, cols, vals = rows[order], cols[order], vals[order]
        self.timers["barrier_s"] += time.perf_counter() - start
        return rows, cols, vals

    def insert_hessian(self, A: PETSc.Mat, triplets) -> None:
        """Add :meth:`hessian_triplets`' triplets to ``A`` (this rank's rows; before
        ``A.assemble()``)."""
        start = time.perf_counter()
        rows, cols, vals = triplets
        if rows.size:
            unique, first = np.unique(rows, return_index=True)
            indptr = np.r_[first, rows.size].astype(PETSc.IntType)
            A.setValuesIJV(indptr, cols.astype(PETSc.IntType), vals,
                           addv=PETSc.InsertMode.ADD_VALUES,
                           rowmap=unique.astype(PETSc.IntType))
        self.timers["barrier_s"] += time.perf_counter() - start

    def friction_adjoint(self, lam: np.ndarray, w: float) -> np.ndarray:
        """w (Hess D + (dF/dx_n)^T) lambda on the owned dof blocks (collective).

        The adjoint of IPC's lagged friction (:mod:`fem_anim.adjoint.backward`):
        :meth:`~fem_anim.contact.lagged_friction.LaggedFriction.adjoint` on the pairs this
        rank owns (its friction mesh), summed at the owners.

        Args:
            lam: A local dof array of ``V`` (the adjoint variable).
            w: The integrator weight.

        Returns:
            (owned blocks, gdim) rows, zero off the free surface dofs.
        """
        x = self._update()
        halo, g = self.friction.halo, self.gdim
        lam = halo.exchange.fetch(lam.reshape(-1, g)[: self.n_owned]).ravel() * halo.free
        out = self.friction.adjoint(lam, self._friction_positions(x))
        owned = np.zeros((self.n_owned, g))
        halo.to_owners((w * out * halo.free).reshape(-1, g), owned)
        return owned

    # -- admissibility ----------------------------------------------------------------------
    def step_bound(self, y: np.ndarray) -> float:
        """The largest collision-free step along the update ``-y`` (collective).

        Each rank sweeps its local mesh (its facets and the halo), whose pairs include every
        pair whose lowest vertex it owns when the halo reaches 2 |dy|_max + L past the
        region (else a wider halo is built for this sweep); the bound is the minimum over
        ranks.

        Args:
            y: The Newton update as a local dof array (the trial point is x - alpha y).

        Returns:
            The largest alpha <= 1 with x - alpha' y collision free for all alpha' <= alpha
            (ipctk's continuous collision detection, with its conservative rescaling).
        """
        x0 = self._update()
        start = time.perf_counter()
        y_owned = y.reshape(-1, self.gdim)[: self.n_owned]
        sweep = float(np.max(np.linalg.norm(y_owned[self.part.blocks], axis=1), initial=0.0))
        sweep = self.comm.allreduce(sweep, op=MPI.MAX)
        halo = self.halo
        if self.comm.size > 1 and \
                self.offset + 2 * sweep + halo.longest + 4 * self._drift > halo.radius:
            halo = self._build_halo(lambda L: self.offset + self.dhat + 2 * sweep + 3 * L)
            x0 = halo.x_built
        dy = halo.exchange.fetch(np.ascontiguousarray(y_owned))
        self.timers["exchange_s"] += time.perf_counter() - start
        start = time.perf_counter()
        alpha = float(ipctk.compute_collision_free_stepsize(
            halo.mesh, x0, x0 - dy, min_distance=self.offset, narrow_phase_ccd=self.ccd))
        alpha = self.comm.allreduce(alpha, op=MPI.MIN)
        self.timers["ccd_s"] += time.perf_counter() - start
        return alpha

    def exact_hessian(self, exact: bool) -> None:
        """Assemble the barrier's and friction's exact Hessian (True) or IPC's per-pair PSD
        projection (False, the default).

        The projection makes every Newton direction a descent direction but changes the
        Hessian where a pair's is indefinite, so Newton converges only linearly near a
        resting contact; near a strict minimiser the exact Hessian of g is positive definite
        and restores quadratic convergence (:class:`fem_anim.solver.minimiser.Minimiser`
        switches to it once Newton's steps are small).
        """
        self.projection = ipctk.PSDProjectionMethod.NONE if exact else \
            ipctk.PSDProjectionMethod.CLAMP

    # -- stiffness schedule -------------------------------------------------------------------
    def stage(self, weight: float, grad_energy: np.ndarray, average_mass: float,
              h: float) -> None:
        """Set kappa (and the lagged friction) for the next step, at the current ``u`` = u_n.

        IPC's kappa multiplies a barrier added to the whole objective; here the barrier sits
        inside w E (seed eq. 4, w = h^2/4 for Newmark), so kappa = kappa_IPC / w.

        Args:
            weight: The integrator weight w of E in the step objective.
            grad_energy: grad E on the local dofs (for the adaptive stiffness).
            average_mass: The mean lumped mass per vertex (ipctk's lower bound on kappa).
            h: The time step (s); friction smooths over ``epsv`` h.
        """
        self.weight = weight
        self.friction = None
        if self.cfg["stiffness"] == "adaptive":
            self._adapt(weight, grad_energy, average_mass)
        if self.cfg["friction"] > 0:
            self._stage_friction(h)

    def restage(self, kappa: float, h: float) -> None:
        """Use the barrier stiffness ``kappa`` (in E, Pa: ``stats.csv``'s
        ``barrier_stiffness``) and lag friction at the current ``u`` = u_n, to re-check a
        written step's equations (collective).

        Args:
            kappa: The step's recorded barrier stiffness.
            h: The step size (s).
        """
        self.kappa = float(kappa)
        self.friction = None
        if self.cfg["friction"] > 0:
            self._stage_friction(h)

    def _stage_friction(self, h: float) -> None:
        """IPC's lagged friction at the current ``u`` = u_n on this rank's local mesh
        (:mod:`fem_anim.contact.lagged_friction`), kept there if the halo is rebuilt."""
        x = self._update()
        mu = float(self.cfg["friction"])
        self.friction = LaggedFriction(self.halo, x, self.collisions, self.dhat, self.kappa, mu,
                                       float(self.cfg["epsv"]) * h)

    def _adapt(self, weight: float, grad_energy: np.ndarray, average_mass: float) -> None:
        """IPC's adaptive kappa at the step start (module docstring), from global sums."""
        x = self._update()
        blocks = self.part.blocks
        g_energy = grad_energy.reshape(-1, self.gdim)[blocks]
        g_local = self.potential.gradient(self.collisions, self.halo.mesh, x)
        g_barrier = np.zeros((self.n_owned, self.gdim))
        self.halo.to_owners(g_local.reshape(-1, self.gdim), g_barrier)
        g_barrier = g_barrier[blocks]
        area = self.halo.mesh.vertex_areas[self.halo.owned]
        areas = self.comm.allreduce(float(np.sum(area)))
        weights = areas / self.part.count / self.dhat ** 3
        if self.comm.size == 1:  # the serial call, to the last digit
            weights = np.mean(self.halo.mesh.vertex_areas) / self.dhat ** 3
            g_e, g_b = weight * g_energy.ravel(), g_local
        else:  # ipctk's kappa depends on the vectors through -g_b.g_e / |g_b|^2 only
            dot = self.comm.allreduce(float(np.sum(weight * g_energy * g_barrier)))
            norm2 = self.comm.allreduce(float(np.sum(g_barrier * g_barrier)))
            g_b = np.array([np.sqrt(norm2)])
            g_e = np.array([dot / g_b[0] if norm2 > 0 else 0.0])
        kappa, self.kappa_max = ipctk.initial_barrier_stiffness(
            self.diagonal, self.potential.barrier, self.dhat, average_mass / weights, g_e, g_b,
            dmin=self.offset)
        # balanced once, where pairs exist; then only IPC's update moves it, so kappa
        # stays put while nothing changes (a pile at rest keeps one objective)
        value = self.kappa_floor if self.balanced else max(kappa, self.kappa_floor)
        self.balanced = self.balanced or self.num_pairs > 0
        self.kappa_floor = value
        self._distance = self._min_distance(x)
        self.kappa_ipc = value
        self.kappa = self.kappa_ipc / weight

    def _min_distance(self, x: np.ndarray) -> float:
        """The smallest SQUARED distance of the pairs nearer than d_hat (m^2, inf if none;
        collective): ipctk's ``compute_minimum_distance``, the quantity its stiffness update
        takes."""
        local = float(self.collisions.compute_minimum_distance(self.halo.mesh, x)) \
            if len(self.collisions) else np.inf
        return self.comm.allreduce(local, op=MPI.MIN)

    def state(self) -> dict[str, float]:
        """What a checkpoint keeps across steps.

        Returns:
            ``{"kappa_floor": ..., "kappa_balanced": ...}``: rank 0's floor of the adaptive
            kappa and whether it was balanced with pairs present (1.0) or not (0.0).
        """
        return {"kappa_floor": float(self.kappa_floor), "kappa_balanced": float(self.balanced)}

    def restore(self, state: dict[str, float]) -> None:
        """Continue from a checkpoint.

        Args:
            state: What :meth:`state` returned (without ``kappa_floor``, the floor is 0).
        """
        self.kappa_floor = float(state.get("kappa_floor", 0.0))
        self.balanced = bool(state.get("kappa_balanced", 0.0))

    def step_stats(self) -> dict[str, float]:
        """The contact columns of a step's ``stats.csv`` row, at the current ``u`` (collective).

        Returns:
            ``barrier_stiffness``: kappa in E (Pa; the objective's barrier is w kappa B),
            ``dhat`` (m), ``contact_pairs``, ``min_distance`` (m, of the pairs nearer than
            d_hat; inf without one) and ``friction_lags``: how often the step's friction
            was lagged (IPC's normal force and tangent basis taken at x_n: 1 with friction).
        """
        x = self._update()
        d = np.sqrt(self._min_distance(x))  # ipctk's is d^2
        return {"barrier_stiffness": self.kappa, "dhat": self.dhat,
                "contact_pairs": self.num_pairs, "min_distance": float(d),
                "friction_lags": int(self.friction is not None)}

    def finish_step(self) -> None:
        """After an accepted step: IPC's update of kappa from the distance's trend."""
        x = self._update()
        if self.cfg["stiffness"] != "adaptive":
            return
        d = self._min_distance(x)
        if np.isfinite(d) and np.isfinite(self._distance):
            self.kappa_floor = ipctk.update_barrier_stiffness(
                self._distance, d, self.kappa_max, self.kappa_floor, self.diagonal,
                dmin=self.offset)
