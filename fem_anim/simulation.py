"""The time loop: scene -> mesh -> problem -> integrator -> solver -> output (STYLE rule 1).

:class:`Simulation` builds everything a scene declares (collectively, under MPI),
then :meth:`Simulation.run` advances ``time.steps`` steps of size ``time.dt``, each one
minimisation of the step objective (seed eq. 4), writing frames, statistics and the
final state. :meth:`Simulation.step` is the single step, usable on its own.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from mpi4py import MPI
from petsc4py import PETSc

from dolfinx.fem import petsc as fem_petsc

from . import compat
from .checkpoint import load_checkpoint, save_checkpoint
from .errors import ConvergenceError, FemAnimError
from .initial import initial_velocity
from .integrator import Integrator, State
from .mesh import SimplexMesh, build_mesh
from .output import (CellGather, RunDirectory, StatsWriter, TrajectoryWriter, VertexGather,
                     write_final, write_scene)
from .petsc_options import flatten_options, merge_options
from .presets import (NEWTON_DEFAULTS, drop_replaced, forcing_options, parallel_note,
                      preset_options)
from .problem import EnergyProblem
from .progress import Progress
from .solver import NONLINEAR_METHODS, Minimiser, SolveStats

__all__ = ["Simulation", "RunResult", "AdaptiveStepper", "solver_options"]


def solver_options(scene, cli_options: dict[str, str] | None = None,
                   preset: str | None = None, comm_size: int = 1) -> dict[str, str]:
    """Merged PETSc options: defaults < method < preset < scene ``[solver.petsc]`` < command line.

    The preset is its parallel variant when ``comm_size > 1``
    (:func:`fem_anim.presets.parallel_options`). A preset's options that belong to a
    component a higher layer replaces (its ``pc_*`` when ``pc_type`` changes, ...) are
    dropped with it (``-pc_type icc`` on top of the MUMPS ``cholesky`` preset is ICC,
    not "ICC by MUMPS"; :func:`fem_anim.presets.drop_replaced`). ``solver.forcing``
    (:func:`fem_anim.presets.forcing_options`) sits above the preset, below the scene's
    own PETSc table.

    Raises:
        FemAnimError: for an unknown preset name (naming ``solver.preset`` or ``--solver``),
            or ``solver.forcing = "adaptive"`` where no Krylov solve is adapted.
    """
    name = preset or scene["solver"]["preset"]
    try:
        layer = preset_options(name, comm_size=comm_size)
    except KeyError as err:
        key = "--solver" if preset else "solver.preset"
        raise FemAnimError(f"{key}: {err.args[0]}") from None
    above = merge_options(flatten_options(scene["solver"]["petsc"]), cli_options or {})
    layer = drop_replaced(layer, above)
    method = NONLINEAR_METHODS[scene["solver"]["method"]]
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


class Simulation:
    """One scene, built and ready to step.

    Args:
        scene: A validated :class:`~fem_anim.scene.Scene`.
        comm: MPI communicator.
        cli_options: PETSc options from the command line (highest precedence).
        preset: Linear solver preset overriding ``solver.preset``.
        domain: A mesh made elsewhere (e.g. from arrays with
            :func:`fem_anim.mesh.mesh_from_arrays`) instead of the scene's ``[mesh]``.
    """

    def __init__(self, scene, comm: MPI.Comm = MPI.COMM_WORLD,
                 cli_options: dict[str, str] | None = None, preset: str | None = None,
                 domain: SimplexMesh | None = None):
        self.scene = scene
        self.comm = comm
        options = solver_options(scene, cli_options, preset, comm.size)
        note = parallel_note(preset or scene["solver"]["preset"], comm.size)
        if note and comm.rank == 0:
            print(f"fem-anim: {note}", file=sys.stderr)
        self.domain = domain if domain is not None else build_mesh(comm, scene)
        self.problem = EnergyProblem(scene, self.domain)
        self.integrator = Integrator(scene["time"]["integrator"])
        self.minimiser = Minimiser(self.problem, options, settings=scene["solver"])
        self.gather = VertexGather(self.domain, self.problem.V)
        self.cell_gather = CellGather(self.domain)

    # -- state ----------------------------------------------------------------------------
    def initial_state(self) -> State:
        """Rest shape, at rest or with the rigid velocity of ``[initial]``
        (:mod:`fem_anim.initial`); for Newmark a_0 = M^-1 (f(x_0) - C v_0), zero on pinned
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
        fem_petsc.set_bc(f, p.bcs, scale=0.0)
        M = fem_petsc.assemble_matrix(p.mass_form, p.bcs)
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
        self._initial_guess(u_pred, state.u, what)
        stats = self.minimiser.solve(p.x_work, what=what)
        p.set_state(p.x_work)
        new = integ.update(h, state, p.u.x.array.copy(), u_pred)
        if integ.name == "newmark":
            # The trapezoidal update v_{n+1} = 2 (u_{n+1} - u_n)/h - v_n would carry a kink
            # of the prescribed motion (a handle stopping) on as a +-v oscillation of the
            # pinned dofs, which never decays and leaks into the free dofs through the
            # consistent mass; the pins' exact rates replace it.
            p.prescribe_pin_rates(new.time, new.v, new.a)
        p.v.x.array[:] = new.v
        return new, stats

    def _initial_guess(self, u_pred: np.ndarray, u_last: np.ndarray, what: str) -> None:
        """Start Newton where the objective is finite: the predictor, else u_n, else the
        linearised response to the pins' motion.

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
        u = compat.petsc_vec(p.u)
        for guess in (u_pred, u_last):
            p.u.x.array[:] = guess
            fem_petsc.set_bc(u, p.bcs)
            u.copy(x)
            if math.isfinite(p.objective(None, x)):
                return
        p.u.x.array[:] = u_last
        u.copy(x)
        r, step = x.duplicate(), x.duplicate()
        p.residual(None, x, r)
        self.minimiser.newton_step(x, r, step)
        x.axpy(-1.0, step)
        r.destroy()
        step.destroy()
        if not math.isfinite(p.objective(None, x)):
            raise ConvergenceError(f"{what}: no start for Newton keeps every element "
                                   "uninverted (the pins move too far in one step): reduce "
                                   "time.dt")

    # -- the run --------------------------------------------------------------------------
    def run(self, output_dir: Path | None = None, quiet: bool = False,
            resume: bool = False) -> RunResult:
        """Run ``time.steps`` frames, writing outputs to ``output_dir`` (None: no files).

        With ``resume``, continue the unfinished run in ``output_dir`` from its last
        checkpoint (:mod:`fem_anim.checkpoint`). A run that fails leaves its staging area
        (frames so far and the last checkpoint) for ``--resume``, but no file posing as a
        result in ``output_dir``.
        """
        cfg = self.scene["time"]
        h, steps, every = cfg["dt"], cfg["steps"], self.scene["output"]["every"]
        run_dir = RunDirectory(output_dir, self.comm, resume) if output_dir is not None \
            else None
        try:
            result = self._loop(h, steps, every, run_dir, quiet, resume)
        except FemAnimError:
            raise  # keep the staging area and its checkpoint: the run can be resumed
        except BaseException:
            if run_dir is not None:
                run_dir.abandon()
            raise
        if run_dir is not None:
            run_dir.commit()
            if self.scene["output"]["render"]:
                self._render(run_dir.path, quiet)
        return result

    def _render(self, path: Path, quiet: bool) -> None:
        """Pictures of the committed run (rank 0, in another process); errors are collective.

        A failed rendering keeps the run's data: ``fem-anim render`` can try again.
        """
        error = None
        if self.comm.rank == 0:
            from .render import render_run

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

    def _loop(self, h, steps, every, run_dir, quiet, resume) -> RunResult:
        stepper = AdaptiveStepper(self, h, self.scene["time"])
        checkpoint_every = self.scene["output"]["checkpoint_every"] or max(1, steps // 10)
        first, rows, kept = 1, [], None
        if resume:
            ck = load_checkpoint(run_dir.file("checkpoint.npz"), self)
            state, first, rows, kept = ck.state, ck.frame + 1, ck.rows, ck.frames_written
            stepper.dt, stepper.last_dt = ck.stepper["dt"], ck.stepper["last_dt"]
            if self.minimiser.shift:
                self.minimiser.shift.c = ck.shift
        else:
            state = self.initial_state()
        stats_file = StatsWriter(run_dir.file("stats.csv"), self.comm, rows) if run_dir \
            else None
        trajectory = TrajectoryWriter(run_dir.file("trajectory.xdmf"), self.domain, kept) \
            if run_dir else None
        progress = Progress(steps, disable=quiet or self.comm.rank != 0)
        progress.update(0, advance=first - 1)
        try:
            if trajectory and not resume:
                trajectory.write(0.0, *self.frame_fields(state))
            for frame in range(first, steps + 1):
                for state, row in stepper.advance(state, frame * h):
                    rows.append(row)
                    if stats_file:
                        stats_file.write(row)
                if trajectory and (frame % every == 0 or frame == steps):
                    trajectory.write(state.time, *self.frame_fields(state))
                if run_dir and frame % checkpoint_every == 0 and frame < steps:
                    save_checkpoint(run_dir.file("checkpoint.npz"), self, state, frame,
                                    len(trajectory.times) if trajectory.rank0 else 0, rows,
                                    {"dt": stepper.dt, "last_dt": stepper.last_dt})
                progress.update(row["newton_its"])
        finally:
            progress.close()
            if stats_file:
                stats_file.close()
            if trajectory:
                trajectory.close()
        final, energy_density = self.frame_fields(state)
        if run_dir is not None:
            write_final(run_dir.file("final.vtu"), self.domain, final, energy_density)
            write_scene(run_dir.file("scene.json"), self.scene, self.comm)
        return RunResult(state, rows, run_dir.path if run_dir else None, final)

    def timed_step(self, state: State, dt: float) -> tuple[State, dict]:
        """One step and its stats row; a non-finite result counts as not converged."""
        start = time.perf_counter()
        new, solve = self.step(state, dt)
        energies = self.problem.energies()
        self._check_finite(new, energies)
        wall = time.perf_counter() - start
        return new, {
            "step": new.step, "time": new.time, "dt": dt, "newton_its": solve.newton_its,
            "linear_its": solve.linear_its, "snes_reason": solve.reason,
            "residual_norm": solve.residual_norm, "newton_decrement": solve.newton_decrement,
            "shift": solve.shift,
            **{f"{kind}_its": count for kind, count in solve.hessian_its.items()}, **energies,
            "assembly_s": solve.assembly_s,
            "factor_s": solve.factor_s, "linear_solve_s": solve.linear_solve_s,
            "other_s": wall - solve.assembly_s - solve.factor_s - solve.linear_solve_s,
            "solve_wall_s": solve.wall_s, "step_wall_s": wall}

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
