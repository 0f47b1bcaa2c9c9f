r"""IPC's lagged friction on one rank's local contact mesh (Li et al. 2020, section 5).

Friction enters the step objective g(x) (seed eq. 4) as a dissipation potential whose normal
forces and tangent bases are taken at the step's start x_n ("lagged"):

.. math::

    D(x) = \sum_k \mu \lambda_k f_0(\|T_k^T (x - x_n)\|),

with :math:`\lambda_k` the pair's barrier force :math:`\kappa |\partial B_k / \partial d|`
(area-weighted, in N), :math:`T_k` its tangent basis, and :math:`f_0` Coulomb's law smoothed
over a slip of :math:`\epsilon_v h` (ipctk's ``FrictionPotential``). D is a function of x
alone within a step, so the step stays a minimisation.

:class:`LaggedFriction` holds one step's lagged pairs on the local mesh they were built on
(a rank's facets and halo, :mod:`fem_anim.contact.distribution`); the caller,
:class:`fem_anim.contact.ipc.IPCContact`, fetches positions on that mesh and sends rows to
their owners. The adjoint (:meth:`LaggedFriction.adjoint`) differentiates the lagged normal
forces and tangent bases too, so gradients through friction are exact.
"""

from __future__ import annotations

import ipctk
import numpy as np

__all__ = ["LaggedFriction"]


class LaggedFriction:
    """One step's friction potential D, lagged at x_n, on a local contact mesh.

    Args:
        halo: The local mesh (``.mesh``: an ``ipctk.CollisionMesh``) the pairs live on; kept
            if the contact's halo is rebuilt within the step.
        x: Its vertices' positions at x_n.
        collisions: The barrier's pairs at x_n on that mesh.
        dhat: The barrier's activation distance (m).
        kappa: The barrier stiffness the normal forces come from (Pa).
        mu: The friction coefficient.
        epsv_h: The slip over which Coulomb's law is smoothed, eps_v h (m).
    """

    def __init__(self, halo, x: np.ndarray, collisions, dhat: float, kappa: float, mu: float,
                 epsv_h: float):
        self.halo = halo
        self.normal = ipctk.BarrierPotential(dhat, kappa, True)
        self.tangential = ipctk.TangentialCollisions()
        self.tangential.build(halo.mesh, x, collisions, self.normal, mu)
        self.potential = ipctk.FrictionPotential(epsv_h)
        self.x_lagged = x.copy()

    def energy(self, x: np.ndarray) -> float:
        """D(x) of this rank's pairs (J), x the positions on :attr:`halo`."""
        return float(self.potential(self.tangential, self.halo.mesh, x - self.x_lagged))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """grad D(x) on the local mesh's vertex components (flat)."""
        return self.potential.gradient(self.tangential, self.halo.mesh, x - self.x_lagged)

    def hessian(self, x: np.ndarray, projection):
        """Hess D(x) on the local mesh (scipy sparse), per pair projected as ``projection``."""
        return self.potential.hessian(self.tangential, self.halo.mesh, x - self.x_lagged,
                                      projection)

    def adjoint(self, lam: np.ndarray, x: np.ndarray) -> np.ndarray:
        """(Hess D + (dF/dx_n)^T) lam on the local mesh: D's exact, unprojected Hessian and
        ipctk's ``force_jacobian`` with respect to the lagged displacements (the normal forces
        and tangent bases taken at x_n), for the adjoint of a step
        (:mod:`fem_anim.adjoint.backward`).

        Args:
            lam: The adjoint variable on the local mesh's vertex components (flat).
            x: The positions on :attr:`halo` at the step's end.
        """
        rest = self.halo.mesh.rest_positions
        slip = x - self.x_lagged
        Hd = self.potential.hessian(self.tangential, self.halo.mesh, slip,
                                    ipctk.PSDProjectionMethod.NONE)
        Jl = self.potential.force_jacobian(
            self.tangential, self.halo.mesh, np.asfortranarray(rest),
            np.asfortranarray(self.x_lagged - rest), np.asfortranarray(slip), self.normal,
            ipctk.TangentialPotential.DiffWRT.LAGGED_DISPLACEMENTS)
        return Hd @ lam + Jl.T @ lam
