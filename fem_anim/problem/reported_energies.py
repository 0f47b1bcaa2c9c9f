"""The energies reported per step: kinetic, elastic, gravitational and contact energy of
the current state, and the per-cell strain energy density of the frames (seed section 4.4).

:class:`ReportedEnergies` is a part of :class:`~fem_anim.problem.objective.EnergyProblem`:
it assembles the problem's compiled ``energy_forms`` and ``cell_elastic_form``.
"""

from __future__ import annotations

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.mesh.checks import cell_volumes
from fem_anim.problem.events import EVENTS

__all__ = ["ReportedEnergies"]


class ReportedEnergies:
    """The energies of the current state, as reported per step and per frame."""

    def energies(self) -> dict[str, float]:
        """Kinetic, elastic, gravitational and contact energy (J) of the current (u, v)
        state and their sum ``total_energy`` (collective)."""
        EVENTS["energies"].begin()
        self.update_quadrature_data()
        values = {name: self.assemble_scalar(form) for name, form in self.energy_forms.items()}
        EVENTS["energies"].end()
        values.setdefault("gravity", 0.0)
        values.setdefault("contact", 0.0)
        if self.ipc is not None:
            values["contact"] += self.ipc.energy(friction=False)  # stored, not dissipated
        values["total_energy"] = values["kinetic"] + values["elastic"] + values["gravity"] + \
            values["contact"]
        return values

    def cell_energy_density(self, u: np.ndarray) -> np.ndarray:
        """Mean strain energy density of each owned cell, 1/|K| int_K psi(F(u)) dX (J/m^3).

        The DG0 projection of the material's psi (seed section 4.4), integrated with the
        elastic quadrature rule, so sum_K |K| psi_K is the elastic energy exactly. Owned
        cells in local order; local work only (each cell's integral is complete on its
        owner), but the caller gathers collectively.

        Args:
            u: Displacement dof values (m), ghosts included (a
                :class:`~fem_anim.simulation.integrators.State`'s ``u``).
        """
        self.u.x.array[:] = u
        self.update_quadrature_data()
        num_owned = self.domain.mesh.topology.index_map(self.domain.mesh.topology.dim).size_local
        cell_dofs = compat.cell_dofs(self.W0)[:num_owned, 0]
        if self._cell_volumes is None:
            mesh = self.domain.mesh
            self._cell_volumes = np.abs(cell_volumes(
                mesh.geometry.x[:, : self.d], compat.geometry_dofmap(mesh)[:num_owned]))
        energy = fem_petsc.assemble_vector(self.cell_elastic_form)
        # a shell's hinge energy, shared by an edge's two cells, also lands on ghost cells
        energy.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        values = energy.array[cell_dofs] / self._cell_volumes
        energy.destroy()
        return values
