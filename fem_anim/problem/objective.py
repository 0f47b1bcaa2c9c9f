"""The step objective bound to DOLFINx: the one module that turns forms into kernels.

:class:`EnergyProblem` composes, from a scene, the UFL step objective

    g(u) = 1/2 ||u - u_pred||_M^2 + w [ int psi(F(u)) dV + E_gravity(u) ]     (seed eq. 4)

(``forms/``: a material's ``psi``, :mod:`forms.inertia`, :mod:`forms.gravity`,
:mod:`forms.integrator`), takes the residual and Jacobian by ``ufl.derivative`` of
that single form (STYLE rule 2), compiles everything once, and offers the assembly
callbacks a PETSc SNES needs (:meth:`objective`, :meth:`residual`, :meth:`jacobian`).
The terms whose Hessian is constant (inertia, Rayleigh damping, gravity) are assembled once
as matrices and a vector from their ``ufl.derivative`` and added by matrix-vector products
(:mod:`fem_anim.problem.constant_terms`); the callbacks assemble w times the rest of E per call.
Only terms the scene declares are built: without ``[gravity]`` there is no gravity
form, without ``[[obstacle]]`` no contact form (:mod:`fem_anim.contact.obstacles`); with ``[[region]]``
entries (:mod:`fem_anim.mesh.regions`) the elastic energy is one integral per material model in
use over its cells, and mu, lambda and rho are piecewise-constant fields instead of
constants. With ``[contact]`` the IPC Toolkit's barrier between surfaces
(:mod:`fem_anim.contact.ipc`) is added to g, its gradient and its Hessian outside UFL (times
w, like every term of E); with ``[[body]]`` the bodies' materials are regions and their pins
hold their own vertices (:mod:`fem_anim.mesh.bodies`). The energies reported per step (kinetic,
elastic, gravity, contact) are separate scalar forms over the same measures.

The unknown is the displacement u = x - X (x deformed, X rest positions); pinned dofs
are Dirichlet conditions whose values live in :attr:`u_bc` (zero for fixed pins).

With ``element.formulation = "mixed"`` (:mod:`fem_anim.problem.mixed_space`) the unknown is instead
w = (u, p / mu) in the Taylor-Hood space P2 x P1, and the elastic term is the perturbed
Lagrangian int psi_dev(F) + p g(J) - p^2 / (2 kappa) of :mod:`fem_anim.forms.incompressible`: the
objective is stationary, not minimal, at the step's solution (the solver then uses no
objective, :mod:`fem_anim.solver.minimiser`). :attr:`u`, the predictor, velocity and the reported
energies stay on the displacement space V; :meth:`set_state` copies w's fields into
:attr:`u` and :attr:`p`. The elastic energy reported is int W(F(u), p) at the solution, the
stored energy of the discrete constrained body. The default quadrature degree is raised
to 1 + d (k - 1) so that int q (J - 1) dX is integrated exactly: with g = J - 1 the total
volume is kept exactly, up to the solver tolerance.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim.forms import damping as damping_forms
from fem_anim.forms import gravity as gravity_forms
from fem_anim.forms import inertia as inertia_forms
from fem_anim.forms.time_schemes import SCHEMES, step_objective
from fem_anim.forms.kinematics import deformation_gradient
from fem_anim.forms.lame import lame_parameters
from fem_anim.forms.material import EXTRA_DATA, get_material
from fem_anim.forms.incompressible import MIXED_MATERIALS, compliance, lagrangian

from fem_anim import compat
from fem_anim.mesh.bodies import body_pins, body_regions
from fem_anim.problem.constant_terms import ConstantTerms, QuadraticTerm
from fem_anim.contact.obstacles import ObstacleContact
from fem_anim.solver.hessian_modification import FILTERS, project_psd
from fem_anim.contact.ipc import IPCContact
from fem_anim.errors import SceneError
from fem_anim.mesh.build import SimplexMesh, cell_volumes
from fem_anim.problem.mixed_space import MixedFields, SchurPreconditioner
from fem_anim.problem.handles import PinMotion
from fem_anim.problem.quadrature import QuadratureData
from fem_anim.mesh.regions import assign_materials, local_cell_markers

__all__ = ["EVENTS", "EnergyProblem", "FILTERED_MODES", "compile_forms",
           "default_quadrature_degree"]

#: ``solver.hessian`` modes that assemble the elastic Hessian from a filtered tangent.
FILTERED_MODES = ("project", "abs", "trust_region_filter", "auto")

JIT_OPTIONS = {"cffi_extra_compile_args": ["-O2", "-march=native"]}

#: PETSc log events of the assembly callbacks (PETSc's own timers: ``-log_view`` lists them,
#: and :mod:`fem_anim.bench.perf` reads them to split a step's time).
EVENTS = {name: PETSc.Log.Event(f"FemAnim{name.capitalize()}")
          for name in ("objective", "residual", "jacobian", "filter", "energies")}


def compile_forms(forms: dict[str, ufl.Form]) -> dict:
    """Compile UFL forms with FFCx into one module, with cache keys that do not depend on history.

    UFL caches a form's signature (its JIT cache key) when first asked. Compiling one form
    changes what UFL computes afterwards for another form built from the same
    expressions (here: the residual, built by ``ufl.derivative`` of the objective), so
    a run with a cold cache and one with a warm cache would name the residual
    differently and recompile it. Taking every signature before compiling anything
    makes the keys those of the forms as built, in every run.
    """
    for form in forms.values():
        form.signature()
    return compat.compile_forms_together(forms, JIT_OPTIONS)


def orthonormalize(vectors: list[PETSc.Vec]) -> None:
    """Modified Gram-Schmidt on distributed PETSc vectors, in place (collective)."""
    for i, v in enumerate(vectors):
        for w in vectors[:i]:
            v.axpy(-v.dot(w), w)
        v.normalize()


def default_quadrature_degree(degree: int) -> int:
    """Quadrature degree of the elastic term: exact for P1 (constant F), 2(k-1) for P_k."""
    return max(1, 2 * (degree - 1))


@dataclass
class EnergyProblem:
    """Forms, functions and assembly callbacks of one scene's step objective."""

    scene: object
    domain: SimplexMesh
    quadrature_degree: int = field(init=False)

    def __post_init__(self) -> None:
        scene, mesh = self.scene, self.domain.mesh
        self.comm: MPI.Comm = mesh.comm
        self.d = d = mesh.topology.dim
        degree = scene["element"]["degree"]
        self.quadrature_degree = scene["element"]["quadrature_degree"]
        if self.quadrature_degree is None:
            self.quadrature_degree = default_quadrature_degree(degree)
            if scene["element"].get("formulation") == "mixed":
                # int q (J - 1) exact for P_{k-1} q: the total volume is kept exactly
                self.quadrature_degree = max(self.quadrature_degree, 1 + d * (degree - 1))
        self.scheme = SCHEMES[scene["time"]["integrator"]]
        self.material_map = None
        #: element.formulation = "mixed": the unknown is w = (u, p~) (fem_anim.problem.mixed_space), a saddle
        #: point; u and v stay displacement Functions, kept equal to w's first field
        self.mixed = scene["element"].get("formulation", "displacement") == "mixed"
        self.saddle_point = self.mixed
        self.fields = MixedFields(mesh, degree) if self.mixed else None
        self.schur = None
        # the displacement model (None for mixed: its energy is forms.mixed's Lagrangian)
        self.material = None if self.mixed else get_material(scene["material"]["model"])

        V = self.V = self.fields.V if self.mixed else compat.vector_space(mesh, degree)
        self.u = fem.Function(V, name="displacement")
        self.u_pred = fem.Function(V, name="predictor")
        self.u_prev = fem.Function(V, name="previous_displacement")
        self.v = fem.Function(V, name="velocity")
        self.u_bc = fem.Function(V, name="pinned_displacement")
        self.u_anchor = fem.Function(V, name="damping_anchor")

        mat = scene["material"]
        if self.mixed and mat["poisson_ratio"] == 0.5:  # lmbda = inf is never formed
            mu, lmbda = mat["youngs_modulus"] / 3.0, np.inf
        else:
            mu, lmbda = lame_parameters(mat["youngs_modulus"], mat["poisson_ratio"])
        self.mu = fem.Constant(mesh, PETSc.ScalarType(mu))
        self.lmbda = fem.Constant(mesh, PETSc.ScalarType(lmbda))
        self.rho = fem.Constant(mesh, PETSc.ScalarType(mat["density"]))
        self.weight = fem.Constant(mesh, PETSc.ScalarType(0.0))
        self.damping_coefficient = fem.Constant(mesh, PETSc.ScalarType(0.0))
        if self.mixed:
            self.mixed_material = MIXED_MATERIALS[mat["model"]]
            self.inv_kappa = fem.Constant(mesh, PETSc.ScalarType(compliance(
                self.mixed_material, mat["youngs_modulus"], mat["poisson_ratio"], d)))
            self.mooney_ratio = fem.Constant(mesh, PETSc.ScalarType(mat["mooney_ratio"]))
            self.p = fem.Function(self.fields.Q, name="pressure")  # p / mu, dimensionless

        dx = ufl.Measure("dx", domain=mesh)
        self.dx_elastic = dx(metadata={"quadrature_degree": self.quadrature_degree})
        #: (material, measure) of each elastic integral: one per model in use
        self.elastic_terms = [] if self.mixed else [(self.material, self.dx_elastic)]
        self.W0 = compat.cell_space(mesh)  # per-cell data: region parameters, energy density
        self.bodies = scene.get("body") or []
        if scene.get("region") or self.bodies:
            self._regions(body_regions(scene) if self.bodies else None)
        self.dx_mass = inertia_forms.mass_measure(dx, degree, mat["mass"] == "lumped")
        # Gravity shares the inertia measure: exact either way (linear integrand; for lumped
        # P1 the vertex rule gives exactly sum_i m_i g.u_i). Integrating it at a lower degree
        # in the same form as the inertia term miscompiles under FFCx 0.5 (the compiled sum
        # differs from the sum of the separately compiled terms; tests/test_mass_and_terms.py).
        self.dx_load = self.dx_mass

        self.quadrature_data: list[QuadratureData] = []
        self._extra: dict = {}  # displacement Function -> the material's quadrature data
        self._quadrature_inputs: list[np.ndarray] | None = None  # their arrays at the refresh
        elastic_u = self._elastic_energy(self.u)
        # the objective's displacement: u itself, or the first field of the mixed unknown
        u_obj = self.u
        if self.mixed:
            elastic_u = self._mixed_energy(self.u, self.p)
            u_obj = self.fields.u
        gravity_u = None
        self.g = None
        if "gravity" in scene.data:
            self.g = fem.Constant(mesh, np.asarray(scene["gravity"]["acceleration"],
                                                   dtype=PETSc.ScalarType))
            gravity_u = gravity_forms.gravity_potential(self.u, self.rho, self.g, self.dx_load)

        self.contact = None  # obstacles: barrier (and friction) terms, forms/obstacle_contact.py
        if scene["obstacle"]:
            self.contact = ObstacleContact(scene["obstacle"], self.u, self.u_prev, degree,
                                           mat["youngs_modulus"])
        potential = potential_u = elastic_u if gravity_u is None else elastic_u + gravity_u
        varying = elastic_u  # the potential's terms whose Hessian changes with u
        if self.contact is not None:
            potential = potential_u = potential_u + self.contact.energy
            varying = varying + self.contact.energy
        if self.scheme.explicit:
            # Symplectic Euler: E linearised at u_prev, grad E(u_prev) . u (forms/time_schemes.py)
            at_prev = self._elastic_energy(self.u_prev)
            if gravity_u is not None:
                at_prev += gravity_forms.gravity_potential(self.u_prev, self.rho, self.g,
                                                           self.dx_load)
            potential = ufl.derivative(at_prev, self.u_prev, self.u)
            if self.contact is not None:  # the barrier stays implicit: it guards d > 0
                potential += self.contact.energy
        if self.mixed:  # the same potential, of the mixed unknown (no contact: refused)
            potential = self._mixed_energy(u_obj, self.fields.p)
            if gravity_u is not None:
                potential += gravity_forms.gravity_potential(u_obj, self.rho, self.g,
                                                             self.dx_load)
        contact_terms = None
        if self.contact is not None:
            contact_terms = self.contact.energy if self.contact.friction is None else \
                self.contact.energy + self.contact.friction
            if self.contact.friction is not None:
                potential += self.contact.friction
                varying += self.contact.friction
        convex = inertia_forms.inertia(u_obj, self.u_pred, self.rho, self.dx_mass)
        unknown = self.fields.w if self.mixed else self.u
        du, dv = ufl.TrialFunction(unknown.function_space), ufl.TestFunction(
            unknown.function_space)
        du_V, dv_V = (ufl.TrialFunction(V), ufl.TestFunction(V)) if self.mixed else (du, dv)
        ufl_forms = {}
        if scene.damped:
            convex += self._dissipation(self.u, self.u_anchor, self.damping_coefficient)
            zero = ufl.as_vector([0.0] * d)
            ufl_forms["damping_force"] = ufl.derivative(
                self._dissipation(self.v, zero, 1.0), self.v, dv_V)
        objective = step_objective(convex, potential, self.weight)
        #: the inertia, damping and gravity terms as matrices and a vector assembled once
        #: (:mod:`fem_anim.problem.constant_terms`); the forms assembled per call hold w times the
        #: rest. Not for the mixed saddle point or the explicit scheme.
        self.split_constant = not self.mixed and not self.scheme.explicit
        assembled = self.weight * varying if self.split_constant else objective
        residual = ufl.derivative(assembled, unknown, dv)
        jacobian = ufl.derivative(residual, unknown, du)
        solver = scene["solver"]
        self.tangent_data = None
        self.hessian_mode = solver["hessian"] if not self.scheme.explicit else "exact"
        correction = None
        if self.contact is not None:
            correction = self.contact.curvature_correction(du, dv)
        if correction is not None:
            jacobian += self.weight * correction  # sphere barriers: PSD-projected Hessian

        def filtered_forms() -> dict[str, ufl.Form]:
            """The Hessian with the elastic tangent filtered (the convex terms exactly;
            gravity is linear) and, for the trust-region ratio's model, y^T H y of the exact
            Hessian along a direction y."""
            filtered = self._projected_elastic_hessian(du, dv)
            if not self.split_constant:
                filtered += ufl.derivative(ufl.derivative(convex, self.u, dv), self.u, du)
            if contact_terms is not None:  # exact: not a function of F
                filtered += self.weight * ufl.derivative(ufl.derivative(
                    contact_terms, self.u, dv), self.u, du)
            if correction is not None:
                filtered += self.weight * correction
            forms = {"jacobian_filtered": filtered}
            if self.hessian_mode in ("trust_region_filter", "auto"):
                self.direction = fem.Function(V, name="newton_direction")
                forms["curvature"] = ufl.derivative(ufl.derivative(
                    objective, self.u, self.direction), self.u, self.direction)
            return forms

        self.direction = None
        #: auto: the filtered forms, built and compiled at their first use
        #: (:meth:`_compile_filtered`): a scene that never meets an indefinite Hessian pays
        #: no JIT for them
        self._lazy_filtered = None
        if self.hessian_mode in ("project", "abs", "trust_region_filter"):
            extra = filtered_forms()  # the filtered Hessian is the only one
            jacobian = extra.pop("jacobian_filtered")
            ufl_forms |= extra
        elif self.hessian_mode == "auto":
            self._lazy_filtered = filtered_forms
        self.filter_inversion = solver["inversion_filter"]
        if self.filter_inversion is None:
            self.filter_inversion = self.mixed or any(m.requires_positive_J
                                                      for m, _ in self.elastic_terms)
        self.det_data = None
        self.det_dofs = None  # quadrature dofs the filter watches (None: all)
        if self.filter_inversion:
            self.det_data = self._quadrature_data(
                "det_F", ufl.det(deformation_gradient(self.u)), lambda J: J, (), ())
            if solver["inversion_filter"] is None and self.material_map is not None:
                self.det_dofs = self._positive_J_dofs()
        ufl_forms |= {
            "objective": assembled,
            "residual": residual,
            "jacobian": jacobian,
            "kinetic": inertia_forms.kinetic_energy(self.v, self.rho, self.dx_mass),
            "elastic": elastic_u,
            "mass": self.rho * ufl.inner(du_V, dv_V) * self.dx_mass,
            "potential_gradient": ufl.derivative(potential_u, self.u, dv_V),
        }
        if gravity_u is not None:
            ufl_forms["gravity"] = gravity_u
        if self.split_constant:
            if scene.damped:  # else the convex terms' Hessian is the mass form
                ufl_forms["constant_hessian"] = ufl.derivative(ufl.derivative(
                    convex, self.u, dv), self.u, du)
                ufl_forms["damping_hessian"] = ufl.derivative(ufl.derivative(
                    self._dissipation(self.u, self.u_anchor, 1.0), self.u, dv), self.u, du)
            if gravity_u is not None:
                ufl_forms["gravity_gradient"] = ufl.derivative(gravity_u, self.u, dv)
        if self.contact is not None:
            ufl_forms["contact"] = self.contact.energy
        # per-cell int_K psi dX, for the energy density field of the frames (last: keeps the
        # other forms' JIT keys)
        q = ufl.TestFunction(self.W0)
        ufl_forms["cell_elastic"] = sum(self._psi(self.u, material=m) * q * dx
                                        for m, dx in self.elastic_terms)
        if self.mixed:
            ufl_forms["cell_elastic"] = self._mixed_energy(self.u, self.p, q)
            p_trial, p_test = ufl.split(du)[-1], ufl.split(dv)[-1]
            ufl_forms["pressure_mass"] = p_trial * p_test * self.dx_elastic
        self.ufl_objective = objective
        self.ufl_elastic = elastic_u
        self.assembly_s = 0.0  # wall time spent assembling (objective, residual, Jacobian)
        start = time.perf_counter()
        compiled = compile_forms(ufl_forms)
        #: Wall time of the form compilation (FFCx + gcc, or a load from the JIT cache).
        self.compile_s = time.perf_counter() - start
        self.objective_form = compiled["objective"]
        self.residual_form = compiled["residual"]
        self.jacobian_form = compiled["jacobian"]
        self.jacobian_filtered_form = compiled.get("jacobian_filtered")
        self.curvature_form = compiled.get("curvature")
        self._active_jacobian = self.jacobian_form
        self.hessian_filter = None  # the tangent's filter in use (None: exact)
        if self.hessian_mode in ("project", "abs", "trust_region_filter"):
            self.set_hessian_filter("clamp" if self.hessian_mode == "project" else "abs")
        self.mass_form = compiled["mass"]
        self.potential_gradient_form = compiled["potential_gradient"]
        self.damping_force_form = compiled.get("damping_force")
        self.energy_forms = {k: compiled[k] for k in ("kinetic", "elastic", "gravity",
                                                            "contact") if k in compiled}
        self.cell_elastic_form = compiled["cell_elastic"]
        self._cell_volumes = None

        self.unknown = unknown
        n_cells = mesh.topology.index_map(d).size_local + mesh.topology.index_map(d).num_ghosts
        self.cell_body = local_cell_markers(self.domain) - 1 if self.bodies else \
            np.zeros(n_cells, np.int32)
        #: the pins on V (mass, initial acceleration) and on the unknown (the step): the same
        #: conditions unless the unknown is the mixed w
        self.displacement_bcs = self._pins()
        self.bcs = [self.fields.dirichletbc(self.u_bc, dofs) for dofs in self._pin_dofs] \
            if self.mixed else self.displacement_bcs
        self.x_work = compat.petsc_vec(unknown).duplicate()
        if self.mixed:
            mu_value, inv_kappa = float(self.mu.value), float(self.inv_kappa.value)
            self.schur = SchurPreconditioner(self.fields, compiled["pressure_mass"],
                                             mu_value * (1.0 + mu_value * inv_kappa))
        self.constant_terms = None
        if self.split_constant:
            terms = [QuadraticTerm(self.mass_form, self.u_pred)]
            if "damping_hessian" in compiled:
                terms.append(QuadraticTerm(compiled["damping_hessian"], self.u_anchor,
                                           self.damping_coefficient))
            linear = (compiled["gravity_gradient"], self.weight) \
                if "gravity_gradient" in compiled else None
            self.constant_terms = ConstantTerms(
                terms, compiled.get("constant_hessian", self.mass_form), self.bcs, linear)
        self.ipc = None  # [contact]: IPC barrier between surfaces (fem_anim/contact/ipc.py)
        if "contact" in scene.data:
            pinned = np.concatenate([bc.dof_indices()[0] for bc in self.displacement_bcs] +
                                    [np.empty(0, np.int32)])
            names = [b["name"] for b in self.bodies] or ["body"]
            self.ipc = IPCContact(scene["contact"], self.u, pinned, names, self.cell_body)

    # -- construction helpers -------------------------------------------------------------
    def _regions(self, regions: list[dict] | None = None) -> None:
        """Per-region materials (:mod:`fem_anim.mesh.regions`): DG0 fields replace the constants
        :attr:`mu`, :attr:`lmbda`, :attr:`rho`, and :attr:`elastic_terms` gets one measure
        per material model in use (cell tags = model index). ``regions``: the bodies'
        (:func:`fem_anim.mesh.bodies.body_regions`) instead of the scene's ``[[region]]``.
        """
        mesh = self.domain.mesh
        self.material_map = cells = assign_materials(self.scene, self.domain, regions)
        Q = self.W0
        cell_dofs = compat.cell_dofs(Q).reshape(-1)[: cells.cell_material.size]
        E, nu = cells.cell_values("youngs_modulus"), cells.cell_values("poisson_ratio")
        fields = dict(zip(("mu", "lmbda"), lame_parameters(E, nu)))
        fields["rho"] = cells.cell_values("density")
        for name, values in fields.items():
            function = fem.Function(Q, name=name)
            function.x.array[cell_dofs] = values
            setattr(self, name, function)
        if len(cells.models) == 1:
            self.material = get_material(cells.models[0])
            self.elastic_terms = [(self.material, self.dx_elastic)]
            return
        n = cells.cell_model.size
        tags = dmesh.meshtags(mesh, self.d, np.arange(n, dtype=np.int32), cells.cell_model)
        dx_tagged = ufl.Measure("dx", domain=mesh, subdomain_data=tags,
                                metadata={"quadrature_degree": self.quadrature_degree})
        self.elastic_terms = [(get_material(model), dx_tagged(k))
                              for k, model in enumerate(cells.models)]

    def _positive_J_dofs(self) -> np.ndarray | None:
        """Quadrature dofs of the cells whose model needs det F > 0 (None: every cell)."""
        needs = np.array([get_material(m).requires_positive_J
                          for m in self.material_map.models])
        if needs.all():
            return None
        cells = needs[self.material_map.cell_model]
        dofs = compat.cell_dofs(self.det_data.function.function_space)
        return dofs[cells].ravel()

    def _quadrature_points(self) -> np.ndarray:
        """Reference points of the elastic quadrature rule (the rule FFCx uses)."""
        cell = self.domain.mesh.topology.cell_name()
        points, _ = compat.reference_quadrature(cell, self.quadrature_degree)
        return points

    def _quadrature_data(self, name: str, expression, evaluate, in_shape, out_shape):
        """A quadrature Function filled by ``evaluate(expression)`` on every update."""
        Q = compat.quadrature_space(self.domain.mesh, self.quadrature_degree, out_shape)
        index_map = self.domain.mesh.topology.index_map(self.d)
        return QuadratureData(fem.Function(Q, name=name),
                              compat.expression(expression, self._quadrature_points(),
                                                JIT_OPTIONS),
                              evaluate, index_map.size_local + index_map.num_ghosts, in_shape)

    def _psi(self, u, F=None, material=None):
        """A material's psi of F(u) (or of a given F), with its quadrature data."""
        F = deformation_gradient(u) if F is None else F
        material = self.material if material is None else material
        if u not in self._extra:
            self._extra[u] = {}
            needs = dict.fromkeys(k for m, _ in self.elastic_terms for k in m.needs(self.d))
            for key in needs:
                data = EXTRA_DATA[key]
                q = self._quadrature_data(key, deformation_gradient(u), data.evaluate,
                                          (self.d, self.d), data.value_shape(self.d))
                self.quadrature_data.append(q)
                self._extra[u][data.keyword] = q.function
        extra = {data.keyword: self._extra[u][data.keyword]
                 for data in map(EXTRA_DATA.get, material.needs(self.d))}
        return material.psi(F, self.mu, self.lmbda, **extra)

    def _elastic_energy(self, u):
        return sum(self._psi(u, material=m) * dx for m, dx in self.elastic_terms)

    def _mixed_energy(self, u, p_scaled, q=1.0):
        """int q W(F(u), mu p~) dX, W the perturbed Lagrangian (:mod:`fem_anim.forms.incompressible`)."""
        W = lagrangian(self.mixed_material, deformation_gradient(u), self.mu * p_scaled,
                       self.mu, self.inv_kappa, self.mooney_ratio)
        return W * q * self.dx_elastic

    def _projected_elastic_hessian(self, du, dv):
        """w int grad(v) : A+ : grad(du), A+ the filtered d^2 psi/dF^2 (clamp or abs, per
        quadrature point: :func:`fem_anim.solver.hessian_modification.filter_tangent`)."""
        d = self.d
        Fv = ufl.variable(deformation_gradient(self.u))
        tangent = ufl.diff(ufl.diff(self._psi(self.u, Fv), Fv), Fv)
        flat = ufl.as_matrix([[tangent[i, j, k, m] for k in range(d) for m in range(d)]
                              for i in range(d) for j in range(d)])
        self.tangent_data = self._quadrature_data(
            "filtered_tangent", flat, project_psd, (d * d, d * d), (d * d, d * d))
        A = self.tangent_data.function  # row i*d + j, column k*d + m, like `flat`

        def flatten(G):
            return ufl.as_vector([G[i, j] for i in range(d) for j in range(d)])

        return self.weight * ufl.inner(flatten(ufl.grad(dv)), ufl.dot(A, flatten(ufl.grad(du)))
                                       ) * self.dx_elastic

    def _dissipation(self, u, anchor, coefficient):
        cfg = self.scene["damping"]
        return damping_forms.dissipation_potential(
            u, anchor, coefficient, float(cfg["alpha"]), float(cfg["beta"]), self.rho, self.mu,
            self.lmbda, self.dx_mass, self.dx_elastic)

    def _pins(self) -> list:
        bcs = []
        self.moving_pins: list[PinMotion] = []
        self._pin_dofs: list[np.ndarray] = []  # nodes of V held by each pin
        coordinates = self.V.tabulate_dof_coordinates()[:, : self.d]
        for body, where, pin in body_pins(self.scene):
            lo = np.asarray(pin["min"], dtype=float)
            hi = np.asarray(pin["max"], dtype=float)

            def inside(x, lo=lo, hi=hi):
                d = lo.size
                return np.all((x[:d].T >= lo) & (x[:d].T <= hi), axis=1)

            dofs = fem.locate_dofs_geometrical(self.V, inside)
            if body is not None:  # a body's pin holds that body's vertices only
                k = [b["name"] for b in self.bodies].index(body)
                cells = np.flatnonzero(self.cell_body == k).astype(np.int32)
                dofs = np.intersect1d(dofs, compat.dofs_of_cells(self.V, cells))
                dofs = dofs.astype(np.int32)
            dofs = self._owners_choice(dofs)
            coordinates_i = coordinates[dofs]
            owned = dofs[dofs < self.V.dofmap.index_map.size_local]
            if self.comm.allreduce(owned.size, op=MPI.SUM) == 0:
                of = f" of body {body!r}" if body is not None else ""
                raise SceneError(f"{where} ({pin['name']}): the box min {pin['min']}, max "
                                 f"{pin['max']} contains no mesh vertex{of}")
            bcs.append(fem.dirichletbc(self.u_bc, dofs))
            self._pin_dofs.append(dofs)
            if pin["velocity"] is not None or pin["angular_velocity"] != 0:
                self.moving_pins.append(PinMotion.from_scene(pin, dofs, coordinates_i))
        return bcs

    def _owners_choice(self, nodes: np.ndarray) -> np.ndarray:
        """The pinned nodes of V as their owners chose them, ghosts included (collective).

        ``locate_dofs_geometrical`` tests each rank's own dof coordinates, which DOLFINx
        computes through each rank's cells: a vertex on a pin box's face can fall inside on
        one rank and outside on another (round-off), and a ghost pinned on one rank but free
        on its owner corrupts the assembly near it (seen on 3 ranks: a residual off by 2e-3).
        The owner decides; its ghosts follow.
        """
        marker = fem.Function(self.V)
        values = marker.x.array.reshape(-1, self.d)
        owned = nodes[nodes < self.V.dofmap.index_map.size_local]
        values[owned, 0] = 1.0
        marker.x.scatter_forward()
        return np.flatnonzero(values[:, 0] == 1.0).astype(np.int32)

    def set_pinned_displacement(self, t: float) -> None:
        """Move the animated pins to their prescribed displacement at time ``t``."""
        values = self.u_bc.x.array.reshape(-1, self.d)
        for motion in self.moving_pins:
            values[motion.dofs] = motion.displacement(t)

    def prescribe_pin_rates(self, t: float, v: np.ndarray, a: np.ndarray) -> None:
        """Overwrite ``v`` and ``a`` (local dof arrays) at the animated pins with their
        prescribed values at time ``t``."""
        for motion in self.moving_pins:
            rates = motion.rates(t)
            for array, value in zip((v, a), rates):
                array.reshape(-1, self.d)[motion.dofs] = value

    # -- assembly -------------------------------------------------------------------------
    def set_state(self, x: PETSc.Vec) -> None:
        """Copy a solver iterate into ``u`` (with ghosts) and refresh quadrature data."""
        u = compat.petsc_vec(self.unknown)
        x.copy(u)
        u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        if self.mixed:
            self.fields.scatter(self.u, self.p)
        self.update_quadrature_data()

    def load_guess(self, u: np.ndarray, x: PETSc.Vec, apply_bcs: bool = True) -> None:
        """An initial guess into ``x`` from displacement values ``u`` (local dofs of V),
        with the pinned values if ``apply_bcs``; a mixed guess keeps the last pressure."""
        if self.mixed:
            self.fields.set_displacement(u)
        else:
            self.u.x.array[:] = u
        vec = compat.petsc_vec(self.unknown)
        if apply_bcs:
            fem_petsc.set_bc(vec, self.bcs)
        vec.copy(x)

    def update_quadrature_data(self) -> None:
        """Refresh the material's quadrature data, unless its inputs are unchanged.

        The data (e.g. corotated's tr sqrt(C), a batched SVD) depends only on the
        displacement Functions it is computed from; when their local arrays (with ghosts)
        equal those of the last refresh, the data is current. Rank-local like the refresh
        itself: no communication, so ranks may decide differently.
        """
        if not self.quadrature_data:
            return
        arrays = [f.x.array for f in self._extra]
        if self._quadrature_inputs is not None and all(
                np.array_equal(a, b) for a, b in zip(arrays, self._quadrature_inputs)):
            return
        for data in self.quadrature_data:
            data.update()
        self._quadrature_inputs = [a.copy() for a in arrays]

    def assemble_scalar(self, form) -> float:
        """A scalar form summed over all ranks."""
        return self.comm.allreduce(fem.assemble_scalar(form), op=MPI.SUM)

    def min_det_F(self) -> float:
        """Smallest det F over the quadrature points of all ranks, for the current u."""
        self.det_data.update()
        local = self.det_data.function.x.array
        if self.det_dofs is not None:
            local = local[self.det_dofs]
        return self.comm.allreduce(local.min() if local.size else np.inf, op=MPI.MIN)

    def objective(self, snes, x: PETSc.Vec) -> float:
        """g(x) for the SNES line search and trust region (STYLE rule 7).

        With the inversion filter on, a state where some det F <= 0 has g = +inf: the
        line search never accepts it (the energy is infinite there, not NaN). Likewise a
        state where a contact point touches or crosses an obstacle (:mod:`fem_anim.contact.obstacles`).
        """
        start = time.perf_counter()
        EVENTS["objective"].begin()
        self.set_state(x)
        if self.filter_inversion and not self.min_det_F() > 0.0:
            value = np.inf
        elif self.contact is not None and not self.contact.min_distance() > 0.0:
            value = np.inf  # a contact point on or through an obstacle: the barrier is +inf
        else:
            value = self.assemble_scalar(self.objective_form)
            if self.constant_terms is not None:
                value += self.constant_terms.value(x)
            if self.ipc is not None:  # the barrier: +inf at contact
                value += float(self.weight.value) * self.ipc.energy()
        EVENTS["objective"].end()
        self.assembly_s += time.perf_counter() - start
        return value

    def residual(self, snes, x: PETSc.Vec, b: PETSc.Vec) -> None:
        """grad g(x), with pinned rows replaced by x - u_bc."""
        start = time.perf_counter()
        EVENTS["residual"].begin()
        self.set_state(x)
        with b.localForm() as b_local:
            b_local.set(0.0)
        fem_petsc.assemble_vector(b, self.residual_form)
        # the lifting reads x at ghost dofs too: those of the state u (set_state updated
        # them), not x's own ghost entries, which SNES never updates (a line-search trial's
        # are stale: under MPI the residual then disagreed with g near pinned dofs owned
        # by another rank). It adds J (u_bc - x) over the pinned dofs: nothing when this
        # rank's pinned dofs hold their values exactly, as after a start at u_bc (skipped
        # then: 18 % of a residual on the 11.5k beam; rank-local, no communication inside).
        if not self._pins_on_target():
            fem_petsc.apply_lifting(b, [self.jacobian_form], [self.bcs],
                                    [compat.petsc_vec(self.unknown)], -1.0)
        b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self.constant_terms is not None:
            self.constant_terms.add_gradient(b, x)
        if self.ipc is not None:
            self.ipc.add_gradient(b, float(self.weight.value))
        fem_petsc.set_bc(b, self.bcs, x, -1.0)
        EVENTS["residual"].end()
        self.assembly_s += time.perf_counter() - start

    def _pins_on_target(self) -> bool:
        """Whether every pinned node of this rank (ghosts included) has u = u_bc exactly."""
        u = self.u.x.array.reshape(-1, self.d)
        u_bc = self.u_bc.x.array.reshape(-1, self.d)
        return all(np.array_equal(u[dofs], u_bc[dofs]) for dofs in self._pin_dofs)

    def set_hessian_filter(self, how: str | None) -> None:
        """Assemble the next Hessians exact (``None``) or with the elastic tangent filtered
        per quadrature point (``"clamp"`` or ``"abs"``: :func:`fem_anim.solver.hessian_modification.filter_tangent`).

        Raises:
            ValueError: a filter asked of a problem built without the filtered form.
        """
        if how is not None:
            self._compile_filtered()
        if how is None:
            if self.hessian_mode in ("project", "abs", "trust_region_filter"):
                raise ValueError(f"solver.hessian = {self.hessian_mode!r} has no exact Hessian")
            self._active_jacobian = self.jacobian_form
        else:
            if self.tangent_data is None:
                raise ValueError(f"solver.hessian = {self.hessian_mode!r} has no filtered "
                                 "Hessian")
            self.tangent_data.evaluate = FILTERS[how]
            self._active_jacobian = self.jacobian_filtered_form or self.jacobian_form
        self.hessian_filter = how

    def _compile_filtered(self) -> None:
        """``auto``: build and compile the filtered Hessian and y^T H y at their first use
        (collective: every rank reaches it at the same Newton iteration)."""
        if self._lazy_filtered is None:
            return
        forms, self._lazy_filtered = self._lazy_filtered(), None
        start = time.perf_counter()
        with compat.jit_locks_released(JIT_OPTIONS):
            compiled = compile_forms(forms)
        self.compile_s += time.perf_counter() - start
        self.jacobian_filtered_form = compiled["jacobian_filtered"]
        self.curvature_form = compiled["curvature"]

    def curvature(self, x: PETSc.Vec, y: PETSc.Vec) -> float:
        """y^T H(x) y with H the exact (unfiltered) Hessian of g, summed over all ranks."""
        self._compile_filtered()
        self.set_state(x)
        direction = compat.petsc_vec(self.direction)
        y.copy(direction)
        direction.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return self.assemble_scalar(self.curvature_form)

    def jacobian(self, snes, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        """Hessian of g at x (exact, or with the elastic part filtered: ``solver.hessian``,
        :meth:`set_hessian_filter`).

        Line-search trials may have left another state in u, so x is set first.
        """
        start = time.perf_counter()
        EVENTS["jacobian"].begin()
        self.set_state(x)
        if self.hessian_filter is not None:
            self.tangent_data.update()
        A.zeroEntries()
        fem_petsc.assemble_matrix(A, self._active_jacobian, self.bcs)
        if self.ipc is not None:
            A.assemble(PETSc.Mat.AssemblyType.FLUSH)
            self.ipc.add_hessian(A, float(self.weight.value))
        A.assemble()
        if self.constant_terms is not None:
            self.constant_terms.add_hessian(A, subset=self.ipc is not None)
        if self.schur is not None:
            self.schur.update(float(self.weight.value))
        EVENTS["jacobian"].end()
        self.assembly_s += time.perf_counter() - start

    def create_matrix(self, mat_type: str | None = None) -> PETSc.Mat:
        """The Jacobian matrix, sparsity and preallocation built once.

        It carries the rigid-body modes as near-nullspace, which algebraic multigrid
        (``cg-gamg``) needs for elasticity and every other solver ignores. ``mat_type``
        ``"baij"`` stores d x d blocks: assembly inserts a block per vertex pair (about 3x
        faster here) but PETSc's and MUMPS's Cholesky and GAMG reject it (LU, ILU, ICC,
        Jacobi, SOR and hypre accept it).
        """
        A = fem_petsc.create_matrix(self.jacobian_form, mat_type)
        A.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        if self.ipc is not None:  # contact pairs couple dofs the elastic pattern does not
            A.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        if not self.mixed:  # the modes of the displacement block only: not set for (u, p)
            A.setNearNullSpace(self.rigid_body_modes())
        return A

    def configure_preconditioner(self, pc: PETSc.PC) -> None:
        """Give a ``fieldsplit`` PC the fields of a mixed problem (``schur`` preset)."""
        if self.schur is not None and pc.getType() == "fieldsplit":
            self.schur.configure(pc)

    def rigid_body_modes(self) -> PETSc.NullSpace:
        """Translations and infinitesimal rotations of the body, orthonormalised."""
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
        return fem_petsc.create_vector(self.residual_form)

    def energies(self) -> dict[str, float]:
        """Kinetic, elastic and gravitational energy of the current (u, v) state."""
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
            u: Displacement dof values, ghosts included (a :class:`State`'s ``u``).
        """
        self.u.x.array[:] = u
        self.update_quadrature_data()
        num_owned = self.domain.mesh.topology.index_map(self.d).size_local
        cell_dofs = compat.cell_dofs(self.W0)[:num_owned, 0]
        if self._cell_volumes is None:
            mesh = self.domain.mesh
            self._cell_volumes = np.abs(cell_volumes(
                mesh.geometry.x[:, : self.d], compat.geometry_dofmap(mesh)[:num_owned]))
        energy = fem_petsc.assemble_vector(self.cell_elastic_form)
        values = energy.array[cell_dofs] / self._cell_volumes
        energy.destroy()
        return values
