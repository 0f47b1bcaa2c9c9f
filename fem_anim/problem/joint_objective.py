"""One step objective over several meshes: a shell and a solid minimised together.

DOLFINx has one cell type per mesh, so a shell (triangles in 3D) and a solid (tetrahedra)
are two meshes, two displacement spaces and two
:class:`~fem_anim.problem.objective.EnergyProblem`\\ s. Their step is still ONE minimisation
(seed eq. 4, section 3.1) over the joint unknown x = (x_s, x_c):

    g(x) = g_s(x_s) + g_c(x_c) + w kappa B(x),

g_s and g_c each part's step objective (inertia, elastic energy, gravity, damping,
obstacles, its pins' Dirichlet rows), B IPC's barrier with lagged friction on the union of
the parts' contact surfaces (:class:`~fem_anim.contact.joint_surface.JointIPCContact`). One
Newton system, one line search whose steps are bounded by one continuous collision
detection over the joint step: contact between the bodies is implicit, never staggered
(docs/notes/shell_solid_coupling.md).

:class:`JointProblem` offers the callbacks :class:`~fem_anim.solver.minimiser.Minimiser`
calls (``objective``, ``residual``, ``jacobian``, ``create_matrix``, ``create_vector``,
``set_state``, ``force_scale``), on vectors of the joint layout
(:class:`~fem_anim.mesh.joint_layout.JointLayout`: each rank's local entries are its owned
entries of each part, concatenated). Each part is assembled by its own callbacks, so its
constant terms, pins and obstacles are the tested single-body code: the joint gradient is
the parts' gradients side by side, the joint Hessian their matrices on the diagonal
(renumbered to the joint layout), and the barrier's terms are added across them.
"""

from __future__ import annotations

import time
from types import SimpleNamespace

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim.contact.joint_surface import JointIPCContact
from fem_anim.mesh.joint_layout import JointLayout
from fem_anim.problem.objective import EnergyProblem

__all__ = ["JointProblem"]


class _JointObstacles:
    """The parts' obstacles (``[[obstacle]]``) as the one ``contact`` the solver bounds
    steps with: the smallest of the parts' bounds and distances."""

    def __init__(self, problem: JointProblem):
        self.problem = problem

    def step_bound(self, y: PETSc.Vec) -> float:
        p = self.problem
        alpha = 1.0
        for k, part in enumerate(p.parts):
            if part.contact is not None:
                p.split(y, p._y_parts, k)
                alpha = min(alpha, part.contact.step_bound(p._y_parts[k]))
        return alpha

    def min_distance(self) -> float:
        return min(part.contact.min_distance() for part in self.problem.parts
                   if part.contact is not None)


class JointProblem:
    """The step objective of several parts (each an EnergyProblem) and the barrier between
    and within their surfaces.

    Building one is collective. The parts must be P1 displacement problems in 3D without a
    ``[contact]`` of their own, staged with one integrator (one weight w).

    Args:
        parts: The parts' problems, e.g. ``[solid, shell]``.
        contact: The validated ``[contact]`` table of the joint barrier (``self`` true).
        offset: The barrier's minimum distance d_min (m): the shell's thickness
            (:mod:`fem_anim.contact.joint_surface`).
        names: The bodies' names by body index (the parts' bodies in order).

    Raises:
        ValueError: a part with its own ``[contact]``, mixed, or not in 3D.
        SceneError: the surfaces cross or are within ``dhat`` at rest.
    """

    saddle_point = False
    filter_inversion = False
    mixed = False
    hessian_filter = None

    def __init__(self, parts: list[EnergyProblem], contact: dict, offset: float,
                 names: list[str]):
        for part in parts:
            if part.ipc is not None or part.mixed or part.d != 3:
                raise ValueError("each part of a joint problem is a 3D displacement problem "
                                 "without a [contact] of its own")
        self.parts = parts
        self.comm = parts[0].comm
        self.layout = layout = JointLayout(self.comm, [p.V for p in parts])
        self.weight = parts[0].weight  # w: every part is staged with the same one
        # every part's bodies, numbered in order
        bodies, first = [], 0
        for part in parts:
            bodies.append(part.cell_body + first)
            first += max(len(part.bodies), 1)
        pinned = [np.concatenate([bc.dof_indices()[0] for bc in p.displacement_bcs] +
                                 [np.empty(0, np.int32)]) for p in parts]
        self.ipc = JointIPCContact(contact, layout, [p.u for p in parts], pinned, bodies,
                                   names, offset)
        self.contact = _JointObstacles(self) if any(p.contact is not None for p in parts) \
            else None
        #: not None when every part has its constant terms split off (the "step" test's
        #: force check needs them)
        self.constant_terms = parts if all(p.constant_terms is not None for p in parts) \
            else None
        # the pinned rows of the joint local array (the barrier's rows are dropped there)
        self._pinned_rows = np.concatenate(
            [layout.offsets[k] + rows[rows < layout.bs * layout.owned[k]]
             for k, rows in enumerate(pinned)]).astype(np.int64)
        self._x_parts = [p.create_vector() for p in parts]
        self._b_parts = [p.create_vector() for p in parts]
        self._y_parts = [p.create_vector() for p in parts]
        self._A_parts = [p.create_matrix() for p in parts]
        self._own_assembly_s = 0.0
        self.step_size = 0.0
        points = np.concatenate([p.domain.mesh.geometry.x[:, :3] for p in parts])
        #: the parts' points together (the stopping test's scene size reads them)
        self.domain = SimpleNamespace(mesh=SimpleNamespace(geometry=SimpleNamespace(
            x=points, dim=3)))
        self.average_mass = self._average_vertex_mass()

    # -- layout ---------------------------------------------------------------------------
    def create_vector(self) -> PETSc.Vec:
        """A vector of the joint layout (the residual's): ghosted with no ghosts, as the
        solver updates the ghosts of its solution (the parts keep their own)."""
        L = self.layout
        return PETSc.Vec().createGhost(np.empty(0, PETSc.IntType),
                                       (L.bs * L.n_owned, L.bs * L.size), bsize=L.bs,
                                       comm=self.comm)

    def split(self, x: PETSc.Vec, into: list[PETSc.Vec], only: int | None = None) -> None:
        """Copy the parts' owned entries of the joint vector ``x`` into their vectors."""
        for k, vec in enumerate(into):
            if only is None or k == only:
                vec.array[:] = x.array_r[self.layout.local_slice(k)]

    def join(self, parts: list[PETSc.Vec], x: PETSc.Vec) -> None:
        """The parts' owned entries into the joint vector ``x``."""
        for k, vec in enumerate(parts):
            x.array[self.layout.local_slice(k)] = vec.array_r

    def joint_array(self, arrays: list[np.ndarray]) -> np.ndarray:
        """The owned entries of per-part local arrays (ghosts included), concatenated."""
        L = self.layout
        return np.concatenate([a[: L.bs * n] for a, n in zip(arrays, L.owned)])

    def create_matrix(self, mat_type: str | None = None) -> PETSc.Mat:
        """The joint Hessian: the parts' sparsity on the diagonal, accepting the barrier's
        new nonzeros (collective).

        Args:
            mat_type: ``"baij"`` stores 3 x 3 blocks (as a one-mesh problem's
                :meth:`~fem_anim.problem.matrices.Matrices.create_matrix`); None or
                ``"aij"``: scalar rows.
        """
        L = self.layout
        b = L.bs if mat_type == "baij" else 1
        n = L.bs * L.n_owned
        rows, cols = [], []
        for k, (part, A) in enumerate(zip(self.parts, self._A_parts)):
            A.zeroEntries()
            fem_petsc.assemble_matrix(A, part.jacobian_form, part.bcs)
            A.assemble()
            r, c, _ = self._part_triplets(k, A)
            rows.append(r)
            cols.append(c)
        # the nonzeros of each (block) row, in the diagonal and off-diagonal parts
        pairs = np.unique(np.stack([np.concatenate(rows) // b, np.concatenate(cols) // b]),
                          axis=1)
        lo, hi = L.bs * L.start // b, L.bs * (L.start + L.n_owned) // b
        local, diag = pairs[0] - lo, (pairs[1] >= lo) & (pairs[1] < hi)
        d_nnz = np.bincount(local[diag], minlength=n // b).astype(PETSc.IntType)
        o_nnz = np.bincount(local[~diag], minlength=n // b).astype(PETSc.IntType)
        size = ((n, L.bs * L.size), (n, L.bs * L.size))
        A = PETSc.Mat().createBAIJ(size, b, nnz=(d_nnz, o_nnz), comm=self.comm) \
            if b > 1 else PETSc.Mat().createAIJ(size, nnz=(d_nnz, o_nnz), comm=self.comm)
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        return A

    def _part_triplets(self, k: int, A: PETSc.Mat):
        """A part's assembled matrix as (joint rows, joint columns, values) of owned rows."""
        indptr, cols, vals = A.getValuesCSR()
        start, _ = A.getOwnershipRange()
        rows = start + np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
        L = self.layout
        return (L.joint_dofs_of_global(k, rows), L.joint_dofs_of_global(k, cols),
                np.array(vals))

    # -- the step -------------------------------------------------------------------------
    def stage(self, u_n: list[np.ndarray], u_pred: list[np.ndarray], weight: float, t: float,
              h: float, damping: list | None = None) -> None:
        """Stage every part (:meth:`EnergyProblem.stage`) and the joint barrier's kappa and
        lagged friction at u_n (collective).

        Args:
            u_n, u_pred: Each part's displacement at the step's start and its predictor
                (m, local dofs of its space, ghosts included).
            weight: The energy weight w (s^2), the same for every part.
            t: Time at the step's end (s).
            h: Step size (s).
            damping: Each part's (c, u_d) if it is damped, else None entries.
        """
        damping = damping or [None] * len(self.parts)
        for part, u0, y, d in zip(self.parts, u_n, u_pred, damping):
            part.stage(u0, y, weight, t, h, d)
        self.step_size = h
        grads = []
        for part, u0 in zip(self.parts, u_n):  # grad E at u_n (IPC's adaptive kappa)
            part.u.x.array[:] = u0
            part.update_quadrature_data()
            f = fem_petsc.assemble_vector(part.potential_gradient_form)
            f.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            grads.append(f.array.copy())
            f.destroy()
        self.ipc.stage(weight, np.concatenate(grads), self.average_mass, h)

    def finish_step(self) -> None:
        """After an accepted step whose solution is set: IPC's stiffness update."""
        self.ipc.finish_step()

    def _average_vertex_mass(self) -> float:
        """The bodies' mass per vertex (kg), for IPC's adaptive stiffness (collective)."""
        total = sum(p.average_vertex_mass() * p.V.dofmap.index_map.size_global * 3
                    for p in self.parts)
        return total / (3 * self.layout.size)

    @property
    def assembly_s(self) -> float:
        """Wall time spent assembling g, its gradient and Hessian (s)."""
        return self._own_assembly_s + sum(p.assembly_s for p in self.parts)

    def set_hessian_filter(self, how) -> None:
        """Only the exact Hessian: ``None`` is accepted, a filter refused."""
        if how is not None:
            raise ValueError("a joint problem assembles the exact Hessian only")

    # -- assembly -------------------------------------------------------------------------
    def set_state(self, x: PETSc.Vec) -> None:
        """Copy the joint iterate into every part's ``u`` (with ghosts)."""
        self.split(x, self._x_parts)
        for part, xp in zip(self.parts, self._x_parts):
            part.set_state(xp)

    def load_guess(self, u: list[np.ndarray], x: PETSc.Vec, apply_bcs: bool = True) -> None:
        """A start into ``x`` from each part's displacement values (local dofs, ghosts)."""
        for part, uk, xp in zip(self.parts, u, self._x_parts):
            part.load_guess(uk, xp, apply_bcs)
        self.join(self._x_parts, x)

    def objective(self, snes, x: PETSc.Vec) -> float:
        """g(x) = sum of the parts' g + w kappa B (collective; +inf at contact)."""
        self.split(x, self._x_parts)
        value = sum(part.objective(snes, xp) for part, xp in zip(self.parts, self._x_parts))
        start = time.perf_counter()
        if np.isfinite(value):
            value += float(self.weight.value) * self.ipc.energy()
        self._own_assembly_s += time.perf_counter() - start
        return value

    def residual(self, snes, x: PETSc.Vec, b: PETSc.Vec) -> None:
        """grad g(x) into ``b``; pinned rows hold x - u_bc (collective)."""
        self.split(x, self._x_parts)
        for part, xp, bp in zip(self.parts, self._x_parts, self._b_parts):
            part.residual(snes, xp, bp)
        self.join(self._b_parts, b)
        start = time.perf_counter()
        barrier = b.duplicate()
        barrier.set(0.0)
        self.ipc.add_gradient(barrier, float(self.weight.value))
        barrier.array[self._pinned_rows] = 0.0
        b.axpy(1.0, barrier)
        barrier.destroy()
        self._own_assembly_s += time.perf_counter() - start

    def jacobian(self, snes, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        """The Hessian of g at x into ``A``: the parts' on the diagonal plus w kappa Hess B
        (IPC's per-pair projection unless exact; pinned rows and columns left out)."""
        self.split(x, self._x_parts)
        A.zeroEntries()
        for k, (part, xp, Ap) in enumerate(zip(self.parts, self._x_parts, self._A_parts)):
            part.jacobian(snes, xp, Ap, Ap)
            start = time.perf_counter()
            rows, cols, vals = self._part_triplets(k, Ap)
            if rows.size:
                unique, first = np.unique(rows, return_index=True)
                indptr = np.r_[first, rows.size].astype(PETSc.IntType)
                A.setValuesIJV(indptr, cols.astype(PETSc.IntType), vals,
                               addv=PETSc.InsertMode.ADD_VALUES,
                               rowmap=unique.astype(PETSc.IntType))
            self._own_assembly_s += time.perf_counter() - start
        start = time.perf_counter()
        A.assemble(PETSc.Mat.AssemblyType.FLUSH)
        self.set_state(x)  # the barrier reads the parts' u
        self.ipc.add_hessian(A, float(self.weight.value))
        A.assemble()
        self._own_assembly_s += time.perf_counter() - start

    def force_scale(self, x: PETSc.Vec) -> float:
        """The largest 2-norm of the terms of grad g at x: the parts' terms
        (:meth:`EnergyProblem.force_scale`) and w grad of the barrier (collective)."""
        self.split(x, self._x_parts)
        sizes = [part.force_scale(xp) for part, xp in zip(self.parts, self._x_parts)]
        self.set_state(x)
        barrier = x.duplicate()
        barrier.set(0.0)
        self.ipc.add_gradient(barrier, float(self.weight.value))
        barrier.array[self._pinned_rows] = 0.0
        sizes.append(barrier.norm())
        barrier.destroy()
        return max(sizes)
