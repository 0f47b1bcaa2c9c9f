"""The potential energy of an elastic body under gravity, with its mass matrix and pins.

``E(x) = E_elastic(x) + E_gravity(x)`` (seed eq. (27b) plus ``-int rho g . x``), the force
``f = -grad E`` (seed section 3.1) and the mass matrix ``M`` of seed eq. (19).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from fem_anim.reference.assembly import elastic_energy, elastic_gradient, elastic_hessian
from fem_anim.reference.geometry import check_mesh
from fem_anim.reference.mass import gravity_gradient, mass_matrix
from fem_anim.reference.materials import MATERIALS, lame_parameters

__all__ = ["EnergyProblem", "build_problem"]


@dataclass(frozen=True)
class EnergyProblem:
    """Potential energy ``E = E_elastic + E_gravity`` of a P1 mesh, mass matrix and pinned dofs.

    Attributes:
        points: Reference vertex positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d+1)``.
        material: Material model name, or one per cell ``(n_cells,)``.
        mu: First Lame parameter, scalar or ``(n_cells,)``.
        lmbda: Second Lame parameter, scalar or ``(n_cells,)``.
        mass: Mass matrix ``M`` (consistent or lumped), CSR.
        gravity_force: ``-grad E_gravity = (m_i g)_i``, ``(n_dofs,)``.
        pinned: Boolean mask of the dofs held at their current values, ``(n_dofs,)``.
    """

    points: np.ndarray
    cells: np.ndarray
    material: str | np.ndarray
    mu: float | np.ndarray
    lmbda: float | np.ndarray
    mass: sp.csr_matrix
    gravity_force: np.ndarray
    pinned: np.ndarray

    @property
    def dim(self) -> int:
        """Spatial dimension ``d``."""
        return self.points.shape[1]

    @property
    def free(self) -> np.ndarray:
        """Boolean mask of the unknown (not pinned) dofs."""
        return ~self.pinned

    def energy(self, x: np.ndarray) -> float:
        """``E(x) = E_elastic(x) - f_gravity . x`` (J).

        Args:
            x: Deformed positions, a dof vector (vertex-major).
        """
        elastic = elastic_energy(self.points, self.cells, self.material, self.mu, self.lmbda, x)
        return elastic - float(self.gravity_force @ x)

    def gradient(self, x: np.ndarray) -> np.ndarray:
        """``grad E(x)``, dense ``(n_dofs,)``.

        Args:
            x: Deformed positions, a dof vector.
        """
        elastic = elastic_gradient(self.points, self.cells, self.material, self.mu, self.lmbda, x)
        return elastic - self.gravity_force

    def hessian(self, x: np.ndarray) -> sp.csr_matrix:
        """``hess E(x)`` (gravity is linear, so only the elastic part), sparse CSR.

        Args:
            x: Deformed positions, a dof vector.
        """
        return elastic_hessian(self.points, self.cells, self.material, self.mu, self.lmbda, x)

    def force(self, x: np.ndarray) -> np.ndarray:
        """``f(x) = -grad E(x)``, set to zero on pinned dofs.

        Args:
            x: Deformed positions, a dof vector.
        """
        return np.where(self.pinned, 0.0, -self.gradient(x))

    def accelerate(self, f: np.ndarray) -> np.ndarray:
        """Constrained acceleration ``a`` with ``M_ff a_f = f_f`` and ``a = 0`` on pinned dofs.

        Args:
            f: A force, a dof vector.
        """
        free = self.free
        a = np.zeros_like(f)
        M_ff = self.mass[free][:, free].tocsc()
        a[free] = spla.spsolve(M_ff, f[free])
        return a


def build_problem(
    points: np.ndarray,
    cells: np.ndarray,
    material,
    E,
    nu,
    rho,
    gravity=None,
    pinned: np.ndarray | None = None,
    lumped: bool = False,
) -> EnergyProblem:
    """Validate inputs and build an :class:`EnergyProblem`.

    Args:
        points: Reference vertex positions, ``(n_vertices, d)``.
        cells: Simplices, ``(n_cells, d+1)``.
        material: One of :data:`~fem_anim.reference.materials.MATERIALS`, or one per cell.
        E: Young's modulus, scalar or ``(n_cells,)``.
        nu: Poisson's ratio, scalar or ``(n_cells,)``.
        rho: Density, scalar or ``(n_cells,)``.
        gravity: Gravitational acceleration ``(d,)``; default zero.
        pinned: Boolean mask over dofs; default none pinned.
        lumped: Use the lumped (row-sum) mass matrix.

    Raises:
        ValueError: On an unknown material, bad shapes or out-of-range parameters.
    """
    points, cells = check_mesh(points, cells)
    n_dofs, d = points.size, points.shape[1]
    if not set(np.atleast_1d(material)) <= set(MATERIALS):
        raise ValueError(f"material must be one of {MATERIALS}, got {material!r}")
    mu, lmbda = lame_parameters(E, nu)
    g = np.zeros(d) if gravity is None else np.asarray(gravity, dtype=float)
    if g.shape != (d,):
        raise ValueError(f"gravity must have shape ({d},), got {g.shape}")
    pinned = np.zeros(n_dofs, bool) if pinned is None else np.asarray(pinned, dtype=bool)
    if pinned.shape != (n_dofs,):
        raise ValueError(f"pinned must be a boolean mask of shape ({n_dofs},), got {pinned.shape}")
    return EnergyProblem(
        points=points,
        cells=cells,
        material=material,
        mu=mu,
        lmbda=lmbda,
        mass=mass_matrix(points, cells, rho, lumped=lumped),
        gravity_force=-gravity_gradient(points, cells, rho, g),
        pinned=pinned,
    )
