"""A shell and a solid stepped together: one minimisation per step over both (seed 3.1).

:class:`JointSimulation` builds the solid's and the shell's scenes as two meshes and two
:class:`~fem_anim.problem.objective.EnergyProblem`\\ s, joins them in one
:class:`~fem_anim.problem.joint_objective.JointProblem` (the IPC barrier on both surfaces,
the shell's thickness as the minimum distance) and minimises each step's objective (seed
eq. 4) over both unknowns at once with the solids' :class:`~fem_anim.solver.minimiser.Minimiser`:
one Newton system, one line search bounded by one continuous collision detection. The
integrator's state is one :class:`~fem_anim.simulation.integrators.State` per part, each
updated by the scheme from its part of the joint solution. Drive it from Python::

    sim = JointSimulation(solid_scene, shell_scene)
    states = sim.initial_state()
    for _ in range(steps):
        states, stats = sim.step(states, dt)

The solid's scene is a solid scene without ``[contact]``; the shell's scene is a shell
scene whose ``[contact]`` (self contact on) becomes the barrier between and within both.
The time, solver and integrator keys are the solid scene's and must equal the shell's
(:func:`fem_anim.scene.joint_rules.check_joint_parts`). A scene file with a shell
``[[body]]`` beside solid ones is split into the two (:func:`split_joint_scene`,
:meth:`JointSimulation.from_scene`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.errors import ConvergenceError, SceneError
from fem_anim.mesh.bodies import build_scene_mesh
from fem_anim.problem.form_compiler import JIT_OPTIONS
from fem_anim.problem.joint_objective import JointProblem
from fem_anim.problem.objective import EnergyProblem
from fem_anim.scene.joint_rules import check_joint_parts, joint_parts
from fem_anim.scene.loading import Scene
from fem_anim.simulation.initial_state import initial_velocity
from fem_anim.simulation.integrators import Integrator, State
from fem_anim.simulation.loop import solver_options
from fem_anim.solver.minimiser import Minimiser
from fem_anim.solver.solve_stats import SolveStats

__all__ = ["JointSimulation", "JointState", "split_joint_scene"]


@dataclass
class JointState:
    """The parts' states advancing together, shaped for
    :class:`~fem_anim.simulation.adaptive.AdaptiveStepper` (time, step count, and BDF2's
    history: ``u_old``/``v_old`` None when the next step must restart it).

    Attributes:
        parts: Each part's :class:`~fem_anim.simulation.integrators.State`.
        time: Time (s).
        step: Completed steps.
        u_old: True when every part holds BDF2's previous step, else None.
        v_old: Likewise.
    """

    parts: list[State]
    time: float = 0.0
    step: int = 0
    u_old: bool | None = None
    v_old: bool | None = None

def split_joint_scene(scene: Scene) -> tuple[Scene, Scene]:
    """The solids' and the shell's scenes of a validated scene with a shell body
    (:func:`fem_anim.scene.joint_rules.joint_parts`; validated as a whole already)."""
    solid, shell = joint_parts(scene.data)
    return (Scene._of(solid, scene.source, scene.base_dir),
            Scene._of(shell, scene.source, scene.base_dir))


class JointSimulation:
    """A solid scene and a shell scene, built and ready to step together (collective).

    Args:
        solid: The solid's validated scene (one body or several ``[[body]]``).
        shell: The shell's validated scene, with ``[contact]``.
        comm: MPI communicator.
        cli_options: PETSc options from the command line (highest precedence).
        preset: Linear solver preset overriding ``solver.preset``.

    Raises:
        SceneError: the scenes cannot run together
            (:func:`~fem_anim.scene.joint_rules.check_joint_parts`), or their surfaces cross
            or lie within ``contact.dhat`` at rest.
    """

    @classmethod
    def from_scene(cls, scene: Scene, comm: MPI.Comm = MPI.COMM_WORLD,
                   cli_options: dict[str, str] | None = None,
                   preset: str | None = None) -> JointSimulation:
        """The simulation of a scene with a shell body (:func:`split_joint_scene`)."""
        return cls(*split_joint_scene(scene), comm, cli_options, preset)

    def __init__(self, solid: Scene, shell: Scene, comm: MPI.Comm = MPI.COMM_WORLD,
                 cli_options: dict[str, str] | None = None, preset: str | None = None):
        error = check_joint_parts(solid.data, shell.data)
        if error:
            raise SceneError(error)
        self.comm = comm
        self.scenes = [solid, Scene._of({k: v for k, v in shell.data.items() if k != "contact"},
                                        shell.source, shell.base_dir)]
        self.domains = [build_scene_mesh(comm, scene) for scene in self.scenes]
        with compat.jit_locks_released(JIT_OPTIONS):
            parts = [EnergyProblem(scene, domain)
                     for scene, domain in zip(self.scenes, self.domains)]
        #: the solids' scene name: a scene with a shell body is run under its own name
        self.name = solid.name
        names = [b["name"] for b in solid["body"]] if solid["body"] else ["solid"]
        names.append(shell["name"])
        self.problem = JointProblem(parts, shell["contact"], shell["shell"]["thickness"], names)
        self.integrator = Integrator(solid["time"]["integrator"])
        self.options = solver_options(solid, cli_options, preset, comm.size)
        # the exact Hessian (the barrier's per-pair projected): a shell has no filtered one
        self.minimiser = Minimiser(self.problem, self.options,
                                   settings=solid["solver"] | {"hessian": "exact"})
        self.minimiser.require_read(cli_options or {})  # a misspelt option is an error
        self.x_work = self.problem.create_vector()

    @property
    def parts(self) -> list[EnergyProblem]:
        """The solid's and the shell's problems."""
        return self.problem.parts

    def initial_state(self) -> list[State]:
        """Each part's state at t = 0: the rest shape, at rest or with its scene's rigid
        ``[initial]`` velocity (local dof arrays of its space, ghosts included)."""
        states = []
        for scene, part in zip(self.scenes, self.parts):
            n = part.u.x.array.size
            v0 = initial_velocity(scene, part)
            state = State(u=np.zeros(n), v=np.zeros(n) if v0 is None else v0, a=np.zeros(n))
            part.v.x.array[:] = state.v
            states.append(state)
        return states

    def energies(self, states: list[State]) -> dict[str, float]:
        """Kinetic, elastic, gravitational and barrier energy (J) of both parts at
        ``states``, and their sum ``total_energy`` (collective)."""
        total: dict[str, float] = {}
        for part, state in zip(self.parts, states):
            part.u.x.array[:] = state.u
            part.v.x.array[:] = state.v
            for key, value in part.energies().items():
                total[key] = total.get(key, 0.0) + value
        barrier = self.problem.ipc.energy(friction=False)
        total["contact"] += barrier
        total["total_energy"] += barrier
        return total

    def timed_step(self, state: JointState, dt: float) -> tuple[JointState, dict]:
        """:meth:`step` on a :class:`JointState` and its ``stats.csv`` row (collective):
        what :class:`~fem_anim.simulation.adaptive.AdaptiveStepper` takes substeps with.

        Raises:
            ConvergenceError: as :meth:`step`, and for a non-finite displacement or energy.
        """
        start = time.perf_counter()
        ipc = self.problem.ipc
        for key in ipc.timers:  # this step's contact time only (not failed tries')
            ipc.timers[key] = 0.0
        parts = state.parts if state.u_old else \
            [replace(s, u_old=None, v_old=None) for s in state.parts]
        new, stats = self.step(parts, dt)
        energies = self.energies(new)
        bad = not (all(np.all(np.isfinite(s.u)) for s in new)
                   and all(map(math.isfinite, energies.values())))
        if self.comm.allreduce(bad, op=MPI.LOR):
            raise ConvergenceError(f"step {new[0].step} (t = {new[0].time:.6g} s) produced "
                                   "a non-finite displacement or energy")
        wall = time.perf_counter() - start
        row = {"step": state.step + 1, "time": new[0].time, "dt": dt,
               "newton_its": stats.newton_its, "linear_its": stats.linear_its,
               "snes_reason": stats.reason, "residual_norm": stats.residual_norm,
               "initial_residual_norm": stats.initial_residual_norm,
               "newton_decrement": stats.newton_decrement, **energies,
               "assembly_s": stats.assembly_s, "factor_s": stats.factor_s,
               "linear_solve_s": stats.linear_solve_s,
               "other_s": wall - stats.assembly_s - stats.factor_s - stats.linear_solve_s,
               "solve_wall_s": stats.wall_s, "step_wall_s": wall,
               "contact_s": sum(ipc.timers.values()),
               "hessian_assemblies": stats.hessian_assemblies,
               "factorisations": stats.factorisations, **ipc.step_stats()}
        return JointState(new, new[0].time, state.step + 1, True, True), row

    def step(self, states: list[State], h: float) -> tuple[list[State], SolveStats]:
        """Advance both parts one step of size ``h``: stage, one minimisation, update.

        Returns:
            The parts' states at t + h and the solver's statistics of the step.

        Raises:
            ConvergenceError: the minimisation failed or no collision-free start has a
                finite objective; ``states`` are left untouched.
        """
        p, integ = self.problem, self.integrator
        weights = {integ.weight(h, s) for s in states}
        assert len(weights) == 1  # the parts' states advance together
        preds = [integ.predictor(h, s) for s in states]
        damping = [integ.damping_anchor(h, s) if part.damped else None
                   for part, s in zip(self.parts, states)]
        t = states[0].time + h
        p.stage([s.u for s in states], preds, weights.pop(), t, h, damping)
        what = f"step {states[0].step + 1} (t = {t:.6g} s)"
        self._collision_free_start(states, preds, what)
        stats = self.minimiser.solve(self.x_work, what=what)
        p.set_state(self.x_work)
        new = [integ.update(h, s, part.u.x.array.copy(), y)
               for part, s, y in zip(self.parts, states, preds)]
        for part, state in zip(self.parts, new):
            part.finish_step(state.time, state.v, state.a, pin_rates=False)
        p.finish_step()
        return new, stats

    def _collision_free_start(self, states: list[State], preds: list[np.ndarray],
                              what: str) -> None:
        """u_n + alpha (y - u_n) into ``x_work``, pins at their targets, alpha the joint
        CCD's collision-free step (:func:`fem_anim.simulation.newton_start.collision_free_guess`
        for one mesh)."""
        p = self.problem
        targets = []
        for part, y in zip(self.parts, preds):
            u = compat.petsc_vec(part.u)
            part.u.x.array[:] = y
            fem_petsc.set_bc(u, part.displacement_bcs)
            u.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            targets.append(part.u.x.array.copy())
        for part, s in zip(self.parts, states):
            part.u.x.array[:] = s.u
        alpha = p.ipc.step_bound(p.joint_array([s.u - y for s, y in zip(states, targets)]))
        for guess in ([s.u + alpha * (y - s.u) for s, y in zip(states, targets)],
                      [s.u for s in states]):
            p.load_guess(guess, self.x_work, apply_bcs=False)
            if math.isfinite(p.objective(None, self.x_work)):
                return
        raise ConvergenceError(f"{what}: no collision-free start with a finite step "
                               "objective: reduce time.dt")
