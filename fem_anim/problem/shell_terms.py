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
thickness integrated out). With the hinge everything is P1: the membrane strain is constant
per triangle and the hinge terms per edge, so one quadrature point is exact for both.

``bending_model = "kirchhoff_love"`` (P2 displacement) replaces the hinge by the C0
interior-penalty energy of :mod:`fem_anim.forms.shell_kirchhoff_love`: Koiter's density
``psi_b(B)`` over the cells (part of :meth:`ShellEnergy.density`) and the symmetric Nitsche
terms on the interior edges, ``bending`` then being the flexural rigidity ``D``; a clamped
boundary edge adds :meth:`ShellEnergy.clamp_energy` over its exterior-facet measure.
"""

from __future__ import annotations

from dataclasses import dataclass

import ufl
from dolfinx import fem
from petsc4py import PETSc
from ufl.geometry import FacetJacobian

from fem_anim.forms import shell_bending, shell_kirchhoff_love, shell_membrane

__all__ = ["BENDING_MODELS", "ShellEnergy", "shell_measures", "shell_thickness"]

#: ``shell.bending_model``: the P1 hinge or the P2 Kirchhoff-Love interior-penalty energy.
BENDING_MODELS = ("hinge", "kirchhoff_love")


def shell_thickness(scene) -> float:
    """The scene's ``shell.thickness`` (m), or 1 for a solid (its density stays per volume)."""
    return float(scene["shell"]["thickness"]) if "shell" in scene.data else 1.0


def shell_measures(mesh, degree: int = 1) -> tuple[ufl.Measure, ufl.Measure]:
    """The cell and interior-edge measures of a shell's energies (P1: one point each; P2:
    the degree-2 rules, three points per cell and two per edge).

    Args:
        mesh: The DOLFINx surface mesh.
        degree: The displacement's Lagrange degree.

    Returns:
        ``(dx, dS)``.
    """
    metadata = {"quadrature_degree": 0 if degree == 1 else 2}
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
        bending: Hinge stiffness ``k`` (J), or with ``bending_model = "kirchhoff_love"``
            the flexural rigidity ``D`` (J); 0 for a membrane (cloth without bending).
        bending_model: A key of :data:`BENDING_MODELS`.
        poisson_ratio: Poisson's ratio of the Kirchhoff-Love bending density.
    """

    model: str
    mu: object
    lmbda: object
    thickness: object
    bending: object
    bending_model: str = "hinge"
    poisson_ratio: object = 0.0

    @classmethod
    def from_scene(cls, scene, mesh, mu, lmbda) -> ShellEnergy:
        """The shell of a scene's ``[material]`` and ``[shell]`` (``bending = "derived"``:
        :func:`fem_anim.forms.shell_bending.hinge_stiffness` of E, nu and t for the hinge,
        :func:`~fem_anim.forms.shell_bending.flexural_rigidity` for Kirchhoff-Love).

        Args:
            scene: A validated scene with a ``[shell]`` table.
            mesh: Its surface mesh.
            mu: The shear modulus (a DOLFINx Constant, Pa).
            lmbda: The first Lame parameter (a DOLFINx Constant, Pa).
        """
        mat, cfg = scene["material"], scene["shell"]
        t = float(cfg["thickness"])
        k, model, nu = cfg["bending"], cfg["bending_model"], mat["poisson_ratio"]
        if k == "derived":
            rule = shell_bending.flexural_rigidity if model == "kirchhoff_love" \
                else shell_bending.hinge_stiffness
            k = rule(mat["youngs_modulus"], nu, t)
        return cls(mat["model"], mu, lmbda, fem.Constant(mesh, PETSc.ScalarType(t)),
                   fem.Constant(mesh, PETSc.ScalarType(k)), model,
                   fem.Constant(mesh, PETSc.ScalarType(nu)))

    @property
    def kirchhoff_love(self) -> bool:
        """The bending is the P2 Kirchhoff-Love energy (not the hinge)."""
        return self.bending_model == "kirchhoff_love"

    def _bends(self) -> bool:
        return not (isinstance(self.bending, (int, float)) and self.bending == 0)

    def density(self, u) -> ufl.core.expr.Expr:
        """The cells' energy per rest area (J/m^2): the membrane's ``t psi(F(u))``, plus
        Koiter's bending density ``psi_b(B(u))`` with the Kirchhoff-Love bending."""
        J = ufl.Jacobian(u.function_space.mesh.ufl_domain())
        F = shell_membrane.surface_deformation_gradient(u, J)
        psi = self.thickness * shell_membrane.membrane_psi(self.model, F, self.mu, self.lmbda)
        if self.kirchhoff_love and self._bends():
            n = shell_bending.unit_normal(shell_membrane.tangent_map(u, J))
            B = shell_kirchhoff_love.curvature_change(ufl.grad(ufl.grad(u)), n)
            psi = psi + shell_kirchhoff_love.kl_psi(B, self.bending, self.poisson_ratio)
        return psi

    def membrane(self, u, dx: ufl.Measure) -> ufl.Form:
        """``int t psi(F(u)) dA`` (J); with the Kirchhoff-Love bending its cell part
        ``int psi_b dA`` too (:meth:`density`)."""
        return self.density(u) * dx

    def bending_energy(self, u, dS: ufl.Measure, q=None) -> ufl.Form:
        """The bending energy over the interior edges (J): the hinge energy, or the
        Kirchhoff-Love interior-penalty terms; with a cell test function ``q``, each edge's
        energy shared equally by its two triangles (``q`` averaged)."""
        weight = 1.0 if q is None else (q("+") + q("-")) / 2
        if self.kirchhoff_love:
            return self._kl_edges(u) * weight * dS
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
        return shell_bending.hinge_density(theta, theta_rest, self.bending, length,
                                           area("+") + area("-")) * weight * dS

    @staticmethod
    def _area_and_length(u):
        """The rest triangle's area and the rest edge's length (UFL, cell and facet)."""
        domain = u.function_space.mesh.ufl_domain()
        J, edge = ufl.Jacobian(domain), FacetJacobian(domain)[:, 0]
        cross = ufl.cross(J[:, 0], J[:, 1])
        return J, ufl.sqrt(ufl.dot(cross, cross)) / 2, ufl.sqrt(ufl.dot(edge, edge))

    def _kl_edges(self, u) -> ufl.core.expr.Expr:
        """The interior edges' Kirchhoff-Love density, ``h_e = (A+ + A-) / |e|``."""
        J, area, length = self._area_and_length(u)
        conormal = ufl.FacetNormal(u.function_space.mesh.ufl_domain())
        return shell_kirchhoff_love.edge_density(
            u, J, conormal, self.bending, self.poisson_ratio,
            (area("+") + area("-")) / length("+"))

    def clamp_energy(self, u, ds: ufl.Measure) -> ufl.Form:
        """The Kirchhoff-Love clamp over boundary edges (J): ``ds`` the exterior-facet
        measure of the clamped edges (whose displacement is also held), ``h = 2 A / |e|``.

        Raises:
            ValueError: with the hinge bending (a hinge clamps by a pinned row of cells).
        """
        if not self.kirchhoff_love:
            raise ValueError("clamp_energy needs bending_model = \"kirchhoff_love\"")
        J, area, length = self._area_and_length(u)
        conormal = ufl.FacetNormal(u.function_space.mesh.ufl_domain())
        return shell_kirchhoff_love.clamp_density(
            u, J, conormal, self.bending, self.poisson_ratio, 2 * area / length) * ds

    def energy(self, u, dx: ufl.Measure, dS: ufl.Measure) -> ufl.Form:
        """Membrane plus bending energy (J); the membrane alone when ``bending`` is the
        number 0."""
        if not self._bends():
            return self.membrane(u, dx)
        return self.membrane(u, dx) + self.bending_energy(u, dS)

    def cell_energy(self, u, q, dx: ufl.Measure, dS: ufl.Measure) -> ufl.Form:
        """Each cell's elastic energy (a vector form of the cell test function ``q``): its
        membrane energy and half the hinge energy of each of its interior edges."""
        if not self._bends():
            return self.density(u) * q * dx
        return self.density(u) * q * dx + self.bending_energy(u, dS, q)
