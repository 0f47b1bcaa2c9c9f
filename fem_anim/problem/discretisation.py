"""The discrete setting of the step objective: function spaces, the state's functions,
material constants and the integration measures.

The unknown is the displacement u = x - X (x deformed, X rest positions) in the vector P_k
space V, or, with ``element.formulation = "mixed"`` (:mod:`fem_anim.problem.mixed_space`),
w = (u, p / mu) in the Taylor-Hood space P2 x P1, whose u and p are copied into the
displacement Functions ``u`` and ``p``. The elastic term is integrated at the
scene's ``element.quadrature_degree``, by default :func:`default_quadrature_degree`, raised
for the mixed formulation to 1 + d (k - 1) so that int q (J - 1) dX is exact (the total
volume is then kept up to the solver tolerance). The inertia term uses the consistent or the
lumped (vertex-rule) mass (:func:`fem_anim.forms.inertia.mass_measure`); gravity shares its
measure.

:class:`Discretisation` is a part of :class:`~fem_anim.problem.objective.EnergyProblem`.
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import fem
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.forms import inertia as inertia_forms
from fem_anim.forms.incompressible import MIXED_MATERIALS, compliance
from fem_anim.forms.lame import lame_parameters
from fem_anim.forms.material import get_material
from fem_anim.forms.time_schemes import SCHEMES
from fem_anim.mesh.bodies import body_regions
from fem_anim.problem.mixed_space import MixedFields
from fem_anim.problem.shell_terms import ShellEnergy, shell_measures, shell_thickness
from fem_anim.problem.wind_terms import WindDrag

__all__ = ["Discretisation", "default_quadrature_degree"]


def default_quadrature_degree(degree: int) -> int:
    """Quadrature degree of the elastic term: exact for P1 (constant F), 2(k-1) for P_k."""
    return max(1, 2 * (degree - 1))


class Discretisation:
    """Spaces, functions, constants and measures of one scene's step objective."""

    def _spaces(self) -> None:
        """The quadrature degree, the scheme, the unknown's space and the state's functions
        (``u``, ``u_pred``, ``u_prev``, ``v``, ``u_bc``, ``u_anchor``)."""
        scene, mesh = self.scene, self.domain.mesh
        self.comm: MPI.Comm = mesh.comm
        #: the displacement's dimension: the mesh's (a shell's surface: 3, its cells' 2)
        self.d = d = mesh.geometry.dim
        degree = scene["element"]["degree"]
        self.quadrature_degree = scene["element"]["quadrature_degree"]
        if self.quadrature_degree is None:
            self.quadrature_degree = default_quadrature_degree(degree)
            if scene["element"].get("formulation") == "mixed":
                # int q (J - 1) exact for P_{k-1} q: the total volume is kept exactly
                self.quadrature_degree = max(self.quadrature_degree, 1 + d * (degree - 1))
        self.scheme = SCHEMES[scene["time"]["integrator"]]
        self.material_map = None
        #: element.formulation = "mixed": the unknown is w = (u, p~), a saddle point; u and
        #: v stay displacement Functions, kept equal to w's first field
        self.mixed = scene["element"].get("formulation", "displacement") == "mixed"
        self.saddle_point = self.mixed
        self.fields = MixedFields(mesh, degree) if self.mixed else None
        self.schur = None
        # the displacement model (None for mixed: its energy is the mixed Lagrangian)
        self.material = None if self.mixed else get_material(scene["material"]["model"])

        V = self.V = self.fields.V if self.mixed else compat.vector_space(mesh, degree)
        self.u = fem.Function(V, name="displacement")
        self.u_pred = fem.Function(V, name="predictor")
        self.u_prev = fem.Function(V, name="previous_displacement")
        self.v = fem.Function(V, name="velocity")
        self.u_bc = fem.Function(V, name="pinned_displacement")
        self.u_anchor = fem.Function(V, name="damping_anchor")

    def _constants(self) -> None:
        """mu, lambda, rho (Pa, Pa, kg/m^3), the weight w and the damping coefficient c
        (staged per step), and the mixed formulation's compliance 1/kappa and pressure."""
        mesh, mat = self.domain.mesh, self.scene["material"]
        if self.mixed and mat["poisson_ratio"] == 0.5:  # lmbda = inf is never formed
            mu, lmbda = mat["youngs_modulus"] / 3.0, np.inf
        else:
            mu, lmbda = lame_parameters(mat["youngs_modulus"], mat["poisson_ratio"])
        self.mu = fem.Constant(mesh, PETSc.ScalarType(mu))
        self.lmbda = fem.Constant(mesh, PETSc.ScalarType(lmbda))
        #: a shell's rho is its area density rho t (kg/m^2; fem_anim.problem.shell_terms)
        self.rho = fem.Constant(mesh, PETSc.ScalarType(mat["density"] * shell_thickness(
            self.scene)))
        self.weight = fem.Constant(mesh, PETSc.ScalarType(0.0))
        self.damping_coefficient = fem.Constant(mesh, PETSc.ScalarType(0.0))
        if self.mixed:
            self.mixed_material = MIXED_MATERIALS[mat["model"]]
            self.inv_kappa = fem.Constant(mesh, PETSc.ScalarType(compliance(
                self.mixed_material, mat["youngs_modulus"], mat["poisson_ratio"], self.d)))
            self.mooney_ratio = fem.Constant(mesh, PETSc.ScalarType(mat["mooney_ratio"]))
            self.p = fem.Function(self.fields.Q, name="pressure")  # p / mu, dimensionless

    def _measures(self) -> None:
        """The elastic measure(s) (one per material model in use: regions and bodies), the
        per-cell space ``W0``, and the mass and load measures."""
        scene, mesh = self.scene, self.domain.mesh
        dx = ufl.Measure("dx", domain=mesh)
        self.dx_elastic = dx(metadata={"quadrature_degree": self.quadrature_degree})
        #: (material, measure) of each elastic integral: one per model in use
        self.elastic_terms = [] if self.mixed else [(self.material, self.dx_elastic)]
        self.W0 = compat.cell_space(mesh)  # per-cell data: region parameters, energy density
        self.bodies = scene.get("body") or []
        # a mixed scene's bodies share one material (fem_anim.scene.consistency): constants
        if (scene.get("region") or self.bodies) and not self.mixed:
            self._regions(body_regions(scene) if self.bodies else None)
        self.dx_mass = inertia_forms.mass_measure(dx, scene["element"]["degree"],
                                                  scene["material"]["mass"] == "lumped")
        # Gravity shares the inertia measure: exact either way (linear integrand; for lumped
        # P1 the vertex rule gives exactly sum_i m_i g.u_i). Integrating it at a lower degree
        # in the same form as the inertia term miscompiles under FFCx 0.5 (the compiled sum
        # differs from the sum of the separately compiled terms; tests/test_mass_and_terms.py).
        self.dx_load = self.dx_mass
        self.shell = None  # a shell's membrane and bending energy (fem_anim.problem.shell_terms)
        if "shell" in scene.data:
            self.shell = ShellEnergy.from_scene(scene, mesh, self.mu, self.lmbda)
            # the membrane's integrand is constant per cell: any rule is exact, and sharing
            # the mass measure's keeps one rule per kernel (two rules in one kernel
            # redefine the Jacobian under FFCx 0.5)
            _, self.dS_shell = shell_measures(mesh, scene["element"]["degree"])
            self.dx_shell = self.dx_mass
            self.elastic_terms = []
        #: ``[wind]``: a shell's aerodynamic drag (fem_anim.problem.wind_terms)
        self.wind = WindDrag.from_scene(scene, mesh) if "wind" in scene.data else None
