"""The time loop: scene -> mesh -> problem -> integrator -> solver -> output (STYLE rule 1).

:class:`Simulation` builds everything a scene declares (collectively, under MPI),
then :meth:`Simulation.run` advances ``time.steps`` steps of size ``time.dt``, each one
minimisation of the step objective (seed eq. 4), writing frames, statistics and the
final state. :meth:`Simulation.step` is the single step, usable on its own.
"""

from __future__ import annotations

import math
import signal
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx.fem import petsc as fem_petsc

from fem_anim import compat
from fem_anim.simulation.checkpoint import load_checkpoint, save_checkpoint
from fem_anim.simulation.energy_report import moving_pins
from fem_anim.errors import ConvergenceError, FemAnimError, Interrupted, describe_os_error
from fem_anim.simulation.initial_state import initial_velocity
from fem_anim.simulation.integrators import Integrator, State
from fem_anim.mesh.bodies import build_scene_mesh
from fem_anim.simulation.interrupt import Interrupts
from fem_anim.mesh.build import SimplexMesh
from fem_anim.output.files import (CellGather, RunDirectory, StatsWriter, TrajectoryWriter, VertexGather,
                     write_final, write_scene)
from fem_anim.petsc_options import flatten_options, merge_options
from fem_anim.solver.presets import (MIXED_ONLY_PRESETS, NEWTON_DEFAULTS, drop_replaced, forcing_options,
                      parallel_note, preset_options)
from fem_anim.problem.objective import JIT_OPTIONS, EnergyProblem
from fem_anim.simulation.progress import Progress
from fem_anim.output.provenance import WallClock
from fem_anim.scene.consistency import MIXED_PRESETS
from fem_anim.solver.minimiser import NONLINEAR_METHODS, Minimiser, SolveStats

__all__ = ["Simulation", "RunResult", "AdaptiveStepper", "solver_options"]


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
    if scene["solver"]["hessian"] in ("shift", "auto"):
        layer = layer | {"mat_mumps_icntl_13": "1"}  # exact inertia from MUMPS in parallel
    try:  # the scene checked the method; the preset may come from the command line
        forcing = forcing_options(scene["solver"]["forcing"], merge_options(layer, above))
    except ValueError as err:
        raise FemAnimError(str(err)) from None
    return merge_options(NEWTON_DEFAULTS, method, layer, forcing, above)


@dataclass
class RunResult:
    """What a finished run produced."""

    state: State
    rows: list[dict]
    output_dir: Path | None
    final_displacement: np.ndarray | None  # rank 0, input vertex order
    resumed_rows: int = 0  # rows taken over from the checkpoint of a resumed run


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
        self._average_mass = None  # of a vertex (kg), for IPC's adaptive stiffness
        self.cell_gather = CellGather(self.domain)
        self.clock.add("compile", self.problem.compile_s)
        self.clock.add("setup", time.perf_counter() - start - self.clock.seconds["mesh"]
                       - self.problem.compile_s)

    # -- state ----------------------------------------------------------------------------
    def initial_state(self) -> State:
        """Rest shape, at rest or with the rigid velocity of ``[initial]``
        (:mod:`fem_anim.simulation.initial_state`); for Newmark a_0 = M^-1 (f(x_0) - C v_0), zero on pinned
        dofs (seed eq. 1b)."""
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
        """a = M^-1 (f(u) - C v), zero on pinned dofs (C: Rayleigh damping, if declared)."""
        p = self.problem
        v = np.zeros_like(u) if v is None else v
        p.u.x.array[:] = u
        p.update_quadrature_data()
        f = fem_petsc.assemble_vector(p.potential_gradient_form)
        f.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        f.scale(-1.0)
        if p.damping_force_form is not None:  # M a_0 = f_0 - C v_0
            p.v.x.array[:] = v
            fem_petsc.assemble_vector(f_damp := f.duplicate(), p.damping_force_form)
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
        """Advance one step of size ``h`` (stage, solve, update).

        Raises:
            ConvergenceError: if the minimisation fails; ``state`` is left untouched.
        """
        p, integ = self.problem, self.integrator
        u_pred = integ.predictor(h, state)
        p.u_pred.x.array[:] = u_pred
        p.u_prev.x.array[:] = state.u
        p.weight.value = integ.weight(h, state)
        if p.damping_force_form is not None:
            c, anchor = integ.damping_anchor(h, state)
            p.damping_coefficient.value = c
            p.u_anchor.x.array[:] = anchor
        p.set_pinned_displacement(state.time + h)
        if p.contact is not None:
            p.contact.stage(h)
        what = f"step {state.step + 1} (t = {state.time + h:.6g} s)"
        if p.ipc is not None:
            self._stage_ipc(state.u, h)
        g0 = self._initial_guess(u_pred, state.u, what)
        if g0 is not None:
            self.minimiser.seed_objective(p.x_work, g0)
        stats = self.minimiser.solve(p.x_work, what=what)
        p.set_state(p.x_work)
        if p.ipc is not None:
            p.ipc.finish_step()
        new = integ.update(h, state, p.u.x.array.copy(), u_pred)
        if integ.name == "newmark":
            # The trapezoidal update v_{n+1} = 2 (u_{n+1} - u_n)/h - v_n would carry a kink
            # of the prescribed motion (a handle stopping) on as a +-v oscillation of the
            # pinned dofs, which never decays and leaks into the free dofs through the
            # consistent mass; the pins' exact rates replace it.
            p.prescribe_pin_rates(new.time, new.v, new.a)
        p.v.x.array[:] = new.v
        return new, stats

    def _stage_ipc(self, u: np.ndarray, h: float) -> None:
        """kappa of this step at u_n (:meth:`fem_anim.contact.ipc.IPCContact.stage`)."""
        p = self.problem
        p.u.x.array[:] = u
        p.update_quadrature_data()
        f = fem_petsc.assemble_vector(p.potential_gradient_form)
        f.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
        if self._average_mass is None:
            ones = f.duplicate()
            ones.set(1.0)
            M = fem_petsc.assemble_matrix(p.mass_form)
            M.assemble()
            Mones = ones.duplicate()
            M.mult(ones, Mones)  # 1^T M 1 = d m_total over d n_vertices dofs
            self._average_mass = Mones.sum() / ones.getSize()
            for obj in (ones, Mones, M):
                obj.destroy()
        grad = np.zeros_like(p.u.x.array)
        grad[: f.array.size] = f.array
        f.destroy()
        p.ipc.stage(float(p.weight.value), grad, self._average_mass, h)

    def _collision_free_guess(self, u_pred: np.ndarray, u_last: np.ndarray, what: str) -> None:
        """With ``[contact]``: u_n + alpha (u_pred - u_n), pins at their targets, with
        alpha ipctk's collision-free step size, so the start has no intersection (the
        barrier is finite on crossed surfaces: the objective cannot reject them).

        Moving pins go only as far as alpha too: Newton's pinned rows x - u_bc then bring
        them to their targets, each step capped by the CCD, so a pin never pushes one
        surface through another; if it cannot get there the step fails and is retried
        smaller (:class:`AdaptiveStepper`).
        """
        p = self.problem
        u = compat.petsc_vec(p.u)
        p.u.x.array[:] = u_pred
        fem_petsc.set_bc(u, p.bcs)
        u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
        target = p.u.x.array.copy()
        p.u.x.array[:] = u_last
        alpha = p.ipc.step_bound(u_last - target)
        for guess in (u_last + alpha * (target - u_last), u_last):
            p.u.x.array[:] = guess
            u.copy(p.x_work)
            if math.isfinite(p.objective(None, p.x_work)):
                return
        raise ConvergenceError(f"{what}: no collision-free start with every element "
                               "uninverted: reduce time.dt")

    def _initial_guess(self, u_pred: np.ndarray, u_last: np.ndarray, what: str) -> float | None:
        """Start Newton where the objective is finite: the predictor, else u_n, else the
        linearised response to the pins' motion; returns g there (None: not evaluated), for
        the minimiser to reuse.

        A large predicted step, or pins that move far in one step, can invert elements,
        where energies such as neo-Hookean's are undefined (+inf with the inversion
        filter). The last resort is one Newton step from u_n with the pins still at their
        old positions: the residual's lifting term carries the pins' increment into the
        free dofs through the Hessian (a linear-elastic extension of the motion).

        Raises:
            ConvergenceError: if even that start inverts an element.
        """
        p = self.problem
        x = p.x_work
        if p.ipc is not None:
            self._collision_free_guess(u_pred, u_last, what)
            return None
        for guess in (u_pred, u_last):
            p.load_guess(guess, x)
            if math.isfinite(g := p.objective(None, x)):
                return g
        p.load_guess(u_last, x, apply_bcs=False)
        r, step = x.duplicate(), x.duplicate()
        p.residual(None, x, r)
        self.minimiser.newton_step(x, r, step)
        x.axpy(-1.0, step)
        r.destroy()
        step.destroy()
        if not math.isfinite(g := p.objective(None, x)):
            why = "the pins move too far in one step" if moving_pins(self.scene) else \
                "the motion predicted over one step inverts elements or overflows"
            raise ConvergenceError(f"{what}: no start for Newton gives a finite step "
                                   f"objective ({why}): reduce time.dt")
        return g

    # -- the run --------------------------------------------------------------------------
    def run(self, output_dir: Path | None = None, quiet: bool = False,
            resume: bool = False) -> RunResult:
        """Run ``time.steps`` frames, writing outputs to ``output_dir`` (None: no files).

        With ``resume``, continue the unfinished run in ``output_dir`` from its last
        checkpoint (:mod:`fem_anim.simulation.checkpoint`). A run that fails, however it fails (an
        error, an OS error, SIGINT/SIGTERM/SIGHUP: :mod:`fem_anim.simulation.interrupt`), leaves its
        staging area (frames so far and the last checkpoint) for ``--resume``, but no file
        posing as a result in ``output_dir``; an interrupted run first writes a
        checkpoint at the frame it stopped.

        Raises:
            Interrupted: after a signal, once the checkpoint is written.
            FemAnimError: for an OS error (naming the file) and every other failure.
        """
        cfg = self.scene["time"]
        h, steps, every = cfg["dt"], cfg["steps"], self.scene["output"]["every"]
        run_dir = RunDirectory(output_dir, self.comm, resume) if output_dir is not None \
            else None
        start = time.perf_counter()
        try:  # nothing is deleted on failure: the staging area is what --resume continues
            with Interrupts(self.comm) as interrupts:
                try:
                    result = self._loop(h, steps, every, run_dir, quiet, resume, interrupts)
                except FemAnimError as err:
                    if interrupts.received is None or isinstance(err, Interrupted):
                        raise
                    name = signal.Signals(interrupts.received).name  # a 2nd signal inside PETSc
                    raise Interrupted(f"interrupted by {name} (twice)",
                                      interrupts.received) from None
            loop_s = time.perf_counter() - start
            stepping = sum(row["step_wall_s"] for row in result.rows[result.resumed_rows:])
            self.clock.add("stepping", stepping)
            self.clock.add("output", loop_s - stepping)  # frames, stats, checkpoints, finals
            if run_dir is not None:
                with self.clock.phase("output"):
                    run_dir.commit()
                if self.scene["output"]["render"]:
                    with self.clock.phase("render"):
                        self._render(run_dir.path, quiet)
        finally:
            if run_dir is not None:
                run_dir.close()
        return result

    def _render(self, path: Path, quiet: bool) -> None:
        """Pictures of the committed run (rank 0, in another process); errors are collective.

        A failed rendering keeps the run's data: ``fem-anim render`` can try again.
        """
        error = None
        if self.comm.rank == 0:
            from fem_anim.render.process import render_run

            try:
                render_run(path, self.scene["render"], quiet=quiet)
            except (FemAnimError, RuntimeError) as err:
                error = f"{err} (the run's data are kept in {path}: render them again with " \
                        f"`fem-anim render {path}`)"
        error = self.comm.bcast(error, root=0)
        if error:
            raise FemAnimError(error)

    def frame_fields(self, state: State) -> tuple[np.ndarray | None, np.ndarray | None]:
        """Vertex displacements and cell energy densities of ``state`` on rank 0 (collective)."""
        return (self.gather.gather(state.u),
                self.cell_gather.gather(self.problem.cell_energy_density(state.u)))

    def _io(self, path: Path, write, *args):
        """``write(*args)`` (rank 0 writes; collective): an OS error becomes one message
        naming the file, raised on every rank."""
        error, result = None, None
        try:
            result = write(*args)
        except OSError as err:
            error = describe_os_error(err, path)
        error = self.comm.bcast(error, root=0)
        if error:
            raise FemAnimError(f"{error} (nothing was deleted)")
        return result

    def _loop(self, h, steps, every, run_dir, quiet, resume, interrupts) -> RunResult:
        stepper = AdaptiveStepper(self, h, self.scene["time"])
        checkpoint_every = self.scene["output"]["checkpoint_every"] or max(1, steps // 10)
        first, rows, kept, resumed_rows = 1, [], None, 0
        if resume:
            ck = load_checkpoint(run_dir.file("checkpoint.npz"), self)
            state, first, rows, kept = ck.state, ck.frame + 1, ck.rows, ck.frames_written
            resumed_rows = len(rows)
            stepper.dt, stepper.last_dt = ck.stepper["dt"], ck.stepper["last_dt"]
            if self.minimiser.shift:
                self.minimiser.shift.c = ck.shift
            if self.problem.ipc is not None:
                self.problem.ipc.restore(ck.contact)
        else:
            state = self.initial_state()
        stats_file = trajectory = None
        if run_dir:  # the trajectory first: a resume it refuses leaves stats.csv as it was
            trajectory = self._io(run_dir.file("trajectory.h5"), TrajectoryWriter,
                                  run_dir.file("trajectory.xdmf"), self.domain, kept)
            stats_file = self._io(run_dir.file("stats.csv"), StatsWriter,
                                  run_dir.file("stats.csv"), self.comm, rows)

        def checkpoint(frame: int) -> None:
            path = run_dir.file("checkpoint.npz")
            self._io(path, save_checkpoint, path, self, state, frame,
                     len(trajectory.times) if trajectory.rank0 else 0, rows,
                     {"dt": stepper.dt, "last_dt": stepper.last_dt})

        progress = Progress(steps, disable=quiet or self.comm.rank != 0)
        progress.update(0, advance=first - 1)
        try:
            if trajectory and not resume:
                self._io(trajectory.h5_path, trajectory.write, 0.0, *self.frame_fields(state))
            for frame in range(first, steps + 1):
                for state, row in stepper.advance(state, frame * h):
                    rows.append(row)
                    if stats_file:
                        self._io(stats_file.path, stats_file.write, row)
                if trajectory and (frame % every == 0 or frame == steps):
                    self._io(trajectory.h5_path, trajectory.write, state.time,
                             *self.frame_fields(state))
                saved = run_dir and frame % checkpoint_every == 0 and frame < steps
                if saved:
                    checkpoint(frame)
                progress.update(row["newton_its"])
                signum = interrupts.pending() if frame < steps else None
                if signum:
                    if run_dir and not saved:
                        checkpoint(frame)
                    raise Interrupted(f"interrupted by {signal.Signals(signum).name} at frame "
                                      f"{frame} of {steps} (t = {state.time:.6g} s)", signum)
        finally:
            progress.close()
            if stats_file:
                stats_file.close()
            if trajectory:
                trajectory.close()
        final, energy_density = self.frame_fields(state)
        if run_dir is not None:
            self._io(run_dir.file("final.vtu"), write_final, run_dir.file("final.vtu"),
                     self.domain, final, energy_density)
            self._io(run_dir.file("scene.json"), write_scene, run_dir.file("scene.json"),
                     self.scene, self.comm)
        return RunResult(state, rows, run_dir.path if run_dir else None, final, resumed_rows)

    def timed_step(self, state: State, dt: float) -> tuple[State, dict]:
        """One step and its stats row; a non-finite result counts as not converged."""
        start = time.perf_counter()
        self._contact_stats()  # the contact time of this step only (not of failed tries)
        new, solve = self.step(state, dt)
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
            **{f"{kind}_its": count for kind, count in solve.hessian_its.items()}, **energies,
            "assembly_s": solve.assembly_s,
            "factor_s": solve.factor_s, "linear_solve_s": solve.linear_solve_s,
            "other_s": wall - solve.assembly_s - solve.factor_s - solve.linear_solve_s,
            "solve_wall_s": solve.wall_s, "step_wall_s": wall, **self._contact_stats()}

    def _contact_stats(self) -> dict:
        """Time in ipctk (detection, barrier, CCD; summed since the last row) and the number
        of active contact pairs at the end of the step (0 without ``[contact]``)."""
        ipc = self.problem.ipc
        if ipc is None:
            return {"contact_s": 0.0, "contact_pairs": 0}
        spent = sum(ipc.timers.values())
        for key in ipc.timers:
            ipc.timers[key] = 0.0
        return {"contact_s": spent, "contact_pairs": self.comm.bcast(ipc.num_pairs, root=0)}

    def _check_finite(self, state: State, energies: dict[str, float]) -> None:
        """No NaN or inf may reach a frame: stop with a clear message instead."""
        bad = not (np.all(np.isfinite(state.u)) and all(map(math.isfinite, energies.values())))
        if self.comm.allreduce(bad, op=MPI.LOR):
            raise ConvergenceError(f"step {state.step} (t = {state.time:.6g} s) produced a "
                                   "non-finite displacement or energy")


class AdaptiveStepper:
    """Adaptive time stepping: halve dt when a step fails, grow it back after successes.

    A frame of length h is reached by substeps. A substep whose minimisation does not
    converge (or whose result is not finite) is discarded, the state is left as it was,
    and it is retried with dt halved, down to ``time.min_dt``; after each success dt is
    doubled again, up to h. Substeps never overshoot a frame time, so frames stay at
    multiples of h and no frame comes from a failed step. BDF2's history assumes a
    constant step: after a change of dt it restarts with one implicit Euler step.
    With ``time.adaptive = false`` the first failure stops the run.
    """

    def __init__(self, sim: Simulation, h: float, time_cfg: dict):
        self.sim = sim
        self.h = h
        self.adaptive = time_cfg["adaptive"]
        self.min_dt = time_cfg["min_dt"] if time_cfg["min_dt"] is not None else h / 256.0
        self.dt = h
        self.last_dt = h

    def advance(self, state: State, t_end: float):
        """Yield (state, stats row) for each accepted substep until ``t_end``."""
        retries = 0
        while t_end - state.time > 1e-9 * self.h:
            dt = min(self.dt, t_end - state.time)
            if dt > t_end - state.time - 1e-9 * self.h:
                dt = t_end - state.time  # land exactly on the frame time
            trial = state
            if self.sim.integrator.name == "bdf2" and abs(dt - self.last_dt) > 1e-12 * self.h:
                trial = replace(state, u_old=None, v_old=None)
            try:
                new, row = self.sim.timed_step(trial, dt)
            except ConvergenceError as err:
                if not self.adaptive or self.dt / 2.0 < self.min_dt:
                    floor = "" if not self.adaptive else \
                        f" (time.min_dt = {self.min_dt:.3g} s reached)"
                    raise ConvergenceError(f"{err}{floor}") from None
                self.dt /= 2.0
                retries += 1
                continue
            row["retries"] = retries
            retries = 0
            self.last_dt = dt
            if dt == self.dt:
                self.dt = min(2.0 * self.dt, self.h)
            state = new
            yield state, row
