"""The simulation of one scene: build it, then step it (seed section 3.1).

:class:`Simulation` builds everything a scene declares (collectively, under MPI): mesh,
step objective (:class:`~fem_anim.problem.objective.EnergyProblem`), integrator and
minimiser. Each step stages the problem from the integrator's predictor, minimises the step
objective (seed eq. 4) and updates the state. Drive it yourself::

    sim = Simulation(scene)
    state = sim.initial_state()
    for _ in range(scene["time"]["steps"]):
        state, stats = sim.step(state, scene["time"]["dt"])

or let :meth:`Simulation.run` advance ``time.steps`` frames with adaptive retries and write
the run's files (:mod:`fem_anim.simulation.run_loop`).
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.errors import ConvergenceError, FemAnimError
from fem_anim.mesh.bodies import build_scene_mesh
from fem_anim.mesh.simplex import SimplexMesh
from fem_anim.output.dof_gather import DofGather
from fem_anim.output.files import CellGather, VertexGather
from fem_anim.output.provenance import WallClock
from fem_anim.petsc_options import flatten_options, merge_options
from fem_anim.problem.form_compiler import JIT_OPTIONS
from fem_anim.problem.objective import EnergyProblem
from fem_anim.scene.consistency import MIXED_PRESETS
from fem_anim.scene.joint_rules import shell_body
from fem_anim.simulation.energy_report import moving_pins
from fem_anim.simulation.handle_work import handle_work
from fem_anim.simulation.initial_state import initial_velocity
from fem_anim.simulation.integrators import Integrator, State
from fem_anim.simulation.newton_start import initial_guess
from fem_anim.simulation.run_loop import RunResult, run_frames
from fem_anim.solver.minimiser import NONLINEAR_METHODS, Minimiser
from fem_anim.solver.solve_stats import SolveStats
from fem_anim.solver.presets import (MIXED_ONLY_PRESETS, NEWTON_DEFAULTS, drop_replaced,
                                     forcing_options, parallel_note, preset_options)

__all__ = ["Simulation", "solver_options"]


def solver_options(scene, cli_options: dict[str, str] | None = None,
                   preset: str | None = None, comm_size: int = 1) -> dict[str, str]:
    """Merged PETSc options: defaults < method < preset < scene ``[solver.petsc]`` < command line.

    The preset is its parallel variant when ``comm_size > 1``
    (:func:`fem_anim.solver.presets.parallel_options`). A preset's options that belong to a
    component a higher layer replaces (its ``pc_*`` when ``pc_type`` changes, ...) are
    dropped with it (``-pc_type icc`` on top of the MUMPS ``cholesky`` preset is ICC,
    not "ICC by MUMPS"; :func:`fem_anim.solver.presets.drop_replaced`). ``solver.forcing``
    (:func:`fem_anim.solver.presets.forcing_options`) sits above the preset, below the scene's
    own PETSc table.

    Raises:
        FemAnimError: for an unknown preset name (naming ``solver.preset`` or ``--solver``),
            or ``solver.forcing = "adaptive"`` where no Krylov solve is adapted.
    """
    name = preset or scene["solver"]["preset"]
    key = "--solver" if preset else "solver.preset"
    try:
        layer = preset_options(name, comm_size=comm_size)
    except KeyError as err:
        raise FemAnimError(f"{key}: {err.args[0]}") from None
    mixed = scene["element"].get("formulation") == "mixed"
    if mixed and name not in MIXED_PRESETS:
        raise FemAnimError(f"{key} = {name!r} cannot solve the saddle-point Hessian of "
                           f"element.formulation = \"mixed\" (symmetric indefinite): use one "
                           f"of {', '.join(MIXED_PRESETS)}")
    if not mixed and name in MIXED_ONLY_PRESETS:
        raise FemAnimError(f"{key} = {name!r} splits displacement and pressure: it needs "
                           "element.formulation = \"mixed\"")
    above = merge_options(flatten_options(scene["solver"]["petsc"]), cli_options or {})
    layer = drop_replaced(layer, above)
    method = NONLINEAR_METHODS[scene["solver"]["method"]]
    if scene["solver"]["method"] == "lbfgs" and scene["solver"]["hessian_update"] != \
            "every_iteration":  # the kept Hessian is L-BFGS's initial one (hessian_reuse.py)
        method = method | {"snes_qn_scale_type": "jacobian"}
    try:  # the scene checked the method; the preset may come from the command line
        forcing = forcing_options(scene["solver"]["forcing"], merge_options(layer, above))
    except ValueError as err:
        raise FemAnimError(str(err)) from None
    return merge_options(NEWTON_DEFAULTS, method, layer, forcing, above)


class Simulation:
    """One scene, built and ready to step.

    Args:
        scene: A validated :class:`~fem_anim.scene.schema.Scene`.
        comm: MPI communicator.
        cli_options: PETSc options from the command line (highest precedence).
        preset: Linear solver preset overriding ``solver.preset``.
        domain: A mesh made elsewhere (e.g. from arrays with
            :func:`fem_anim.mesh.build.mesh_from_arrays`) instead of the scene's ``[mesh]``.
    """

    def __init__(self, scene, comm: MPI.Comm = MPI.COMM_WORLD,
                 cli_options: dict[str, str] | None = None, preset: str | None = None,
                 domain: SimplexMesh | None = None):
        if shell_body(scene.data) is not None:
            raise FemAnimError("a scene with a shell [[body]] beside solids is two meshes "
                               "stepped together: run it with `fem-anim run` or fem_anim.run "
                               "(fem_anim.simulation.JointSimulation from Python)")
        self.scene = scene
        self.comm = comm
        #: Wall time per phase (summary.json's ``wall``: :mod:`fem_anim.output.provenance`).
        self.clock = WallClock()
        start = time.perf_counter()
        #: The merged PETSc options of the step solver (summary.json's ``petsc_options``).
        self.options = options = solver_options(scene, cli_options, preset, comm.size)
        note = parallel_note(preset or scene["solver"]["preset"], comm.size)
        if note and comm.rank == 0:
            print(f"fem-anim: {note}", file=sys.stderr)
        with self.clock.phase("mesh"):
            self.domain = domain if domain is not None else build_scene_mesh(comm, scene)
        with compat.jit_locks_released(JIT_OPTIONS):  # a Ctrl-C while compiling
            self.problem = EnergyProblem(scene, self.domain)
        self.integrator = Integrator(scene["time"]["integrator"])
        self.minimiser = Minimiser(self.problem, options, settings=scene["solver"])
        self.minimiser.require_read(cli_options or {})
        self.gather = VertexGather(self.domain, self.problem.V)
        self.cell_gather = CellGather(self.domain)
        self._handles = moving_pins(scene)  # stats' handle_work needs computing
        #: The fields the trajectory holds at every dof (``output.fields``), by name.
        self.dof_gathers = self._dof_gathers()
        self.clock.add("compile", self.problem.compile_s)
        self.clock.add("setup", time.perf_counter() - start - self.clock.seconds["mesh"]
                       - self.problem.compile_s)

    # -- state ----------------------------------------------------------------------------
    def initial_state(self) -> State:
        """The state at t = 0, to start :meth:`step` from (collective).

        The rest shape (u = 0), at rest or with the rigid velocity of ``[initial]``
        (:mod:`fem_anim.simulation.initial_state`); for Newmark a_0 = M^-1 (f(x_0) - C v_0),
        zero on pinned dofs (seed eq. 1b), else a_0 = 0.

        Returns:
            A :class:`~fem_anim.simulation.integrators.State` of local dof values of V
            (ghosts included): u (m), v (m/s), a (m/s^2), time 0 s, step 0.
        """
        p = self.problem
        n = p.u.x.array.size
        state = State(u=np.zeros(n), v=np.zeros(n), a=np.zeros(n))
        v0 = initial_velocity(self.scene, p)
        if v0 is not None:
            state.v = v0
            p.v.x.array[:] = v0
        if self.integrator.name == "newmark":
            state.a = self.acceleration(state.u, state.v)
        return state

    def acceleration(self, u: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """a = M^-1 (f(u) - C v) (m/s^2), zero on pinned dofs (collective).

        f = -grad E(u) (elastic and gravity forces), C the Rayleigh damping matrix if
        declared, f_d a shell's wind drag at (u, v) if declared; u (m) and v (m/s) are local dof values of V, ghosts included.
        """
        p = self.problem
        v = np.zeros_like(u) if v is None else v
        p.u.x.array[:] = u
        p.update_quadrature_data()
        f = fem_petsc.assemble_vector(p.potential_gradient_form)
        f.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        f.scale(-1.0)
        for form in (p.damping_force_form, p.drag_force_form):  # M a_0 = f_0 - C v_0 + f_d
            if form is None:
                continue
            p.v.x.array[:] = v
            fem_petsc.assemble_vector(f_damp := f.duplicate(), form)
            f_damp.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            f.axpy(-1.0, f_damp)
            f_damp.destroy()
        fem_petsc.set_bc(f, p.displacement_bcs, None, 0.0)
        M = fem_petsc.assemble_matrix(p.mass_form, p.displacement_bcs)
        M.assemble()
        ksp = PETSc.KSP().create(self.comm)
        ksp.setOperators(M)
        ksp.setType("cg")
        ksp.getPC().setType("jacobi")
        ksp.setTolerances(rtol=1e-14, atol=0.0, max_it=10000)
        a = f.duplicate()
        ksp.solve(f, a)
        a.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        with a.localForm() as loc:
            out = loc.array.copy()
        for obj in (ksp, M, f, a):
            obj.destroy()
        return out

    # -- one step -------------------------------------------------------------------------
    def step(self, state: State, h: float) -> tuple[State, SolveStats]:
        """Advance one step of size ``h``: stage, solve, update.

        Stages the problem (:meth:`~fem_anim.problem.objective.EnergyProblem.stage`) with
        the integrator's predictor and weight, minimises the step objective (seed eq. 4)
        from a start where it is finite (:mod:`fem_anim.simulation.newton_start`), and
        updates velocity and acceleration by the scheme (seed eq. 1b for Newmark).
        Collective under MPI.

        Args:
            state: The state at the step's start: local dof values of V (ghosts included)
                of displacement u (m), velocity v (m/s), acceleration a (m/s^2), BDF2's
                previous step, time (s) and step count; not modified.
            h: Step size (s).

        Returns:
            The state at t + h, and the solver's statistics of the step.

        Raises:
            ConvergenceError: if the minimisation fails or no start has a finite
                objective; ``state`` is left untouched (retry with a smaller ``h``).
        """
        p, integ = self.problem, self.integrator
        u_pred = integ.predictor(h, state)
        damping = integ.damping_anchor(h, state) if p.damped else None
        p.stage(state.u, u_pred, integ.weight(h, state), state.time + h, h, damping)
        what = f"step {state.step + 1} (t = {state.time + h:.6g} s)"
        g0 = initial_guess(p, self.minimiser, self.scene, u_pred, state.u, what)
        if g0 is not None:
            self.minimiser.seed_objective(p.x_work, g0)
        stats = self.minimiser.solve(p.x_work, what=what)
        p.set_state(p.x_work)
        new = integ.update(h, state, p.u.x.array.copy(), u_pred)
        # Newmark: the trapezoidal update v_{n+1} = 2 (u_{n+1} - u_n)/h - v_n would carry a
        # kink of the prescribed motion (a handle stopping) on as a +-v oscillation of the
        # pinned dofs, which never decays and leaks into the free dofs through the
        # consistent mass; the pins' exact rates replace it.
        p.finish_step(new.time, new.v, new.a, pin_rates=integ.name == "newmark")
        return new, stats

    # -- the run --------------------------------------------------------------------------
    def run(self, output_dir: Path | None = None, quiet: bool = False,
            resume: bool = False) -> RunResult:
        """Run ``time.steps`` frames, writing outputs to ``output_dir`` (None: no files).

        Each frame of length ``time.dt`` is reached by adaptive substeps
        (:class:`~fem_anim.simulation.adaptive.AdaptiveStepper`). With ``resume``, continue
        the unfinished run in ``output_dir`` from its last checkpoint
        (:mod:`fem_anim.simulation.checkpoint`). A run that fails, however it fails (an
        error, an OS error, SIGINT/SIGTERM/SIGHUP: :mod:`fem_anim.simulation.interrupt`),
        leaves its staging area (frames so far and the last checkpoint) for ``--resume``,
        but no file posing as a result in ``output_dir``; an interrupted run first writes a
        checkpoint at the frame it stopped. Collective under MPI.

        Args:
            output_dir: The run directory, or None to write nothing.
            quiet: No progress bar.
            resume: Continue the unfinished run in ``output_dir``.

        Returns:
            The final state, the stats rows and the final displacement (rank 0).

        Raises:
            Interrupted: after a signal, once the checkpoint is written.
            FemAnimError: for an OS error (naming the file) and every other failure.
        """
        return run_frames(self, output_dir, quiet, resume)

    def frame_fields(self, state: State) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Vertex displacements and cell energy densities of ``state`` on rank 0 (collective)."""
        return (self.gather.gather(state.u),
                self.cell_gather.gather(self.problem.cell_energy_density(state.u)))

    def _dof_gathers(self) -> dict[str, DofGather]:
        """A P2 body's displacement, and the listed velocity and pressure (collective)."""
        p, fields = self.problem, self.scene["output"]["fields"]
        out = {}
        if self.scene["element"]["degree"] > 1 or "velocity" in fields:
            gather = DofGather(self.domain, p.V)
            if self.scene["element"]["degree"] > 1:
                out["displacement"] = gather
            if "velocity" in fields:
                out["velocity"] = gather
        if "pressure" in fields:
            out["pressure"] = DofGather(self.domain, p.fields.Q)
        return out

    def frame_dofs(self, state: State) -> dict[str, np.ndarray | None]:
        """Every dof of the fields of :attr:`dof_gathers` on rank 0 (None elsewhere;
        collective): displacement (m), velocity (m/s) and pressure p = mu p~ (Pa; the
        mixed unknown's p~ = p / mu, :mod:`fem_anim.problem.mixed_space`), as the last
        step left it."""
        p = self.problem
        values = {"displacement": lambda: state.u, "velocity": lambda: state.v,
                  "pressure": lambda: float(p.mu.value) * p.p.x.array}
        return {name: g.gather(values[name]()) for name, g in self.dof_gathers.items()}

    def timed_step(self, state: State, dt: float) -> tuple[State, dict]:
        """:meth:`step`, its energies and its stats row (a ``stats.csv`` row; collective).

        Raises:
            ConvergenceError: as :meth:`step`, and for a non-finite displacement or energy.
        """
        start = time.perf_counter()
        self._contact_stats(row=False)  # this step's contact time only (not failed tries')
        new, solve = self.step(state, dt)
        work = handle_work(self.problem, state.u, self.problem.x_work) if self._handles \
            else 0.0
        energies = self.problem.energies()
        self._check_finite(new, energies)
        wall = time.perf_counter() - start
        return new, {
            "step": new.step, "time": new.time, "dt": dt, "newton_its": solve.newton_its,
            "linear_its": solve.linear_its, "snes_reason": solve.reason,
            "residual_norm": solve.residual_norm,
            "initial_residual_norm": solve.initial_residual_norm,
            "newton_decrement": solve.newton_decrement, "shift": solve.shift,
            "residual_ratio": solve.residual_ratio,
            "hessian_assemblies": solve.hessian_assemblies,
            "factorisations": solve.factorisations,
            "inertia_checks": solve.inertia_checks,
            "inertia_fallbacks": solve.inertia_fallbacks,
            **{f"{kind}_its": count for kind, count in solve.hessian_its.items()}, **energies,
            "handle_work": work,
            "assembly_s": solve.assembly_s,
            "factor_s": solve.factor_s, "linear_solve_s": solve.linear_solve_s,
            "other_s": wall - solve.assembly_s - solve.factor_s - solve.linear_solve_s,
            "solve_wall_s": solve.wall_s, "step_wall_s": wall, **self._contact_stats()}

    def _contact_stats(self, row: bool = True) -> dict:
        """Time in ipctk (detection, barrier, CCD; summed since the last row) and, with
        ``[contact]``, the step's barrier stiffness, d-hat, pairs, smallest distance and
        friction lags at its end (:meth:`fem_anim.contact.ipc.IPCContact.step_stats`;
        without ``[contact]``: 0 pairs, and NaN for the quantities that do not apply)."""
        ipc = self.problem.ipc
        if ipc is None:
            return {"contact_s": 0.0, "contact_pairs": 0, **dict.fromkeys(
                ("barrier_stiffness", "dhat", "min_distance", "friction_lags"), math.nan)}
        spent = sum(ipc.timers.values())
        for key in ipc.timers:
            ipc.timers[key] = 0.0
        return {"contact_s": spent, **(ipc.step_stats() if row else {})}

    def _check_finite(self, state: State, energies: dict[str, float]) -> None:
        """No NaN or inf may reach a frame: stop with a clear message instead."""
        bad = not (np.all(np.isfinite(state.u)) and all(map(math.isfinite, energies.values())))
        if self.comm.allreduce(bad, op=MPI.LOR):
            raise ConvergenceError(f"step {state.step} (t = {state.time:.6g} s) produced a "
                                   "non-finite displacement or energy")
