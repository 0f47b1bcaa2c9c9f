"""The UFL terms of the step objective (seed eq. 4) and their derivatives.

From the scene, :class:`EnergyTerms` builds

    g(u) = 1/2 ||u - u_pred||_M^2 + w [ int psi(F(u)) dV + E_gravity(u) + E_contact(u) ]

(``fem_anim.forms``: a material's ``psi``, :mod:`fem_anim.forms.inertia`,
:mod:`fem_anim.forms.gravity`, :mod:`fem_anim.forms.time_schemes`), plus the Rayleigh
dissipation potential when damped, and takes the residual and Jacobian by
``ufl.derivative`` of that single energy. Only the terms the scene declares are built:
without ``[gravity]`` there is no gravity form, without ``[[obstacle]]`` no obstacle contact
form (:mod:`fem_anim.contact.obstacles`). With ``[[region]]`` or ``[[body]]`` entries the
elastic energy is one integral per material model in use over its cells, and mu, lambda and
rho are piecewise-constant fields. The mixed formulation's elastic term is the perturbed
Lagrangian int psi_dev(F) + p g(J) - p^2 / (2 kappa) (:mod:`fem_anim.forms.incompressible`).
The energies reported per step (kinetic, elastic, gravity, contact) are separate scalar
forms over the same measures.

:class:`EnergyTerms` is a part of :class:`~fem_anim.problem.objective.EnergyProblem`: it
reads the problem's functions, constants and measures, set before it runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.contact.obstacles import ObstacleContact
from fem_anim.forms import damping as damping_forms
from fem_anim.forms import gravity as gravity_forms
from fem_anim.forms import inertia as inertia_forms
from fem_anim.forms.incompressible import lagrangian
from fem_anim.forms.kinematics import deformation_gradient
from fem_anim.forms.lame import lame_parameters
from fem_anim.forms.material import EXTRA_DATA, get_material
from fem_anim.forms.time_schemes import step_objective
from fem_anim.mesh.regions import assign_materials
from fem_anim.problem.form_compiler import JIT_OPTIONS
from fem_anim.problem.quadrature import QuadratureData

__all__ = ["EnergyTerms", "StepTerms"]


@dataclass
class StepTerms:
    """The UFL pieces of one scene's step objective, from which its forms are derived."""

    elastic_u: ufl.Form  #: int psi(F(u)) dX of the displacement u
    gravity_u: ufl.Form | None  #: E_gravity(u) (None without ``[gravity]``)
    potential_u: ufl.Form  #: E(u): elastic, gravity and obstacle contact
    potential: ufl.Form  #: E of the objective's unknown (linearised for the explicit scheme)
    varying: ufl.Form  #: the terms of E whose Hessian changes with u
    contact_terms: ufl.Form | None  #: obstacle barrier (and friction)
    convex: ufl.Form | None = None  #: inertia (and dissipation) of the objective
    objective: ufl.Form | None = None  #: g
    unknown: fem.Function | None = None  #: u, or the mixed w
    du: ufl.Argument | None = None  #: trial function of the unknown's space
    dv: ufl.Argument | None = None  #: test function of the unknown's space
    du_V: ufl.Argument | None = None  #: trial function of V
    dv_V: ufl.Argument | None = None  #: test function of V
    correction: ufl.Form | None = None  #: PSD correction of sphere barriers' Hessian


class EnergyTerms:
    """Building the step objective's terms, the derivatives and the reported energies."""

    def _potential_terms(self) -> StepTerms:
        """E(u): elastic energy, gravity and obstacle contact (sets ``g``, ``contact``)."""
        scene, degree = self.scene, self.scene["element"]["degree"]
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
            self.g = fem.Constant(self.domain.mesh, np.asarray(
                scene["gravity"]["acceleration"], dtype=PETSc.ScalarType))
            gravity_u = gravity_forms.gravity_potential(self.u, self.rho, self.g, self.dx_load)

        self.contact = None  # obstacles: barrier (and friction) terms
        if scene["obstacle"]:
            # a shell's mesh is its mid-surface: its faces lie t / 2 out
            offset = scene["shell"]["thickness"] / 2 if "shell" in scene.data else 0.0
            self.contact = ObstacleContact(scene["obstacle"], self.u, self.u_prev, degree,
                                           scene["material"]["youngs_modulus"], offset)
        potential = potential_u = elastic_u if gravity_u is None else elastic_u + gravity_u
        varying = elastic_u  # the potential's terms whose Hessian changes with u
        if self.contact is not None:
            potential = potential_u = potential_u + self.contact.energy
            varying = varying + self.contact.energy
        if self.scheme.explicit:
            # Symplectic Euler: E linearised at u_prev, grad E(u_prev) . u
            at_prev = self._elastic_energy(self.u_prev)
            if gravity_u is not None:
                at_prev += gravity_forms.gravity_potential(self.u_prev, self.rho, self.g,
                                                           self.dx_load)
            potential = ufl.derivative(at_prev, self.u_prev, self.u)
            if self.contact is not None:  # the barrier stays implicit: it guards d > 0
                potential += self.contact.energy
        if self.mixed:  # the same potential, of the mixed unknown
            potential = self._mixed_energy(u_obj, self.fields.p)
            if gravity_u is not None:
                potential += gravity_forms.gravity_potential(u_obj, self.rho, self.g,
                                                             self.dx_load)
            if self.contact is not None:  # the barrier of the displacement block
                potential += self._of_unknown(self.contact.energy)
        contact_terms = None
        if self.contact is not None:
            contact_terms = self.contact.energy if self.contact.friction is None else \
                self.contact.energy + self.contact.friction
            if self.contact.friction is not None:
                potential += self._of_unknown(self.contact.friction)
                varying += self.contact.friction
        if self.wind is not None:  # drag: a dissipation with the geometry of u_n, in w E
            drag = self.wind.step_potential(self.u, self.u_anchor, self.u_prev,
                                            self.damping_coefficient, self.weight, self.dx_shell)
            potential, varying = potential + drag, varying + drag
        terms = StepTerms(elastic_u, gravity_u, potential_u, potential, varying, contact_terms)
        terms.convex = inertia_forms.inertia(u_obj, self.u_pred, self.rho, self.dx_mass)
        return terms

    def _step_forms(self, terms: StepTerms) -> dict[str, ufl.Form]:
        """g, its residual and Jacobian (sets ``split_constant``, ``hessian_mode``).

        Returns:
            The first forms to compile: the damping force (damped scenes) and, for the
            filtered Hessian modes, y^T H y; ``"assembled"``, ``"residual"`` and
            ``"jacobian"`` are returned for ``_report_forms`` to place.
        """
        scene, d = self.scene, self.d
        unknown = terms.unknown = self.fields.w if self.mixed else self.u
        du, dv = ufl.TrialFunction(unknown.function_space), ufl.TestFunction(
            unknown.function_space)
        du_V, dv_V = (ufl.TrialFunction(self.V), ufl.TestFunction(self.V)) if self.mixed \
            else (du, dv)
        terms.du, terms.dv, terms.du_V, terms.dv_V = du, dv, du_V, dv_V
        ufl_forms = {}
        if scene.damped:  # of the objective's displacement (the mixed w's first field)
            u_obj = self.fields.u if self.mixed else self.u
            terms.convex += self._dissipation(u_obj, self.u_anchor, self.damping_coefficient)
            zero = ufl.as_vector([0.0] * d)
            ufl_forms["damping_force"] = ufl.derivative(
                self._dissipation(self.v, zero, 1.0), self.v, dv_V)
        if self.wind is not None:  # f(v) at (u, v), for the initial acceleration
            ufl_forms["drag_force"] = ufl.derivative(
                self.wind.force_potential(self.v, self.u, self.dx_shell), self.v, dv_V)
        objective = terms.objective = step_objective(terms.convex, terms.potential,
                                                     self.weight)
        #: the inertia, damping and gravity terms as matrices and a vector assembled once
        #: (:mod:`fem_anim.problem.constant_terms`); the forms assembled per call hold w times
        #: the rest. Not for the mixed saddle point or the explicit scheme.
        self.split_constant = not self.mixed and not self.scheme.explicit
        assembled = self.weight * terms.varying if self.split_constant else objective
        residual = ufl.derivative(assembled, unknown, dv)
        jacobian = ufl.derivative(residual, unknown, du)
        self.tangent_data = None
        self.hessian_mode = scene["solver"]["hessian"] if not self.scheme.explicit \
            else "exact"
        if self.contact is not None:  # on the displacement block of a mixed unknown
            du_u, dv_u = (ufl.split(du)[0], ufl.split(dv)[0]) if self.mixed else (du, dv)
            correction = self.contact.curvature_correction(du_u, dv_u)
            terms.correction = None if correction is None else self._of_unknown(correction)
        if terms.correction is not None:
            jacobian += self.weight * terms.correction  # sphere barriers: PSD-projected
        jacobian = self._choose_hessian_forms(terms, jacobian, ufl_forms)
        return ufl_forms | {"assembled": assembled, "residual": residual, "jacobian": jacobian}

    def _inversion_filter(self) -> None:
        """``solver.inversion_filter``: the det F data the objective's +inf test reads."""
        solver = self.scene["solver"]
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

    def _report_forms(self, terms: StepTerms, step: dict[str, ufl.Form]
                      ) -> dict[str, ufl.Form]:
        """Every form to compile, in the compiled module's order: the step's, the energies
        reported per step, the mass, the constant terms, the per-cell energy."""
        du, dv, du_V, dv_V = terms.du, terms.dv, terms.du_V, terms.dv_V
        ufl_forms = {k: v for k, v in step.items()
                     if k not in ("assembled", "residual", "jacobian")}
        ufl_forms |= {
            "objective": step["assembled"],
            "residual": step["residual"],
            "jacobian": step["jacobian"],
            "kinetic": inertia_forms.kinetic_energy(self.v, self.rho, self.dx_mass),
            "elastic": terms.elastic_u,
            "mass": self.rho * ufl.inner(du_V, dv_V) * self.dx_mass,
            "potential_gradient": ufl.derivative(terms.potential_u, self.u, dv_V),
        }
        if terms.gravity_u is not None:
            ufl_forms["gravity"] = terms.gravity_u
        if self.split_constant:
            if self.scene.damped:  # else the convex terms' Hessian is the mass form
                ufl_forms["constant_hessian"] = ufl.derivative(ufl.derivative(
                    terms.convex, self.u, dv), self.u, du)
                ufl_forms["damping_hessian"] = ufl.derivative(ufl.derivative(
                    self._dissipation(self.u, self.u_anchor, 1.0), self.u, dv), self.u, du)
            if terms.gravity_u is not None:
                ufl_forms["gravity_gradient"] = ufl.derivative(terms.gravity_u, self.u, dv)
        if self.contact is not None:
            ufl_forms["contact"] = self.contact.energy
        # per-cell int_K psi dX, for the energy density field of the frames (last: keeps the
        # other forms' JIT keys)
        q = ufl.TestFunction(self.W0)
        ufl_forms["cell_elastic"] = sum(self._psi(self.u, material=m) * q * dx
                                        for m, dx in self.elastic_terms) \
            if self.shell is None else self.shell.cell_energy(self.u, q, self.dx_shell,
                                                              self.dS_shell)
        if self.mixed:
            ufl_forms["cell_elastic"] = self._mixed_energy(self.u, self.p, q)
            p_trial, p_test = ufl.split(du)[-1], ufl.split(dv)[-1]
            ufl_forms["pressure_mass"] = p_trial * p_test * self.dx_elastic
        return ufl_forms

    # -- the pieces -----------------------------------------------------------------------
    def _regions(self, regions: list[dict] | None = None) -> None:
        """Per-region materials (:mod:`fem_anim.mesh.regions`): DG0 fields replace the
        constants ``mu``, ``lmbda``, ``rho``, and ``elastic_terms`` gets one measure per
        material model in use (cell tags = model index).

        Args:
            regions: The bodies' regions (:func:`fem_anim.mesh.bodies.body_regions`), or
                None for the scene's ``[[region]]`` entries.
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

    def _quadrature_data(self, name: str, expression, evaluate, in_shape, out_shape,
                         cells: np.ndarray | None = None) -> QuadratureData:
        """A quadrature Function filled by ``evaluate(expression)`` on every update (on
        ``cells`` only, if given)."""
        Q = compat.quadrature_space(self.domain.mesh, self.quadrature_degree, out_shape)
        index_map = self.domain.mesh.topology.index_map(self.d)
        return QuadratureData(fem.Function(Q, name=name),
                              compat.expression(expression, self._quadrature_points(),
                                                JIT_OPTIONS),
                              evaluate, index_map.size_local + index_map.num_ghosts, in_shape,
                              cells)

    def _cells_reading(self, key: str) -> np.ndarray | None:
        """The local cells whose material's psi reads the extra data ``key``
        (:data:`~fem_anim.forms.material.EXTRA_DATA`), None for every cell.

        With several material models each is integrated over its own tagged cells
        (``elastic_terms``), so the data of a corotated body's SVD is read there alone; on a
        pile of four bodies, one of them corotated, the others' cells need none.
        """
        cells = self.material_map
        index_map = self.domain.mesh.topology.index_map(self.d)
        if cells is None or len(cells.models) == 1 or \
                cells.cell_model.size != index_map.size_local + index_map.num_ghosts:
            return None
        reads = np.array([key in get_material(m).needs(self.d) for m in cells.models])
        return None if reads.all() else np.flatnonzero(reads[cells.cell_model]).astype(np.int32)

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
                                          (self.d, self.d), data.value_shape(self.d),
                                          self._cells_reading(key))
                self.quadrature_data.append(q)
                self._extra[u][data.keyword] = q.function
        extra = {data.keyword: self._extra[u][data.keyword]
                 for data in map(EXTRA_DATA.get, material.needs(self.d))}
        return material.psi(F, self.mu, self.lmbda, **extra)

    def _elastic_energy(self, u):
        """int psi(F(u)) dX, one integral per material model in use (a shell's membrane and
        bending energy)."""
        if self.shell is not None:
            return self.shell.energy(u, self.dx_shell, self.dS_shell)
        return sum(self._psi(u, material=m) * dx for m, dx in self.elastic_terms)

    def _of_unknown(self, form):
        """A form of the displacement ``u`` as a form of the objective's unknown: itself, or,
        for the mixed formulation, with ``u`` replaced by the first field of w."""
        return ufl.replace(form, {self.u: self.fields.u}) if self.mixed else form

    def _mixed_energy(self, u, p_scaled, q=1.0):
        """int q W(F(u), mu p~) dX, W the perturbed Lagrangian
        (:func:`fem_anim.forms.incompressible.lagrangian`)."""
        W = lagrangian(self.mixed_material, deformation_gradient(u), self.mu * p_scaled,
                       self.mu, self.inv_kappa, self.mooney_ratio)
        return W * q * self.dx_elastic

    def _dissipation(self, u, anchor, coefficient):
        """The Rayleigh dissipation potential c/2 (u - u_d)^T C (u - u_d)
        (:func:`fem_anim.forms.damping.dissipation_potential`).

        C = alpha M + beta K_0, K_0 the stiffness at rest: 1/2 d^T K_0 d is the
        linear-elastic energy int mu |eps|^2 + lmbda/2 tr(eps)^2 = int mu |dev eps|^2 +
        K/2 tr(eps)^2 (K = lmbda + 2 mu / d the bulk modulus). The mixed formulation damps
        its displacement block with the deviatoric part only, the linear-elastic energy of
        the Lame pair (mu, -2 mu / d): its volumetric part K/2 tr(eps)^2 is infinite at
        nu = 1/2, where the constraint g(J) = 0 keeps the motion isochoric (tr eps(v) = 0)
        and the term does no work; for nu < 1/2 it would put the volumetric stiffness, which
        the pressure carries, back into the displacement block.
        """
        if not hasattr(self, "damping_alpha"):  # Constants: the adjoint differentiates them
            cfg, mesh = self.scene["damping"], self.domain.mesh
            self.damping_alpha = fem.Constant(mesh, PETSc.ScalarType(float(cfg["alpha"])))
            self.damping_beta = fem.Constant(mesh, PETSc.ScalarType(float(cfg["beta"])))
        lmbda = -2.0 / self.d * self.mu if self.mixed else self.lmbda
        return damping_forms.dissipation_potential(
            u, anchor, coefficient, self.damping_alpha, self.damping_beta, self.rho, self.mu,
            lmbda, self.dx_mass, self.dx_elastic)
