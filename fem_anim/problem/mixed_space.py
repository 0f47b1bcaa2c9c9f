"""The Taylor-Hood (u, p) unknown of the mixed formulation, bound to DOLFINx and PETSc.

With ``element.formulation = "mixed"`` the unknown of a step is ``w = (u, p~)`` in the
mixed space P_k^d x P_{k-1} (Taylor-Hood for k = 2), ``p~ = p / mu`` the pressure in units
of the shear modulus (so that both blocks of the saddle-point Hessian scale like ``mu``).
The energy is :func:`fem_anim.forms.incompressible.lagrangian`;
:mod:`fem_anim.problem.energy_terms` builds the forms. This module holds what the
displacement-only problem has no use for:

* :class:`MixedFields`: the mixed space, the maps between its dofs and those of the
  collapsed displacement and pressure spaces (everything time stepping keeps -- predictor,
  velocity, frames -- lives on the displacement space ``V`` as before; the pressure has no
  inertia and no history), the Dirichlet conditions of the pins on the displacement
  sub-space, and the index sets of the two fields (owned dofs, global numbering) for a
  PETSc fieldsplit preconditioner;
* :class:`SchurPreconditioner`: the matrix that stands in for the Schur complement
  ``S = C - B A^-1 B^T`` of the Hessian ``[[A, B^T], [B, C]]`` in the ``schur`` preset: for
  elasticity ``B A^-1 B^T ~ M_p / mu`` (the pressure mass over the shear modulus) and
  ``C = -w/kappa M_p``, so with the scaled pressure (a factor mu^2 on the pressure block)

      S ~ -w mu (1 + mu / kappa) M_p,   M_p = int p~ q~ dX,

  ``w`` the energy weight of the step. Under time stepping the inertia in ``A`` makes the
  true ``S`` smaller than this for small ``h`` (the pressure-mass preconditioner is the
  quasi-static one; Cahouet-Chabard would add the inertia) -- it stays a good
  preconditioner when ``w K`` dominates ``M``, i.e. for the stiff, large steps where a
  mixed formulation matters.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim import compat

__all__ = ["MixedFields", "SchurPreconditioner"]


class MixedFields:
    """The unknown ``w = (u, p~)`` of a mixed step and its sub-spaces.

    Args:
        mesh: The DOLFINx mesh.
        degree: Displacement degree k; the pressure has degree k - 1.
    """

    def __init__(self, mesh, degree: int):
        self.W = compat.mixed_space(mesh, degree, degree - 1)
        self.V, self.u_dofs = compat.collapse_subspace(self.W, 0)
        self.Q, self.p_dofs = compat.collapse_subspace(self.W, 1)
        self.w = fem.Function(self.W, name="displacement_pressure")
        self.u, self.p = ufl.split(self.w)
        self.block = self.V.dofmap.index_map_bs
        self._block = fem.Function(self.V)  # displacement_part's result

    def scatter(self, u: fem.Function, p: fem.Function) -> None:
        """Copy the two fields of :attr:`w` (owned and ghost values) into ``u`` and ``p``."""
        u.x.array[:] = self.w.x.array[self.u_dofs]
        p.x.array[:] = self.w.x.array[self.p_dofs]

    def displacement_part(self, y: PETSc.Vec) -> PETSc.Vec:
        """The displacement block of a vector ``y`` of the mixed space, as a vector of ``V``
        (owned values copied, ghosts updated from their owners, so the ghost entries of
        ``y`` need not be current; collective). The result is overwritten by the next call.
        """
        with y.localForm() as local:
            self._block.x.array[:] = local.array_r[self.u_dofs]
        vec = compat.petsc_vec(self._block)
        vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return vec

    def set_displacement(self, u: np.ndarray) -> None:
        """Put displacement values (local dofs of ``V``) into :attr:`w`; the pressure stays."""
        self.w.x.array[self.u_dofs] = u

    def dirichletbc(self, value: fem.Function, blocks: np.ndarray):
        """Prescribe ``u = value`` (a Function on ``V``) at the nodes ``blocks`` of ``V``."""
        unrolled = (blocks[:, None] * self.block + np.arange(self.block)).ravel()
        dofs = [self.u_dofs[unrolled], unrolled.astype(np.int32)]
        return fem.dirichletbc(value, dofs, self.W.sub(0))

    def index_sets(self) -> tuple[PETSc.IS, PETSc.IS]:
        """Global indices of the owned displacement and pressure dofs of ``w``."""
        index_map = self.W.dofmap.index_map
        n_owned = index_map.size_local * self.W.dofmap.index_map_bs
        start = index_map.local_range[0] * self.W.dofmap.index_map_bs
        comm = self.W.mesh.comm
        sets = []
        for dofs in (self.u_dofs, self.p_dofs):
            owned = np.sort(dofs[dofs < n_owned]).astype(PETSc.IntType) + start
            sets.append(PETSc.IS().createGeneral(owned, comm=comm))
        return sets[0], sets[1]


class SchurPreconditioner:
    """``-w mu (1 + mu/kappa) M_p`` for ``PCFieldSplitSetSchurPre(USER)`` (module docstring).

    Args:
        fields: The mixed unknown.
        mass_form: Compiled ``int p~ q~ dX`` on the mixed space (zero displacement rows).
        scale: ``mu (1 + mu / kappa)``.
    """

    def __init__(self, fields: MixedFields, mass_form, scale: float):
        self.fields = fields
        self.is_u, self.is_p = fields.index_sets()
        full = fem_petsc.assemble_matrix(mass_form)
        full.assemble()
        self.mass = full.createSubMatrix(self.is_p, self.is_p)
        full.destroy()
        self.matrix = self.mass.duplicate(copy=True)
        self.scale = scale

    def update(self, weight: float) -> None:
        """Rescale for the energy weight ``w`` of the current step."""
        self.mass.copy(self.matrix)
        self.matrix.scale(-weight * self.scale)

    def configure(self, pc: PETSc.PC) -> None:
        """Name the fields ``u`` and ``p`` and hand the Schur preconditioner matrix to a
        ``fieldsplit`` PC (``-pc_fieldsplit_schur_precondition user``)."""
        pc.setFieldSplitIS(("u", self.is_u), ("p", self.is_p))
        compat.set_schur_user_matrix(pc, self.matrix)

    def destroy(self) -> None:
        """Free the PETSc matrices and index sets."""
        for obj in (self.mass, self.matrix, self.is_u, self.is_p):
            obj.destroy()
