"""The step objective bound to DOLFINx: the one module that turns forms into kernels.

:class:`EnergyProblem` composes, from a scene, the UFL step objective

    g(u) = 1/2 ||u - u_pred||_M^2 + w [ int psi(F(u)) dV + E_gravity(u) ]     (seed eq. 4)

(its terms: :mod:`fem_anim.problem.energy_terms`), takes the residual and Jacobian by
``ufl.derivative`` of that single form, compiles everything once
(:mod:`fem_anim.problem.form_compiler`), and offers the assembly callbacks a PETSc SNES
needs (:meth:`~EnergyProblem.objective`, :meth:`~EnergyProblem.residual`,
:meth:`~EnergyProblem.jacobian`). Each step, :meth:`~EnergyProblem.stage` sets every
coefficient g reads; :meth:`~EnergyProblem.finish_step` records the accepted step.

The terms whose Hessian is constant (inertia, Rayleigh damping, gravity) are assembled once
as matrices and a vector and added by matrix-vector products
(:mod:`fem_anim.problem.constant_terms`); the callbacks assemble w times the rest of E per
call. With ``[contact]`` the IPC Toolkit's barrier between surfaces
(:mod:`fem_anim.contact.ipc`) is added to g, its gradient and its Hessian outside UFL (times
w, like every term of E). Pinned dofs are Dirichlet conditions whose values live in
``u_bc`` (:mod:`fem_anim.problem.pins`). With ``element.formulation = "mixed"`` the unknown
is w = (u, p / mu) (:mod:`fem_anim.problem.discretisation`) and g is stationary, not
minimal, at the step's solution (the solver then uses no objective). The other parts of the
class: :mod:`~fem_anim.problem.discretisation`, :mod:`~fem_anim.problem.tangent_filter`,
:mod:`~fem_anim.problem.matrices`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.contact.ipc import IPCContact
from fem_anim.mesh.simplex import SimplexMesh
from fem_anim.mesh.regions import local_cell_markers
from fem_anim.problem.constant_terms import ConstantTerms, QuadraticTerm
from fem_anim.problem.discretisation import Discretisation
from fem_anim.problem.energy_terms import EnergyTerms
from fem_anim.problem.events import EVENTS
from fem_anim.problem.form_compiler import compile_forms
from fem_anim.problem.matrices import Matrices
from fem_anim.problem.mixed_space import SchurPreconditioner
from fem_anim.problem.pins import Pins
from fem_anim.problem.reported_energies import ReportedEnergies
from fem_anim.problem.tangent_filter import ONLY_FILTERED, TangentFilter

__all__ = ["EnergyProblem"]

@dataclass
class EnergyProblem(Discretisation, EnergyTerms, TangentFilter, Pins, Matrices,
                    ReportedEnergies):
    """Forms, functions and assembly callbacks of one scene's step objective.

    Building one is collective (it compiles the forms and locates the pins).

    Args:
        scene: A validated :class:`~fem_anim.scene.schema.Scene`.
        domain: The scene's mesh.

    Raises:
        SceneError: a pin's box holds no mesh vertex.
    """

    scene: object
    domain: SimplexMesh
    quadrature_degree: int = field(init=False)

    def __post_init__(self) -> None:
        self._spaces()
        self._constants()
        self._measures()
        terms = self._potential_terms()
        step_forms = self._step_forms(terms)
        self._inversion_filter()
        compiled = self._compile(self._report_forms(terms, step_forms), terms)
        self._constrain(compiled, terms.unknown)

    def _compile(self, ufl_forms: dict, terms) -> dict:
        """Compile every form (collective) and keep the compiled ones."""
        self.ufl_objective = terms.objective
        self.ufl_elastic = terms.elastic_u
        self.assembly_s = 0.0  # wall time spent assembling (objective, residual, Jacobian)
        self._blocked = {}  # form id -> its block (BAIJ) matrix (assemble_form_matrix)
        self._pattern = None  # ((matrix, nonzeros), sorted entry keys) (grow_pattern)
        #: Hessians whose pattern grow_pattern widened (contact pairs' new entries)
        self.pattern_growths = 0
        #: Hessians assembled through a block matrix (Matrices.assemble_form_matrix)
        self.blocked_assemblies = 0
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
        if self.hessian_mode in ONLY_FILTERED:
            self.set_hessian_filter("clamp" if self.hessian_mode == "project" else "abs")
        self.mass_form = compiled["mass"]
        self.potential_gradient_form = compiled["potential_gradient"]
        self.damping_force_form = compiled.get("damping_force")
        #: -f(v) of ``[wind]``'s drag at (u, v) (None without wind)
        self.drag_force_form = compiled.get("drag_force")
        self.energy_forms = {k: compiled[k] for k in ("kinetic", "elastic", "gravity",
                                                      "contact") if k in compiled}
        self.cell_elastic_form = compiled["cell_elastic"]
        self._cell_volumes = None
        return compiled

    def _constrain(self, compiled: dict, unknown: fem.Function) -> None:
        """Pins, the constant terms, the mixed preconditioner and the IPC barrier."""
        mesh, d = self.domain.mesh, self.d
        self.unknown = unknown
        cell_map = mesh.topology.index_map(mesh.topology.dim)
        n_cells = cell_map.size_local + cell_map.num_ghosts
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
        self.ipc = None  # [contact]: IPC barrier between surfaces
        #: a vertex's average mass (kg), for IPC's adaptive stiffness (None: no [contact])
        self.average_mass = None
        if "contact" in self.scene.data:
            pinned = np.concatenate([bc.dof_indices()[0] for bc in self.displacement_bcs] +
                                    [np.empty(0, np.int32)])
            names = [b["name"] for b in self.bodies] or ["body"]
            # a shell's layers stay its thickness apart (fem_anim.contact.contact_surface)
            offset = self.scene["shell"]["thickness"] if "shell" in self.scene.data else 0.0
            self.ipc = IPCContact(self.scene["contact"], self.u, pinned, names, self.cell_body,
                                  offset,
                                  (self.fields.W, self.fields.u_dofs) if self.mixed else None)
            self.average_mass = self.average_vertex_mass()

    # -- the step -------------------------------------------------------------------------
    @property
    def damped(self) -> bool:
        """Whether g holds a dissipation potential: Rayleigh damping (``[damping]``) or a
        shell's drag (``[wind]``); either reads the scheme's ``(c, u_d)``."""
        return self.damping_force_form is not None or self.drag_force_form is not None

    def stage(self, u_n: np.ndarray, u_pred: np.ndarray, weight: float, t: float, h: float,
              damping: tuple[float, np.ndarray] | None = None) -> None:
        """Set every coefficient the step objective of the step from t - h to t reads.

        The objective is then g of seed eq. 4 for this step: the predictor, the weight, the
        dissipation's anchor, the pins' prescribed displacement at ``t``, the friction
        smoothing length of obstacles, and IPC's barrier stiffness (adaptive: balanced
        against w grad E at u_n; collective); ``h`` is kept as :attr:`step_size`, the
        scale of the stopping test's step (a Newton step is small against h times the
        scene's size). Arrays are local dof values of V, ghosts
        included (a :class:`~fem_anim.simulation.integrators.State`'s), in metres.

        Args:
            u_n: Displacement at the step's start (m).
            u_pred: The integrator's predictor y - X (m).
            weight: The energy weight w (s^2).
            t: Time at the step's end (s).
            h: Step size (s).
            damping: (c, u_d) of the dissipation potential
                (:meth:`~fem_anim.simulation.integrators.Integrator.damping_anchor`);
                needed exactly when :attr:`damped`.

        Raises:
            ValueError: ``damping`` missing for a damped scene.
        """
        if self.damped and damping is None:
            raise ValueError("a damped step objective needs damping = (c, u_d)")
        self.u_pred.x.array[:] = u_pred
        self.u_prev.x.array[:] = u_n
        self.weight.value = weight
        #: The step size h (s): scales IPC's step test (:mod:`fem_anim.solver.stopping`)
        self.step_size = h
        if self.damped:
            self.damping_coefficient.value, self.u_anchor.x.array[:] = damping
        self.set_pinned_displacement(t)
        if self.contact is not None:
            self.contact.stage(h)
        if self.ipc is not None:
            self._stage_ipc(u_n, h)

    def _stage_ipc(self, u_n: np.ndarray, h: float) -> None:
        """kappa of this step at u_n (:meth:`fem_anim.contact.ipc.IPCContact.stage`)."""
        self.u.x.array[:] = u_n
        self.update_quadrature_data()
        f = fem_petsc.assemble_vector(self.potential_gradient_form)
        f.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        grad = np.zeros_like(self.u.x.array)
        grad[: f.array.size] = f.array
        f.destroy()
        self.ipc.stage(float(self.weight.value), grad, self.average_mass, h)

    def finish_step(self, t: float, v: np.ndarray, a: np.ndarray, pin_rates: bool) -> None:
        """Record an accepted step whose solution is in ``u``: IPC's stiffness update, and
        the new velocity ``v`` (m/s, local dofs of V) for the reported kinetic energy.

        Args:
            t: Time at the step's end (s).
            v: The new velocity; with ``pin_rates`` its pinned entries are overwritten.
            a: The new acceleration (m/s^2); likewise.
            pin_rates: Put the animated pins' exact rates at ``t`` into ``v`` and ``a``
                (:meth:`~fem_anim.problem.pins.Pins.prescribe_pin_rates`).
        """
        if self.ipc is not None:
            self.ipc.finish_step()
        if pin_rates:
            self.prescribe_pin_rates(t, v, a)
        self.v.x.array[:] = v

    def force_scale(self, x: PETSc.Vec) -> float:
        """The largest 2-norm, over the free dofs, of the terms of grad g at x (collective).

        The terms of the residual r = grad g (seed eq. 4): inertia M (x - y) and the two
        momenta it is the difference of, M (x - u_n) and M (y - u_n) (h M v_{n+1} and
        h M v_n for implicit Euler: a body in free flight has no other), Rayleigh damping, w times the assembled part of grad E (elastic energy and obstacles'
        barrier and friction), w times gravity's constant gradient, and w times the IPC
        barrier's and lagged friction's gradient. At a step's solution they sum to zero;
        the stopping test asks ||r|| to be small against the largest of them.

        Raises:
            ValueError: for a problem without the constant terms split off (mixed,
                explicit): its terms are not assembled apart.
        """
        if self.constant_terms is None:
            raise ValueError("the force terms are assembled apart only for an implicit "
                             "displacement formulation")
        self.set_state(x)
        ct = self.constant_terms
        work, z, Qz = x.duplicate(), x.duplicate(), x.duplicate()
        sizes = []

        def measure(vec: PETSc.Vec) -> None:
            fem_petsc.set_bc(vec, self.bcs, None, 0.0)  # free dofs only
            sizes.append(vec.norm())

        x.copy(z)
        fem_petsc.set_bc(z, self.bcs)  # the pins at their values, as the residual has them
        for k, (term, Q) in enumerate(zip(ct.terms, ct.matrices)):  # inertia, damping
            pairs = [(z, term.anchor)]  # s Q (x - a)
            if k == 0:  # the inertia's two momenta: M (x - u_n) and M (y - u_n)
                pairs += [(z, self.u_prev), (compat.petsc_vec(term.anchor), self.u_prev)]
            for end, start in pairs:
                end.copy(work)
                work.axpy(-1.0, compat.petsc_vec(start))
                Q.mult(work, Qz)
                Qz.scale(1.0 if term.scale is None else float(term.scale.value))
                measure(Qz)
        if ct.gradient is not None:  # gravity: w f
            ct.gradient.copy(work)
            work.scale(float(ct.linear_scale.value))
            measure(work)
        with work.localForm() as local:  # w times the assembled part of grad E
            local.set(0.0)
        fem_petsc.assemble_vector(work, self.residual_form)
        work.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        measure(work)
        if self.ipc is not None:  # w (kappa grad B + grad D)
            with work.localForm() as local:
                local.set(0.0)
            self.ipc.add_gradient(work, float(self.weight.value))
            measure(work)
        for vec in (work, z, Qz):
            vec.destroy()
        return max(sizes)

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
        """g(x), for the SNES line search and trust region (collective).

        With the inversion filter on, a state where some det F <= 0 has g = +inf: the
        line search never accepts it (the energy is infinite there, not NaN). Likewise a
        state where a contact point touches or crosses an obstacle
        (:mod:`fem_anim.contact.obstacles`), and IPC's barrier at contact.
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
        """grad g(x) into ``b``, with pinned rows replaced by x - u_bc (collective)."""
        start = time.perf_counter()
        EVENTS["residual"].begin()
        self.set_state(x)
        with b.localForm() as b_local:
            b_local.set(0.0)
        fem_petsc.assemble_vector(b, self.residual_form)
        # the lifting reads x at ghost dofs too: those of the state u (set_state updated
        # them), not x's own ghost entries, which SNES never updates (a line-search trial's
        # are stale under MPI). It adds J (u_bc - x) over the pinned dofs: nothing when this
        # rank's pinned dofs hold their values exactly, as after a start at u_bc (skipped
        # then; rank-local, no communication inside).
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

    def jacobian(self, snes, x: PETSc.Vec, A: PETSc.Mat, P: PETSc.Mat) -> None:
        """Hessian of g at x into ``A`` (exact, or with the elastic part filtered:
        ``solver.hessian``,
        :meth:`~fem_anim.problem.tangent_filter.TangentFilter.set_hessian_filter`; collective).

        Line-search trials may have left another state in u, so x is set first.
        """
        start = time.perf_counter()
        EVENTS["jacobian"].begin()
        self.set_state(x)
        if self.hessian_filter is not None:
            self.tangent_data.update()
        if self.ipc is not None:  # the pairs' entries, and A's pattern grown to hold them
            barrier = self.ipc.hessian_triplets(float(self.weight.value))
            self.grow_pattern(A, barrier[0], barrier[1])
        A.zeroEntries()
        self.assemble_form_matrix(A, self._active_jacobian)
        if self.ipc is not None:
            A.assemble(PETSc.Mat.AssemblyType.FLUSH)
            self.ipc.insert_hessian(A, barrier)
        A.assemble()
        if self.constant_terms is not None:
            # contact pairs and a shell's hinges (edge-neighbour couplings) add nonzeros
            # the mass form's pattern lacks
            self.constant_terms.add_hessian(A, subset=self.ipc is not None or
                                            self.shell is not None)
        if self.schur is not None:
            self.schur.update(float(self.weight.value))
        EVENTS["jacobian"].end()
        self.assembly_s += time.perf_counter() - start
