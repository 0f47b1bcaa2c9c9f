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

ipctk is serial: this module is its one MPI wrapper. The surface vertices (P1
dofs on the exterior facets; for P2 also the facets' edge-midpoint dofs, each facet split in
four on them: :mod:`fem_anim.contact.p2_surface`) are numbered by their global dof block,
in order, so each rank owns a contiguous run of them; each evaluation gathers their positions x = X + u to
rank 0, which builds the collision set and evaluates there, then broadcasts scalars and
sends each rank the gradient entries and Hessian rows it owns. The Hessian is
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
from fem_anim.contact.p2_surface import surface_faces
from fem_anim.errors import SceneError

__all__ = ["IPCContact", "CCD_MAX_ITERATIONS", "CCD_TOLERANCE", "narrow_phase_ccd"]

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
        n_owned = index_map.size_local
        mesh.topology.create_connectivity(tdim - 1, tdim)
        mesh.topology.create_connectivity(tdim - 1, 0)
        mesh.topology.create_connectivity(tdim, 0)
        c_to_v = mesh.topology.connectivity(tdim, 0).array.reshape(-1, tdim + 1)
        # the surface (a solid's boundary facets, a shell's triangles), P2 split on midpoints
        entity_vertices, entity_cells = surface_entities(mesh)
        local_faces, parent = surface_faces(V, entity_vertices, c_to_v)
        faces = index_map.local_to_global(local_faces.ravel().astype(np.int32)).reshape(
            local_faces.shape)
        face_body = cell_body[entity_cells[parent]]
        start = index_map.local_range[0]
        ranges = np.asarray(self.comm.allgather(index_map.local_range[1]))
        gathered = self.comm.gather((faces, face_body), root=0)
        owned_lists = None
        if self.comm.rank == 0:
            faces = np.concatenate([f for f, _ in gathered])
            self.face_body = np.concatenate([b for _, b in gathered])
            self.surface = np.unique(faces)  # global blocks, ascending: collision numbering
            self.faces = np.searchsorted(self.surface, faces).astype(np.int32)
            self.counts = np.diff(np.searchsorted(self.surface, np.r_[0, ranges]))
            owned_lists = np.split(self.surface, np.cumsum(self.counts)[:-1])
        self.blocks = (self.comm.scatter(owned_lists, root=0) - start).astype(np.int64)
        assert np.all(self.blocks < n_owned)
        self.rows, global_rows = self._unknown_rows(unknown, n_owned)
        parts = self.comm.gather(global_rows, root=0)
        #: rank 0: the unknown's global row of each surface dof, in collision order
        self.global_rows = np.concatenate(parts) if self.comm.rank == 0 else None
        X = V.tabulate_dof_coordinates()[self.blocks, :g]
        is_pinned = np.zeros(V.dofmap.index_map_bs * (n_owned + index_map.num_ghosts), bool)
        is_pinned[pinned] = True
        free = ~is_pinned.reshape(-1, g)[self.blocks]
        rest, free = self._gather(X), self._gather(free.astype(float))
        self.timers = {"detection_s": 0.0, "barrier_s": 0.0, "ccd_s": 0.0}
        # adaptive: 0 until the first step sets it (initial energies: no pair between bodies)
        self.kappa = float(cfg["stiffness"]) if cfg["stiffness"] != "adaptive" else 0.0
        self.kappa_floor = 0.0
        #: Whether kappa has been balanced against the elastic forces with pairs present
        self.balanced = False
        self.weight = 1.0
        self._distance = np.inf
        #: IPC's per-pair projection of the Hessian (NONE: the exact Hessian, for tests)
        self.projection = ipctk.PSDProjectionMethod.CLAMP
        self.friction = None  # the step's lagged friction potential (rank 0), if any
        self._x = None
        self.num_pairs = 0
        if self.comm.rank == 0:
            self.free = free.ravel() > 0.5
            edges = ipctk.edges(self.faces) if g == 3 else self.faces
            F = self.faces if g == 3 else np.empty((0, 3), np.int32)
            self.mesh = ipctk.CollisionMesh(rest, np.asfortranarray(edges, np.int32),
                                            np.asfortranarray(F, np.int32))
            if not cfg["self"]:
                self.mesh.can_collide = ipctk.make_connected_components_filter(F)
            self.potential = ipctk.BarrierPotential(self.dhat, 1.0, True)
            self.ccd = narrow_phase_ccd()
            self.collisions = ipctk.NormalCollisions()
            self.collisions.use_area_weighting = True
            self.diagonal = float(np.linalg.norm(np.ptp(rest, axis=0)))
            self.vertex_body = np.zeros(rest.shape[0], np.int64)
            self.vertex_body[self.faces.ravel()] = np.repeat(self.face_body, g)
        error = self._check_rest(rest, body_names) if self.comm.rank == 0 else None
        error = self.comm.bcast(error, root=0)
        if error:
            raise SceneError(error)

    def _unknown_rows(self, unknown, n_owned: int) -> tuple[np.ndarray, np.ndarray]:
        """The local and global rows of the unknown holding the owned surface dofs
        (unrolled, vertex-major: x, y(, z) of each vertex)."""
        g, V = self.gdim, self.u.function_space
        rows = (self.blocks[:, None] * g + np.arange(g)).ravel()
        if unknown is None:
            start = V.dofmap.index_map.local_range[0]
            return rows, (self.blocks[:, None] + start) * g + np.arange(g)
        W, u_dofs = unknown
        rows = np.asarray(u_dofs)[rows].astype(np.int64)
        bs, index_map = W.dofmap.index_map_bs, W.dofmap.index_map
        assert np.all(rows < index_map.size_local * bs)  # owned dofs of V are owned in W
        nodes = index_map.local_to_global((rows // bs).astype(np.int32))
        return rows, (np.asarray(nodes, np.int64) * bs + rows % bs).reshape(-1, g)

    # -- the MPI seam -------------------------------------------------------------------------
    def _gather(self, local: np.ndarray) -> np.ndarray | None:
        """Rows of the owned surface vertices, stacked on rank 0 in collision order."""
        parts = self.comm.gather(np.ascontiguousarray(local, dtype=float), root=0)
        return np.concatenate(parts) if self.comm.rank == 0 else None

    def _scatter(self, rows: np.ndarray | None) -> np.ndarray:
        """Rank 0's per-vertex rows back to the ranks owning the vertices."""
        parts = np.split(rows, np.cumsum(self.counts)[:-1]) if self.comm.rank == 0 else None
        return self.comm.scatter(parts, root=0)

    def positions(self, values: np.ndarray | None = None) -> np.ndarray | None:
        """Surface vertex rows gathered to rank 0, in collision order (collective).

        Args:
            values: A local dof array to gather instead of the positions (no X added);
                None for the current positions x = X + u.

        Returns:
            The (surface vertices, gdim) array on rank 0; None on the other ranks.
        """
        if values is None:
            u = self.u.x.array.reshape(-1, self.gdim)[self.blocks]
            x = self._gather(u)
            return None if x is None else self.mesh.rest_positions + x
        return self._gather(values.reshape(-1, self.gdim)[self.blocks])

    def _update(self) -> np.ndarray | None:
        """Gather x and rebuild the collision set when x changed (collective)."""
        start = time.perf_counter()
        x = self.positions()
        if self.comm.rank == 0 and (self._x is None or not np.array_equal(x, self._x)):
            self.collisions.build(self.mesh, x, self.dhat, self.offset)
            self._x = x
            self.num_pairs = len(self.collisions)
        self.timers["detection_s"] += time.perf_counter() - start
        return x

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
        value = None
        if self.comm.rank == 0:
            value = self.kappa * self.potential(self.collisions, self.mesh, x)
            if friction and self.friction is not None:
                value += self.friction(self.tangential, self.mesh, x - self._x_lagged)
        self.timers["barrier_s"] += time.perf_counter() - start
        return self.comm.bcast(value, root=0)

    def add_gradient(self, b: PETSc.Vec, scale: float) -> None:
        """Add ``scale`` kappa grad B(x) (+ grad D) to ``b`` on the owned surface dofs (collective).

        Args:
            b: The local gradient vector (owned entries are updated in place).
            scale: The factor applied to the barrier's gradient (the integrator weight w).
        """
        x = self._update()
        start = time.perf_counter()
        grad = None
        if self.comm.rank == 0:
            grad = (scale * self.kappa) * self.potential.gradient(
                self.collisions, self.mesh, x)
            if self.friction is not None:
                grad += scale * self.friction.gradient(self.tangential, self.mesh,
                                                       x - self._x_lagged)
            grad = grad.reshape(-1, self.gdim)
        mine = self._scatter(grad)
        b.array[self.rows] += mine.ravel()
        self.timers["barrier_s"] += time.perf_counter() - start

    def add_hessian(self, A: PETSc.Mat, scale: float) -> None:
        """Add ``scale`` kappa Hess B(x)^+ (per-pair PSD projection) to ``A`` (collective).

        Rows and columns of pinned dofs are left out. Call before ``A.assemble()``.

        Args:
            A: The Hessian matrix; it must accept new nonzeros.
            scale: The factor applied to the barrier's Hessian (the integrator weight w).
        """
        x = self._update()
        start = time.perf_counter()
        parts = None
        if self.comm.rank == 0:
            H = self.kappa * self.potential.hessian(self.collisions, self.mesh, x,
                                                    self.projection)
            if self.friction is not None:
                H = H + self.friction.hessian(self.tangential, self.mesh, x - self._x_lagged,
                                              self.projection)
            H = H.tocoo()
            keep = self.free[H.row] & self.free[H.col]
            g = self.gdim
            to_global = self.global_rows.ravel()  # dof i of the surface -> the unknown's row
            rows, cols = to_global[H.row[keep]], to_global[H.col[keep]]
            vals = scale * H.data[keep]
            ranges = np.cumsum(self.counts)  # surface vertices per rank, in rank order
            owner = np.searchsorted(ranges, H.row[keep] // g, side="right")
            parts = [(rows[owner == r], cols[owner == r], vals[owner == r])
                     for r in range(self.comm.size)]
        rows, cols, vals = self.comm.scatter(parts, root=0)
        if rows.size:
            order = np.lexsort((cols, rows))
            rows, cols, vals = rows[order], cols[order], vals[order]
            unique, first = np.unique(rows, return_index=True)
            indptr = np.r_[first, rows.size].astype(PETSc.IntType)
            A.setValuesIJV(indptr, cols.astype(PETSc.IntType), vals,
                           addv=PETSc.InsertMode.ADD_VALUES,
                           rowmap=unique.astype(PETSc.IntType))
        self.timers["barrier_s"] += time.perf_counter() - start

    # -- admissibility ----------------------------------------------------------------------
    def step_bound(self, y: np.ndarray) -> float:
        """The largest collision-free step along the update ``-y`` (collective).

        Args:
            y: The Newton update as a local dof array (the trial point is x - alpha y).

        Returns:
            The largest alpha <= 1 with x - alpha' y collision free for all alpha' <= alpha
            (ipctk's continuous collision detection, with its conservative rescaling).
        """
        x0 = self._update()
        dy = self.positions(y)
        start = time.perf_counter()
        alpha = float(ipctk.compute_collision_free_stepsize(
            self.mesh, x0, x0 - dy, min_distance=self.offset,
            narrow_phase_ccd=self.ccd)) if self.comm.rank == 0 else None
        self.timers["ccd_s"] += time.perf_counter() - start
        return self.comm.bcast(alpha, root=0)

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
        """IPC's lagged friction (section 5): normal forces and tangent bases at x_n,

        D(x) = sum_k mu lambda_k f0(|T_k^T (x - x_n)|), f0 smoothed over eps_v h,

        with lambda_k the pair's barrier force kappa |dB_k/dd| (area-weighted, in N).
        """
        x = self._update()
        if self.comm.rank == 0:
            normal = ipctk.BarrierPotential(self.dhat, self.kappa, True)
            self.tangential = ipctk.TangentialCollisions()
            self.tangential.build(self.mesh, x, self.collisions, normal,
                                  float(self.cfg["friction"]))
            self.friction = ipctk.FrictionPotential(float(self.cfg["epsv"]) * h)
            self._x_lagged = x.copy()
        else:
            self.friction = True  # rank 0 holds the potential; the others only take part

    def _adapt(self, weight: float, grad_energy: np.ndarray, average_mass: float) -> None:
        """IPC's adaptive kappa at the step start (module docstring)."""
        x = self._update()
        g_energy = self.positions(grad_energy)
        value = None
        if self.comm.rank == 0:
            g_barrier = self.potential.gradient(self.collisions, self.mesh, x)
            weights = np.mean(self.mesh.vertex_areas) / self.dhat ** 3
            kappa, self.kappa_max = ipctk.initial_barrier_stiffness(
                self.diagonal, self.potential.barrier, self.dhat, average_mass / weights,
                weight * g_energy.ravel(), g_barrier, dmin=self.offset)
            # balanced once, where pairs exist; then only IPC's update moves it, so kappa
            # stays put while nothing changes (a pile at rest keeps one objective)
            value = self.kappa_floor if self.balanced else max(kappa, self.kappa_floor)
            self.balanced = self.balanced or self.num_pairs > 0
            self.kappa_floor = value
            self._distance = self._min_distance(x)
        self.kappa_ipc = self.comm.bcast(value, root=0)
        self.kappa = self.kappa_ipc / weight

    def _min_distance(self, x: np.ndarray) -> float:
        """Rank 0: the smallest SQUARED distance of the pairs nearer than d_hat (m^2, inf if
        none): ipctk's ``compute_minimum_distance``, the quantity its stiffness update takes."""
        return float(self.collisions.compute_minimum_distance(self.mesh, x)) \
            if self.num_pairs else np.inf

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
        d = np.sqrt(self._min_distance(x)) if self.comm.rank == 0 else None  # ipctk's is d^2
        return {"barrier_stiffness": self.kappa, "dhat": self.dhat,
                "contact_pairs": self.comm.bcast(self.num_pairs, root=0),
                "min_distance": self.comm.bcast(d, root=0),
                "friction_lags": int(self.friction is not None)}

    def finish_step(self) -> None:
        """After an accepted step: IPC's update of kappa from the distance's trend."""
        x = self._update()
        if self.cfg["stiffness"] != "adaptive" or self.comm.rank != 0:
            return
        d = self._min_distance(x)
        if np.isfinite(d) and np.isfinite(self._distance):
            self.kappa_floor = ipctk.update_barrier_stiffness(
                self._distance, d, self.kappa_max, self.kappa_floor, self.diagonal,
                dmin=self.offset)

    def _check_rest(self, x: np.ndarray, names: list[str]) -> str | None:
        """Rank 0: no surfaces cross, no two bodies within d_hat at rest (None: fine).

        Pairs of one body within d_hat are legal (a thin part): the barrier is finite there.
        """
        self.collisions.build(self.mesh, x, self.dhat, self.offset)
        ids = [c.vertex_ids(self.mesh.edges, self.mesh.faces) for c in self.collisions]
        pairs = {tuple(sorted({int(self.vertex_body[v]) for v in vs if v >= 0})) for vs in ids}
        between = sorted(p for p in pairs if len(p) == 2)
        if ipctk.has_intersections(self.mesh, x):
            if between:
                a, b = between[0]
                return (f"at rest, bodies {names[a]!r} and {names[b]!r} intersect; move them "
                        "apart (body offset)")
            return "at rest, the bodies' surfaces intersect (a mesh crosses itself)"
        if self.offset > 0 and len(self.collisions) and \
                self.collisions.compute_minimum_distance(self.mesh, x) <= self.offset:
            d = self.collisions.compute_minimum_distance(self.mesh, x)
            return (f"at rest, two non-adjacent elements of a shell are {d:.3g} m apart, not "
                    f"more than its thickness {self.offset} m (the contact offset); make the "
                    "shell thinner or its elements larger")
        if between:
            a, b = between[0]
            return (f"at rest, bodies {names[a]!r} and {names[b]!r} are closer than "
                    f"contact.dhat = {self.dhat} m; move them apart (body offset) or reduce "
                    "contact.dhat")
        return None
