"""The energies of a shell body bound to DOLFINx: membrane over the cells, bending over the
interior edges of a triangle surface in 3D (geometric dimension 3, topological 2).

The unknown is the displacement ``u`` (3 components, P1) of the mid-surface. With the rest
Jacobian ``J = dX/dxi`` of each triangle (``ufl.Jacobian``), :mod:`fem_anim.forms.shell_membrane`
gives the 3x2 ``F = D_s D_m^{-1}`` (seed eq. 26) and the membrane energy

    E_m(u) = int_S t psi(F(u)) dA,

and :mod:`fem_anim.forms.shell_bending` the discrete-shell hinge energy

    E_b(u) = int_{interior edges} 3 k |e| / (A+ + A-) (theta(u) - theta_rest)^2 dS,

with the triangles' normals from ``D_s`` restricted to the two sides of each edge (``'+'``,
``'-'``), the edge vector from the facet Jacobian of the ``'+'`` side, and the ``'-'`` normal
oriented by the sign of the rest normals' dot product (the mesh may orient the two triangles
either way). Mass and gravity use the area density ``rho t`` (seed section 4.1 with the
thickness integrated out). Everything is P1: the membrane strain is constant per triangle
and the hinge terms per edge, so one quadrature point is exact for both.
"""

from __future__ import annotations

from dataclasses import dataclass

import ufl
from dolfinx import fem
from petsc4py import PETSc
from ufl.geometry import FacetJacobian

from fem_anim.forms import shell_bending, shell_membrane

__all__ = ["ShellEnergy", "shell_measures", "shell_thickness"]


def shell_thickness(scene) -> float:
    """The scene's ``shell.thickness`` (m), or 1 for a solid (its density stays per volume)."""
    return float(scene["shell"]["thickness"]) if "shell" in scene.data else 1.0


def shell_measures(mesh) -> tuple[ufl.Measure, ufl.Measure]:
    """The cell and interior-edge measures of a shell's energies (one point each: P1).

    Args:
        mesh: The DOLFINx surface mesh.

    Returns:
        ``(dx, dS)``.
    """
    metadata = {"quadrature_degree": 0}
    return (ufl.Measure("dx", domain=mesh, metadata=metadata),
            ufl.Measure("dS", domain=mesh, metadata=metadata))


@dataclass
class ShellEnergy:
    """The membrane and bending energy of a shell of one material.

    Attributes:
        model: Membrane model, a key of :data:`fem_anim.forms.shell_membrane.MEMBRANE_MODELS`.
        mu: Shear modulus (Pa; a constant or a cell field).
        lmbda: First Lamé parameter of the 3D material (Pa).
        thickness: Shell thickness ``t`` (m).
        bending: Hinge stiffness ``k`` (J); 0 for a membrane (cloth without bending).
    """

    model: str
    mu: object
    lmbda: object
    thickness: object
    bending: object

    @classmethod
    def from_scene(cls, scene, mesh, mu, lmbda) -> ShellEnergy:
        """The shell of a scene's ``[material]`` and ``[shell]`` (``bending = "derived"``:
        :func:`fem_anim.forms.shell_bending.hinge_stiffness` of E, nu and t).

        Args:
            scene: A validated scene with a ``[shell]`` table.
            mesh: Its surface mesh.
            mu: The shear modulus (a DOLFINx Constant, Pa).
            lmbda: The first Lame parameter (a DOLFINx Constant, Pa).
        """
        mat, cfg = scene["material"], scene["shell"]
        t = float(cfg["thickness"])
        k = cfg["bending"]
        if k == "derived":
            k = shell_bending.hinge_stiffness(mat["youngs_modulus"], mat["poisson_ratio"], t)
        return cls(mat["model"], mu, lmbda, fem.Constant(mesh, PETSc.ScalarType(t)),
                   fem.Constant(mesh, PETSc.ScalarType(k)))

    def density(self, u) -> ufl.core.expr.Expr:
        """The membrane energy per rest area ``t psi(F(u))`` (J/m^2)."""
        J = ufl.Jacobian(u.function_space.mesh.ufl_domain())
        F = shell_membrane.surface_deformation_gradient(u, J)
        return self.thickness * shell_membrane.membrane_psi(self.model, F, self.mu, self.lmbda)

    def membrane(self, u, dx: ufl.Measure) -> ufl.Form:
        """``int t psi(F(u)) dA`` (J)."""
        return self.density(u) * dx

    def bending_energy(self, u, dS: ufl.Measure, q=None) -> ufl.Form:
        """The hinge energy over the interior edges (J); with a cell test function ``q``,
        each edge's energy shared equally by its two triangles (``q`` averaged)."""
        domain = u.function_space.mesh.ufl_domain()
        J = ufl.Jacobian(domain)
        edge_rest = FacetJacobian(domain)[:, 0]
        N = shell_bending.unit_normal(J)
        n = shell_bending.unit_normal(shell_membrane.tangent_map(u, J))
        orientation = ufl.sign(ufl.dot(N("+"), N("-")))
        edge = (ufl.Identity(3) + ufl.grad(u)("+")) * edge_rest("+")
        theta = shell_bending.hinge_angle(n("+"), orientation * n("-"), edge)
        theta_rest = shell_bending.hinge_angle(N("+"), orientation * N("-"), edge_rest("+"))
        cross = ufl.cross(J[:, 0], J[:, 1])
        area = ufl.sqrt(ufl.dot(cross, cross)) / 2
        length = ufl.sqrt(ufl.dot(edge_rest("+"), edge_rest("+")))
        weight = 1.0 if q is None else (q("+") + q("-")) / 2
        return shell_bending.hinge_density(theta, theta_rest, self.bending, length,
                                           area("+") + area("-")) * weight * dS

    def energy(self, u, dx: ufl.Measure, dS: ufl.Measure) -> ufl.Form:
        """Membrane plus bending energy (J); the membrane alone when ``bending`` is the
        number 0."""
        if isinstance(self.bending, (int, float)) and self.bending == 0:
            return self.membrane(u, dx)
        return self.membrane(u, dx) + self.bending_energy(u, dS)

    def cell_energy(self, u, q, dx: ufl.Measure, dS: ufl.Measure) -> ufl.Form:
        """Each cell's elastic energy (a vector form of the cell test function ``q``): its
        membrane energy and half the hinge energy of each of its interior edges."""
        return self.density(u) * q * dx + self.bending_energy(u, dS, q)
