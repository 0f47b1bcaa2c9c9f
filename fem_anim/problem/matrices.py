"""The step objective's PETSc matrices and vectors: the Jacobian with its near-nullspace,
the residual vector, a vertex's average mass.

:class:`Matrices` is a part of :class:`~fem_anim.problem.objective.EnergyProblem`: it reads
the problem's compiled ``jacobian_form``, ``residual_form`` and ``mass_form``, its ``V``,
``d``, ``comm``, ``mixed``, ``ipc`` and ``schur``.
"""

from __future__ import annotations

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

__all__ = ["BLOCKED_ASSEMBLY", "GROW_AT_ONCE", "Matrices", "orthonormalize"]

#: Assemble an AIJ Hessian through a d x d block matrix (:meth:`Matrices.assemble_form_matrix`).
BLOCKED_ASSEMBLY = True
#: Widen the Hessian's pattern for new contact entries at once (:meth:`Matrices.grow_pattern`).
GROW_AT_ONCE = True


def orthonormalize(vectors: list[PETSc.Vec]) -> None:
    """Modified Gram-Schmidt on distributed PETSc vectors, in place (collective)."""
    for i, v in enumerate(vectors):
        for w in vectors[:i]:
            v.axpy(-v.dot(w), w)
        v.normalize()


class Matrices:
    """Creating the Jacobian matrix and vectors of the step objective."""

    def create_matrix(self, mat_type: str | None = None) -> PETSc.Mat:
        """The Jacobian matrix, sparsity and preallocation built once (collective).

        It carries the rigid-body modes as near-nullspace, which algebraic multigrid
        (``cg-gamg``) needs for elasticity and every other solver ignores (not for the
        mixed (u, p) unknown). With ``[contact]`` it accepts new nonzeros: contact pairs
        couple dofs the elastic pattern does not.

        Args:
            mat_type: PETSc matrix type; ``"baij"`` stores d x d blocks (one insertion per
                vertex pair), which PETSc's and MUMPS's Cholesky and GAMG reject (LU, ILU,
                ICC, Jacobi, SOR and hypre accept it). None: DOLFINx's default (AIJ).
        """
        A = fem_petsc.create_matrix(self.jacobian_form, mat_type)
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        if self.ipc is not None:  # contact pairs couple dofs the elastic pattern does not
            A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        if not self.mixed:  # the modes of the displacement block only: not set for (u, p)
            A.setNearNullSpace(self.rigid_body_modes())
        return A

    def assemble_form_matrix(self, A: PETSc.Mat, form) -> None:
        """Add the Hessian form ``form`` (pins as identity rows) into the zeroed matrix ``A``
        (collective); ``A`` is left assembled for adding (flushed or final). A matrix
        never assembled is filled by a direct assembly first (its pattern).

        For an AIJ ``A`` of a vector unknown the form is assembled into a d x d block
        (BAIJ) matrix of the form's own pattern (:data:`BLOCKED_ASSEMBLY`) and added to
        ``A`` row by row (``MatAXPY`` with ``SUBSET_NONZERO_PATTERN``): DOLFINx inserts a
        tetrahedron's 12 x 12 element matrix as 16 blocks instead of 144 entries, each
        found by a search in its row, and the copy walks each row once. ``A``'s entries
        are the same numbers, bit for bit, as a direct assembly (each a sum in the same
        cell order, then added to a zero; under MPI the contributions of other ranks' cells
        arrive in another order, so a few entries differ in the last bit) and its pattern
        (contact pairs included) is left as it is, so a factorisation keeps its symbolic
        analysis. A BAIJ ``A``, a scalar unknown (the mixed (u, p)) or
        ``BLOCKED_ASSEMBLY = False`` assemble directly.
        """
        bs = self.V.dofmap.index_map_bs
        if not BLOCKED_ASSEMBLY or self.mixed or bs == 1 or \
                A.getType() not in ("seqaij", "mpiaij"):
            fem_petsc.assemble_matrix(A, form, self.bcs)
            return
        if not A.assembled:
            # a matrix never assembled holds its pattern as preallocation only (DOLFINx
            # 0.9), which an assembly before any insertion squeezes out: fill it once
            fem_petsc.assemble_matrix(A, form, self.bcs)
            A.assemble()
            A.zeroEntries()
        B = self._blocked.get(id(form))
        if B is None:
            B = self._blocked[id(form)] = fem_petsc.create_matrix(form, "baij")
        B.zeroEntries()
        fem_petsc.assemble_matrix(B, form, self.bcs)
        B.assemble()
        A.axpy(1.0, B, PETSc.Mat.Structure.SUBSET_NONZERO_PATTERN)
        self.blocked_assemblies += 1

    def grow_pattern(self, A: PETSc.Mat, rows: np.ndarray, cols: np.ndarray) -> bool:
        """Widen ``A``'s nonzero pattern to hold the entries (rows, cols) (this rank's rows,
        global columns) in one go, before they are added (collective).

        Contact pairs couple dofs the elastic pattern does not, and new pairs keep coming
        within a step. Added one by one, each new entry of a full row makes PETSc
        reallocate the whole matrix (``MatSeqXAIJReallocateAIJ``: a copy of every nonzero);
        here the union of ``A``'s pattern and the new entries is set at once
        (``MatXAIJSetPreallocationCSR``, zero values: call it before assembling ``A``). The
        pattern is the same set of nonzeros either way, so the factorisation is the same
        and its symbolic analysis is redone at the same Newton iterations as before.
        Serial only: on 2 ranks under PETSc 3.22 a run aborted with heap corruption in
        MUMPS's numeric factorisation (likely: an MPI matrix re-preallocated rebuilds its
        diagonal and off-diagonal blocks, whose restarted nonzero states PETSc sums into the
        matrix's, so the new pattern's state can equal an old one and a stale symbolic
        analysis be reused); under MPI the entries are added one by one, as before. Does nothing (False) there, when
        :data:`GROW_AT_ONCE` is False, when ``A`` was never assembled, or without a new
        entry.

        Returns:
            Whether the pattern was widened.
        """
        if not GROW_AT_ONCE or not A.assembled or self.comm.size > 1:
            return False
        n = A.getSize()[1]
        start, end = A.getOwnershipRange()  # (0, n): one rank
        state = (A.handle, A.getInfo()["nz_allocated"])
        if self._pattern is None or self._pattern[0] != state:  # read A's pattern
            indptr, indices, _ = A.getValuesCSR()
            local = np.repeat(np.arange(start, end, dtype=np.int64), np.diff(indptr))
            self._pattern = (state, local * n + indices, indptr.astype(PETSc.IntType),
                             indices.astype(PETSc.IntType))
        _, keys, indptr, columns = self._pattern
        wanted = np.unique(rows.astype(np.int64) * n + cols)
        at = np.searchsorted(keys, wanted)
        missing = wanted[(at == keys.size) | (keys[np.minimum(at, keys.size - 1)] != wanted)] \
            if keys.size else wanted
        if not self.comm.allreduce(missing.size > 0, op=MPI.LOR):
            return False
        at = np.searchsorted(keys, missing)  # each row's columns stay sorted
        keys = np.insert(keys, at, missing)
        columns = np.insert(columns, at, (missing % n).astype(PETSc.IntType))
        added = np.bincount(missing // n - start, minlength=end - start)
        indptr = indptr + np.r_[0, np.cumsum(added)].astype(PETSc.IntType)
        A.setPreallocationCSR((indptr, columns))
        A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        self._pattern = ((A.handle, A.getInfo()["nz_allocated"]), keys, indptr, columns)
        self.pattern_growths += 1
        return True

    def configure_preconditioner(self, pc: PETSc.PC) -> None:
        """Give a ``fieldsplit`` PC the fields of a mixed problem (``schur`` preset)."""
        if self.schur is not None and pc.getType() == "fieldsplit":
            self.schur.configure(pc)

    def rigid_body_modes(self) -> PETSc.NullSpace:
        """Translations and infinitesimal rotations of the body, orthonormalised (collective)."""
        x = self.V.tabulate_dof_coordinates()
        n_owned = self.V.dofmap.index_map.size_local
        x = x[:n_owned, : self.d]
        d = self.d
        modes = []
        for axis in range(d):
            mode = np.zeros((n_owned, d))
            mode[:, axis] = 1.0
            modes.append(mode)
        planes = [(0, 1)] if d == 2 else [(0, 1), (1, 2), (2, 0)]
        for i, j in planes:  # rotation in the (i, j) plane: (-x_j, x_i)
            mode = np.zeros((n_owned, d))
            mode[:, i], mode[:, j] = -x[:, j], x[:, i]
            modes.append(mode)
        vectors = []
        for mode in modes:
            v = self.create_vector()
            v.array[:] = mode.ravel()
            vectors.append(v)
        orthonormalize(vectors)
        return PETSc.NullSpace().create(vectors=vectors, comm=self.comm)

    def create_vector(self) -> PETSc.Vec:
        """A vector of the unknown's layout (the residual's)."""
        return fem_petsc.create_vector(self.residual_form)

    def average_vertex_mass(self) -> float:
        """1^T M 1 / n_dofs: the mass of the body per vertex (kg), M without pins (collective).

        Over d n_vertices dofs, 1^T M 1 = d m_total: the vertex average IPC's adaptive
        stiffness takes (:meth:`fem_anim.contact.ipc.IPCContact.stage`).
        """
        M = fem_petsc.assemble_matrix(self.mass_form)
        M.assemble()
        ones = M.createVecRight()
        ones.set(1.0)
        Mones = ones.duplicate()
        M.mult(ones, Mones)
        average = Mones.sum() / ones.getSize()
        for obj in (ones, Mones, M):
            obj.destroy()
        return average
