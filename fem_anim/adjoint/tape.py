"""The forward run the adjoint sweeps back over: every step's state, kept in memory.

:func:`record_forward` steps a :class:`~fem_anim.simulation.loop.Simulation` ``steps`` times
with a fixed step h (seed section 3.1) from the rest shape with the parameters' initial
velocity, and keeps each :class:`~fem_anim.simulation.integrators.State` (u, v, a and
BDF2's u_{n-1}, v_{n-1}: local dof arrays). That is all the backward sweep needs: it
re-stages each step's objective from the state at its start and re-assembles the exact
Hessian at the state at its end; with ``[contact]`` it also keeps each step's IPC barrier
stiffness kappa (the adaptive schedule is restarted at every forward run, so the run is
the same function of the parameters each time). The memory is :attr:`Tape.nbytes` (about
5 x 8 bytes per local dof and step; no checkpointing: for short runs).

A step whose Newton iteration did not converge to its test (kept at the iteration budget
or at the round-off floor) has no defined derivative: :func:`record_forward` raises.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from fem_anim.errors import ConvergenceError
from fem_anim.simulation.initial_state import initial_velocity
from fem_anim.simulation.integrators import State
from fem_anim.solver.stopping import CONVERGED_REASONS

__all__ = ["Tape", "record_forward"]


@dataclass
class Tape:
    """The states of one forward run: ``states[n]`` at time n h (``states[0]``: t = 0).

    Attributes:
        h: The step size (s).
        states: The states at the start and after each step.
        forward_s: Wall time of the forward steps (s).
    """

    h: float
    states: list[State] = field(default_factory=list)
    #: IPC's barrier stiffness kappa of each step (Pa; empty without ``[contact]``)
    barrier_stiffness: list[float] = field(default_factory=list)
    forward_s: float = 0.0

    @property
    def steps(self) -> int:
        """The number of steps taken."""
        return len(self.states) - 1

    @property
    def nbytes(self) -> int:
        """Bytes of the kept states on this rank (the state arrays; not the meshes' data)."""
        return sum(a.nbytes for s in self.states for a in (s.u, s.v, s.a, s.u_old, s.v_old)
                   if a is not None)


def start_state(sim, parameters) -> State:
    """The state at t = 0 with the parameters' initial velocity and displacement
    (collective).

    v_0 is the scene's rigid field with its translational part replaced by the parameters'
    ``initial.velocity`` and each body's (v_0 is affine in them); Newmark's
    a_0 = M^-1 (f(0) - C v_0) is computed from the current material (seed eq. 1b).
    """
    p = sim.problem
    n = p.u.x.array.size
    v0 = initial_velocity(sim.scene, p)
    v0 = np.zeros(n) if v0 is None else v0
    v0 = v0 + parameters.velocity_offset(p)
    p.v.x.array[:] = v0
    state = State(u=parameters.displacement_offset(p), v=v0, a=np.zeros(n))
    if sim.integrator.name == "newmark":
        state.a = sim.acceleration(state.u, state.v)
    return state


def record_forward(sim, parameters, steps: int, h: float) -> Tape:
    """Run ``steps`` steps of size ``h`` and keep every state (collective).

    Args:
        sim: The :class:`~fem_anim.simulation.loop.Simulation`.
        parameters: Its :class:`~fem_anim.adjoint.parameters.ParameterSet` (already assigned).
        steps: Number of steps.
        h: Step size (s).

    Returns:
        The :class:`Tape`.

    Raises:
        ConvergenceError: a step failed, or stopped without meeting its convergence test
            (its derivative is then undefined).
    """
    start = time.perf_counter()
    tape = Tape(h=h)
    state = start_state(sim, parameters)
    tape.states.append(state)
    ipc = sim.problem.ipc
    if ipc is not None:  # IPC's adaptive stiffness schedule from its start, every run
        ipc.restore({"kappa_floor": 0.0, "kappa_balanced": 0.0})
        ipc.kappa = float(ipc.cfg["stiffness"]) if ipc.cfg["stiffness"] != "adaptive" else 0.0
        ipc._distance = np.inf
    for _ in range(steps):
        state, stats = sim.step(state, h)
        if ipc is not None:
            tape.barrier_stiffness.append(float(ipc.kappa))
        if stats.reason not in CONVERGED_REASONS:
            raise ConvergenceError(
                f"step {state.step} (t = {state.time:.6g} s) stopped without converging "
                f"(SNES reason {stats.reason}): the gradient is undefined there")
        tape.states.append(state)
    tape.forward_s = time.perf_counter() - start
    return tape
