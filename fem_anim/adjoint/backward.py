"""The backward sweep: the discrete adjoint of the time-stepping (seed section 3.1, eq. 4).

Step n solves R(x_{n+1}; y_n, d_n, theta) = grad_x g = 0 with g of seed eq. 4,

    g(x) = 1/2 ||x - y_n||_M^2 + c_n/2 ||x - d_n||_C^2 + w_n E(x; theta),

y_n the integrator's predictor and d_n its damping anchor, both linear in the state s_n
(u, v, a and BDF2's u_{n-1}, v_{n-1}), and the new state s_{n+1} = U(s_n, x_{n+1}, y_n)
linear too (:mod:`fem_anim.simulation.integrators`). With H = dR/dx the *exact* Hessian
(never a projected or filtered one) at the converged x_{n+1}, the implicit function
theorem gives dx_{n+1} = -H^-1 (R_y dy + R_d dd + R_theta dtheta). Going backwards, the
adjoint s_bar_{n+1} of the state gives

    x_bar = U_x^T s_bar_{n+1},   lambda = H^-1 x_bar   (zero on pinned dofs),
    y_bar = U_y^T s_bar_{n+1} - R_y^T lambda,   d_bar = -R_d^T lambda,
    theta_bar -= R_theta^T lambda,
    s_bar_n = U_s^T s_bar_{n+1} + P^T y_bar + D^T d_bar   (+ the objective's dJ/ds_n).

R_y^T lambda, R_d^T lambda and R_theta^T lambda are derivatives of the scalar form
<R, lambda> (``ufl.action``) with respect to the Functions ``u_pred``, ``u_anchor`` and
the material's stand-in coefficients (:mod:`fem_anim.adjoint.parameters`), assembled once
per step; only H is a matrix (assembled and factorised once per step by PETSc KSP, a
direct solver as the forward default). The scalar coefficients of the linear maps P, D
and U are read off the integrator itself by applying it to unit one-entry states, so the
sweep is the transpose of exactly the forward code. Newmark's a_0 solves
M a_0 = -grad E(0) - C v_0 (seed eq. 1b) and is differentiated the same way, with M in
place of H.

A handle's velocity moves the pinned values of x: with lambda = 0 on the pins, the total
adjoint of a pinned value is x_bar - H lambda there (the free dofs' response
-H_ff^-1 H_fp), dotted with d u_D(t)/dtheta; with Newmark the handles' v and a are their
exact rates (not the integrator's update), so their adjoint goes to the rates' derivative
and not back through the update.

Friction coefficients (obstacles' and IPC's mu) enter R linearly through the lagged
friction potential D = mu D_1 (:mod:`fem_anim.adjoint.parameters`): an obstacle's as a
stand-in coefficient like the material's, IPC's as -<w grad D / mu, lambda> from ipctk.

Contact (seed eq. 4's E holds it): an obstacle's barrier and lagged friction are UFL terms
of g, so H holds their exact Hessian and, friction's pressure and normal being lagged at
u_n = ``u_prev``, -d<R, lambda>/du_prev joins the adjoint of u_n (exact). IPC's barrier
and friction live outside UFL: their unprojected Hessian (ipctk) times w is added to H,
with each step's kappa as the forward recorded it (:class:`~fem_anim.adjoint.tape.Tape`;
kappa and d_hat are constants of the step, the adaptive schedule is not differentiated);
friction's dependence on u_n, through its slip x - x_n and through the normal forces and
tangent bases lagged at x_n (ipctk's ``force_jacobian`` with respect to the lagged
displacements), joins the adjoint of u_n: exact.

Adjoint arrays are local dof arrays whose ghost entries equal their owners' (contributions
are summed to the owners, then copied back to the ghosts), so the sweep is the same on any
number of ranks.
"""

from __future__ import annotations

import time
import numpy as np
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.problem.form_compiler import compile_forms
from fem_anim.simulation.integrators import State

__all__ = ["BackwardSweep", "STATE_FIELDS", "linear_maps"]

#: The state arrays the integrator carries, in the order of the linear maps.
STATE_FIELDS = ("u", "v", "a", "u_old", "v_old")


def _unit_state(inputs: tuple[str, ...], which: str | None) -> State:
    """A one-entry state with 1 in field ``which`` and 0 elsewhere."""
    arrays = {k: np.array([1.0 if k == which else 0.0]) for k in inputs}
    return State(u=arrays["u"], v=arrays["v"], a=arrays["a"], u_old=arrays.get("u_old"),
                 v_old=arrays.get("v_old"))


def linear_maps(integrator, h: float, state: State) -> dict:
    """The scalar coefficients of the predictor, damping anchor and update of one step.

    Returns:
        ``inputs`` (the state fields present), ``P`` (input -> coefficient of y),
        ``D`` (input -> coefficient of d), ``U`` ((output, input) -> coefficient, the
        inputs including ``"x"`` the step's solution and ``"y"`` the predictor).
    """
    inputs = ("u", "v", "a") + (("u_old", "v_old") if state.u_old is not None else ())
    zero = np.zeros(1)
    P = {k: float(integrator.predictor(h, _unit_state(inputs, k))[0]) for k in inputs}
    D = {k: float(integrator.damping_anchor(h, _unit_state(inputs, k))[1][0]) for k in inputs}
    U = {}
    for k in (*inputs, "x", "y"):
        new = integrator.update(h, _unit_state(inputs, k if k in inputs else None),
                                np.array([1.0 if k == "x" else 0.0]),
                                np.array([1.0 if k == "y" else 0.0]))
        for out in STATE_FIELDS:
            U[out, k] = float(getattr(new, out)[0])
    return {"inputs": inputs, "P": P, "D": D, "U": U}


class BackwardSweep:
    """The adjoint's forms and solver for one problem (building it is collective).

    Args:
        problem: The :class:`~fem_anim.problem.objective.EnergyProblem` (displacement
            formulation, no quadrature data).
        parameters: Its :class:`~fem_anim.adjoint.parameters.ParameterSet`.
        newmark: Whether a_0 is computed from the equations of motion (Newmark).
    """

    def __init__(self, problem, parameters, newmark: bool):
        p = self.problem = problem
        self.parameters = parameters
        rep = parameters.replacements
        coefficients = parameters.coefficients
        V = p.V
        dv, du = ufl.TestFunction(V), ufl.TrialFunction(V)
        self.lam = fem.Function(V, name="adjoint")
        self.work = fem.Function(V, name="adjoint_work")
        g = ufl.replace(p.ufl_objective, rep)
        R = ufl.derivative(g, p.u, dv)
        L = ufl.action(R, self.lam)
        forms = {"hessian": ufl.derivative(R, p.u, du),  # exact: no filter, no projection
                 "y": ufl.derivative(L, p.u_pred, dv)}
        if p.damped:
            forms["d"] = ufl.derivative(L, p.u_anchor, dv)
        cell = ufl.TestFunction(p.W0)  # the derivative per cell (DG0)
        for name, f in coefficients.items():
            forms[f"theta_{name}"] = ufl.derivative(L, f, cell)
        #: obstacle friction lags its pressure and normal at u_n = u_prev: R depends on u_n
        self.lagged = p.contact is not None and p.contact.friction is not None
        if self.lagged:
            forms["prev"] = ufl.derivative(L, p.u_prev, dv)
        #: handle-velocity parameters: the pinned values' adjoint needs H lambda off the pins
        self.handles = parameters.handle_names
        if self.handles:
            forms["hlam"] = ufl.derivative(L, p.u, dv)
            self.handle_dofs = parameters.handle_dofs()
        self.newmark = newmark
        if newmark:  # r0(a) = grad E(0) + C v_0 + M a = 0, and its action on mu
            self.a0 = fem.Function(V, name="initial_acceleration")
            potential = p._elastic_energy(p.u)
            if p.g is not None:
                from fem_anim.forms import gravity as gravity_forms
                potential = potential + gravity_forms.gravity_potential(p.u, p.rho, p.g,
                                                                        p.dx_load)
            r0 = ufl.derivative(potential, p.u, dv) + \
                p.rho * ufl.inner(self.a0, dv) * p.dx_mass
            if p.damped:
                zero = ufl.as_vector([0.0] * p.d)
                r0 = r0 + ufl.derivative(p._dissipation(p.v, zero, 1.0), p.v, dv)
            L0 = ufl.action(ufl.replace(r0, rep), self.lam)
            forms["v0"] = ufl.derivative(L0, p.v, dv)
            forms["u0"] = ufl.derivative(L0, p.u, dv)  # grad E(u_0): u_0 a parameter
            for name, f in coefficients.items():
                forms[f"theta0_{name}"] = ufl.derivative(L0, f, cell)
            forms["mass"] = ufl.replace(p.rho * ufl.inner(du, dv) * p.dx_mass, rep)
        self.forms = compile_forms(forms)  # one FFCx module
        self.H = fem_petsc.create_matrix(self.forms["hessian"])
        if p.ipc is not None:  # contact pairs couple dofs the elastic pattern does not
            self.H.setOption(PETSc.Mat.Option.NEW_NONZERO_ALLOCATION_ERR, False)
        self.cell_work = fem.Function(p.W0, name="adjoint_cells")
        self.b = compat.petsc_vec(self.work).duplicate()
        self.x = self.b.duplicate()
        self.ksp = PETSc.KSP().create(p.comm)
        self.ksp.setOptionsPrefix("fem_anim_adjoint_")
        self.ksp.setType("preonly")
        self.ksp.getPC().setType("lu")
        self.ksp.getPC().setFactorSolverType("mumps")
        self.ksp.setFromOptions()
        self.pinned = np.concatenate([bc.dof_indices()[0] for bc in p.displacement_bcs] +
                                     [np.empty(0, np.int32)])
        self.owned = V.dofmap.index_map.size_local * V.dofmap.index_map_bs
        #: Wall time (s) of the last sweep's Hessian assemblies and factorisations + solves.
        self.solve_s = {"assembly": 0.0, "solve": 0.0}
        #: The last sweep's gradient per cell: parameter name -> dJ/dc on each owned DG0
        #: dof (the parameter's value taken as cell-wise; zero off its cells), for the
        #: parameters bound through the step's coefficients (materials, damping, an
        #: obstacle's friction)
        self.cell_gradient: dict[str, np.ndarray] = {}

    # -- helpers ------------------------------------------------------------------------
    def consistent(self, local: np.ndarray) -> np.ndarray:
        """Sum ghost contributions into their owners and copy the sums back to the ghosts."""
        self.work.x.array[:] = local
        vec = compat.petsc_vec(self.work)
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return self.work.x.array.copy()

    def vector(self, name: str) -> np.ndarray:
        """A vector form assembled, as a consistent local array."""
        vec = compat.petsc_vec(self.work)
        with vec.localForm() as loc:
            loc.set(0.0)
        fem_petsc.assemble_vector(vec, self.forms[name])
        vec.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        vec.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        return self.work.x.array.copy()

    def cell_vector(self, name: str) -> np.ndarray:
        """A DG0 vector form assembled: its owned entries (one per owned cell)."""
        cells = compat.petsc_vec(self.cell_work)
        with cells.localForm() as loc:
            loc.set(0.0)
        fem_petsc.assemble_vector(cells, self.forms[name])
        cells.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        return cells.array.copy()

    def dot(self, a: np.ndarray, b: np.ndarray) -> float:
        """Sum of a * b over the owned dofs of all ranks."""
        n = self.owned
        return self.problem.comm.allreduce(float(a[:n] @ b[:n]), op=MPI.SUM)

    def solve(self, form: str, rhs: np.ndarray) -> None:
        """lambda = A^-1 rhs into ``lam``, A the form with the pins' rows and columns
        replaced by the identity, rhs zero on pinned dofs (collective)."""
        start = time.perf_counter()
        self.H.zeroEntries()
        fem_petsc.assemble_matrix(self.H, self.forms[form], bcs=self.problem.displacement_bcs)
        ipc = self.problem.ipc
        if ipc is not None and form == "hessian":  # the barrier's (and friction's) exact one
            self.H.assemble(PETSc.Mat.AssemblyType.FLUSH)
            projection = ipc.projection
            ipc.exact_hessian(True)
            ipc.add_hessian(self.H, float(self.problem.weight.value))
            ipc.projection = projection
        self.H.assemble()
        mid = time.perf_counter()
        rhs = rhs.copy()
        rhs[self.pinned] = 0.0
        self.b.array[:] = rhs[: self.owned]
        self.ksp.setOperators(self.H)
        self.ksp.solve(self.b, self.x)
        self.x.copy(compat.petsc_vec(self.lam))
        compat.petsc_vec(self.lam).ghostUpdate(addv=PETSc.InsertMode.INSERT,
                                               mode=PETSc.ScatterMode.FORWARD)
        self.solve_s["assembly"] += mid - start
        self.solve_s["solve"] += time.perf_counter() - mid

    def material_bar(self, prefix: str) -> dict[str, float]:
        """-d<R, lambda>/dtheta for each material and damping parameter, by the chain rule
        (the cell-wise derivatives summed over the parameter's cells and the ranks)."""
        partial = {name: self.cell_vector(f"{prefix}_{name}")
                   for name in self.parameters.coefficients}
        out = {}
        for name in self.parameters.names:
            direction = self.parameters.material_direction(name)
            if direction is None:
                continue
            mask = self.parameters.cell_mask(direction.group)
            cells = sum(factor * partial[c] for c, factor in direction.terms) * mask
            self.cell_gradient[name] = self.cell_gradient.get(name, 0.0) - cells
            out[name] = -self.problem.comm.allreduce(float(cells.sum()), op=MPI.SUM)
        return out

    # -- the sweep ----------------------------------------------------------------------
    def run(self, sim, tape, state_bars: list[dict]) -> np.ndarray:
        """dJ/dtheta from the adjoint of each state (collective).

        Args:
            sim: The :class:`~fem_anim.simulation.loop.Simulation` of the forward run.
            tape: Its :class:`~fem_anim.adjoint.tape.Tape` (its ``reverse`` gives s_n and
                s_{n+1}; the revolve storage re-steps ``sim`` between them).
            state_bars: For each state n, the objective's dJ/ds_n (field -> consistent local
                array; absent fields are zero). Modified in place.

        Returns:
            The gradient, in the order of the parameters' names.
        """
        p, integ, h = self.problem, sim.integrator, tape.h
        self.solve_s = {"assembly": 0.0, "solve": 0.0}
        self.cell_gradient = {}
        names = self.parameters.names
        grad = dict.fromkeys(names, 0.0)
        zero = np.zeros_like(tape.states[0].u)
        # s_n and s_{n+1} backwards, from memory, disk or recomputed (revolve): between
        # two steps of this loop the forward may have been re-stepped, so each is re-staged
        for n, start, end in tape.reverse(sim):
            bar = {k: state_bars[n + 1].get(k, zero) for k in STATE_FIELDS}
            if self.handles and self.newmark:  # the handles' v and a: their rates at t
                bar = self._handle_rates_bar(bar, end.time, grad)
            maps = linear_maps(integ, h, start)
            U = maps["U"]
            x_bar = sum(U[o, "x"] * bar[o] for o in STATE_FIELDS)
            y_bar = sum(U[o, "y"] * bar[o] for o in STATE_FIELDS)
            s_bar = {k: sum(U[o, k] * bar[o] for o in STATE_FIELDS) for k in maps["inputs"]}
            # the step's objective as the forward staged it, at its solution
            self.stage(sim, tape, n, start)
            p.u.x.array[:] = end.u
            self.solve("hessian", x_bar)
            if self.handles:  # x's pinned values u_D(t): x_bar - H lambda there
                pinned_bar = x_bar - self.vector("hlam")
                for name in self.handles:
                    grad[name] += self.dot(pinned_bar,
                                           self.parameters.handle_bases(name, end.time)[0])
            y_bar = y_bar - self.vector("y")
            for name, value in self.material_bar("theta").items():
                grad[name] += value
            if "contact.friction" in grad:  # IPC's mu: R_mu = w grad D / mu
                grad["contact.friction"] -= self._ipc_mu_bar()
            d_bar = -self.vector("d") if p.damped else None
            target = state_bars[n]
            for k in maps["inputs"]:
                total = s_bar[k] + maps["P"][k] * y_bar
                if d_bar is not None:
                    total = total + maps["D"][k] * d_bar
                target[k] = target.get(k, zero) + total
            if self.lagged:  # R's dependence on u_n through the lagged friction
                target["u"] = target["u"] - self.vector("prev")
            if p.ipc is not None and p.ipc.friction is not None:
                target["u"] = target["u"] + self._ipc_friction_bar()
        bar0 = {"u": state_bars[0].get("u", zero), "v": state_bars[0].get("v", zero)}
        if self.newmark:
            u_part, v_part = self._initial_acceleration(tape.initial, state_bars[0], grad)
            bar0 = {"u": bar0["u"] + u_part, "v": bar0["v"] + v_part}
        #: dJ/du_0 and dJ/dv_0 per dof (consistent local arrays; zero on pinned dofs)
        self.initial_bar = {k: a.copy() for k, a in bar0.items()}
        for a in self.initial_bar.values():
            a[self.pinned] = 0.0
        for name in names:  # u_0 and v_0's dependence on the parameters
            for field, basis in self.parameters.initial_bases(name, p):
                grad[name] += self.dot(bar0[field], basis)
        return np.array([grad[name] for name in names])

    def stage(self, sim, tape, n: int, start: State) -> None:
        """Stage step n's objective as the forward did (collective): the predictor, weight,
        damping anchor and pins from the state at its start, and IPC's recorded barrier
        stiffness (the adaptive schedule is not re-run: kappa and d_hat are constants of
        the step) with friction lagged at u_n; ``start`` is s_n."""
        p, integ, h = self.problem, sim.integrator, tape.h
        u_pred = integ.predictor(h, start)
        damping = integ.damping_anchor(h, start) if p.damped else None
        ipc, p.ipc = p.ipc, None
        try:
            p.stage(start.u, u_pred, integ.weight(h, start), start.time + h, h, damping)
        finally:
            p.ipc = ipc
        if ipc is not None:
            p.u.x.array[:] = start.u
            ipc.weight = float(p.weight.value)
            ipc.restage(tape.barrier_stiffness[n], h)

    def _ipc_friction_bar(self) -> np.ndarray:
        """-dR/du_n^T lambda of IPC's lagged friction (collective).

        R holds w grad D(x; x_n) = -w F(x_n, v) with F ipctk's friction force, v = x - x_n
        the slip and the normal forces and tangent bases taken at x_n, so
        dR/du_n = -w (dF/dx_n - dF/dv) and

            -dR/du_n^T lambda = w (dF/dx_n)^T lambda + w Hess D lambda

        (``force_jacobian`` with respect to the lagged displacements, and the exact,
        unprojected Hessian of D).
        """
        ipc = self.problem.ipc  # the pairs are distributed: fem_anim.contact.distribution
        rows = ipc.friction_adjoint(self.lam.x.array, float(self.problem.weight.value))
        local = np.zeros_like(self.lam.x.array)
        local.reshape(-1, ipc.gdim)[: rows.shape[0]] = rows
        return self.consistent(local)

    def _handle_rates_bar(self, bar: dict, t: float, grad: dict) -> dict:
        """Newmark puts the handles' exact rates at t into v and a at their nodes
        (:meth:`fem_anim.problem.pins.Pins.prescribe_pin_rates`): adds the velocity
        parameters' part and returns the adjoint with those entries cut from the update."""
        for name in self.handles:
            grad[name] += self.dot(bar["v"], self.parameters.handle_bases(name, t)[1])
        bar = dict(bar)
        for k in ("v", "a"):
            bar[k] = bar[k].copy()
            bar[k][self.handle_dofs] = 0.0
        return bar

    def _ipc_mu_bar(self) -> float:
        """<dR/dmu, lambda> of IPC's friction coefficient at the step's solution
        (collective): D = mu D_1 with the normal forces and tangent bases lagged at x_n,
        so dR/dmu = w grad D / mu, grad D the difference of ipctk's gradients with and
        without friction."""
        ipc, w = self.problem.ipc, float(self.problem.weight.value)
        x = ipc._update()
        rows = ipc._gradient_rows(x, w, True) - ipc._gradient_rows(x, w, False)
        local = np.zeros_like(self.lam.x.array)
        local.reshape(-1, ipc.gdim)[: rows.shape[0]] = rows
        return self.dot(local, self.lam.x.array) / float(ipc.cfg["friction"])

    def _initial_acceleration(self, state: State, bar: dict,
                              grad: dict) -> tuple[np.ndarray, np.ndarray]:
        """Back through M a_0 = -grad E(u_0) - C v_0: adds theta's part to ``grad`` and
        returns u_0's and v_0's."""
        p = self.problem
        a_bar = bar.get("a", np.zeros_like(state.u)).copy()
        p.u.x.array[:] = state.u
        p.v.x.array[:] = state.v
        self.a0.x.array[:] = state.a
        self.solve("mass", a_bar)
        for name, value in self.material_bar("theta0").items():
            grad[name] += value
        return -self.vector("u0"), -self.vector("v0")
