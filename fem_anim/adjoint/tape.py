"""The forward run the adjoint sweeps back over, and where its states are kept.

:func:`record_forward` steps a :class:`~fem_anim.simulation.loop.Simulation` ``steps`` times
with a fixed step h (seed section 3.1) from the rest shape with the parameters' initial
velocity. The backward sweep needs, for each step n backwards, the state s_n at its start
(to re-stage the step objective, seed eq. 4) and s_{n+1} at its end (the exact Hessian);
a :class:`~fem_anim.simulation.integrators.State` is u, v, a and BDF2's u_{n-1}, v_{n-1}
(local dof arrays, 5 x 8 bytes per local dof). :meth:`Tape.reverse` hands them out, kept
one of three ways (``storage``):

* ``"memory"``: every state in memory (N + 1 states; fastest);
* ``"revolve"``: ``checkpoints`` states in memory at most, placed by Griewank's binomial
  schedule (:mod:`fem_anim.adjoint.schedule`); the states between them are recomputed by
  the same forward steps during the sweep;
* ``"disk"``: every state written to an ``.npz`` file per step in a temporary folder of
  this rank's own (under MPI each rank writes its local arrays), read back by the sweep
  and removed when the tape is closed (the next forward run, or the process's end).

A recomputed step repeats the recorded step's arithmetic exactly: it starts from a stored
state (BDF2's u_{n-1}, v_{n-1} and Newmark's a are in it) with what the simulation carries
across steps besides restored as it was there: IPC's adaptive barrier stiffness schedule
(kappa, its floor, whether it was balanced, the last pairs' distance and kappa's bound),
the Hessian shift, the velocity the problem holds, and the Hessian's sparsity pattern
that IPC's pairs grew (:func:`fresh_hessian`: the direct solvers' rounding depends on it;
each recording run starts from the cells' pattern). Each recorded state's bytes are
fingerprinted; a recomputed state whose fingerprint differs is counted in
:attr:`Tape.replay_mismatches` (the tests assert none serially; a recomputed IPC kappa more
than 1e-9 relative from the recorded one, another piece of the adaptive schedule, raises).
The states an objective reads (its
:meth:`~fem_anim.adjoint.objectives.Objective.steps`; all of them if it does not say) are
kept too, their u and v only.

A step whose Newton iteration did not converge to its test (kept at the iteration budget
or at the round-off floor) has no defined derivative: :func:`record_forward` raises.
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
import time
import weakref
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fem_anim.adjoint.schedule import BinomialSchedule
from fem_anim.errors import ConvergenceError, FemAnimError, describe_os_error
from fem_anim.simulation.initial_state import initial_velocity
from fem_anim.simulation.integrators import State
from fem_anim.solver.stopping import CONVERGED_REASONS

__all__ = ["STORAGES", "Tape", "choose_storage", "record_forward", "state_bytes"]

#: The ways to keep the forward states (``"auto"`` chooses by :func:`choose_storage`).
STORAGES = ("auto", "memory", "revolve", "disk")
#: ``"auto"`` keeps every state in memory while they take at most this much (bytes, per rank).
MEMORY_BUDGET = 256 * 2**20
FIELDS = ("u", "v", "a", "u_old", "v_old")


def state_bytes(state: State) -> int:
    """Bytes of a state's arrays."""
    return sum(getattr(state, k).nbytes for k in FIELDS if getattr(state, k) is not None)


def _fingerprint(state: State) -> bytes:
    """A digest of a state's arrays, to check a recomputed state bit for bit."""
    digest = hashlib.blake2b(digest_size=16)
    for k in FIELDS:
        a = getattr(state, k)
        if a is not None:
            digest.update(a.tobytes())
    return digest.digest()


def choose_storage(storage: str, checkpoints: int | None, steps: int, ndofs: int,
                   budget: int = MEMORY_BUDGET) -> tuple[str, int | None]:
    """The storage and checkpoint count to use.

    ``"auto"``: ``"memory"`` while N + 1 states of 5 x 8 bytes per local dof fit in
    ``budget``, else ``"revolve"`` with as many checkpoints as fit in it. ``"revolve"``
    without ``checkpoints``: as many as fit in the budget (at least 2).

    Raises:
        FemAnimError: an unknown storage or a checkpoint count below 1.
    """
    if storage not in STORAGES:
        raise FemAnimError(f"gradient: storage must be one of {', '.join(STORAGES)}, "
                           f"got {storage!r}")
    if checkpoints is not None and int(checkpoints) < 1:
        raise FemAnimError(f"gradient: checkpoints must be >= 1, got {checkpoints}")
    per_state = 5 * 8 * max(ndofs, 1)
    fit = max(2, budget // per_state)
    if storage == "auto":
        if checkpoints is not None:
            return "revolve", int(checkpoints)
        return ("memory", None) if (steps + 1) * per_state <= budget else ("revolve", fit)
    if storage == "revolve":
        return storage, int(checkpoints) if checkpoints is not None else fit
    return storage, None


@dataclass
class Tape:
    """The states of one forward run: s_n at time n h (s_0 at t = 0).

    Attributes:
        h: The step size (s).
        steps: N, the number of steps.
        storage: ``"memory"``, ``"revolve"`` or ``"disk"``.
        checkpoints: Revolve's most stored states (None otherwise).
        forward_s: Wall time of the recording forward steps (s).
        recomputed: Forward steps re-run by the last :meth:`reverse`.
        replay_mismatches: Recomputed states that differ from the recorded ones.
        peak_stored: The most states held in memory at once by the tape (revolve: its
            checkpoints; memory: all; disk: s_0), not counting the sweep's two working states.
        peak_nbytes: The most bytes they took at once (this rank).
    """

    h: float
    steps: int = 0
    storage: str = "memory"
    checkpoints: int | None = None
    #: IPC's barrier stiffness kappa of each step (Pa; empty without ``[contact]``)
    barrier_stiffness: list[float] = field(default_factory=list)
    forward_s: float = 0.0
    recomputed: int = 0
    replay_mismatches: int = 0
    peak_stored: int = 0
    peak_nbytes: int = 0
    _stored: dict = field(default_factory=dict, repr=False)  # n -> State (full)
    _carry: dict = field(default_factory=dict, repr=False)  # n -> what steps carry over
    _observed: dict = field(default_factory=dict, repr=False)  # n -> State (u, v)
    _prints: list = field(default_factory=list, repr=False)
    _folder: Path | None = field(default=None, repr=False)
    _finalizer: object = field(default=None, repr=False)
    _work: dict = field(default_factory=dict, repr=False)

    # -- access -------------------------------------------------------------------------
    @property
    def states(self) -> "_StateView":
        """``states[n]``: s_n where the tape holds it (every n for memory and disk; for
        revolve the checkpoints it still holds and the objective's steps, u and v)."""
        return _StateView(self)

    @property
    def initial(self) -> State:
        """s_0 (always kept)."""
        return self.state(0)

    @property
    def nbytes(self) -> int:
        """Bytes of the states held in memory now on this rank (the state arrays)."""
        held = {id(s): s for s in (*self._stored.values(), *self._observed.values())}
        return sum(state_bytes(s) for s in held.values())

    @property
    def disk_bytes(self) -> int:
        """Bytes of this rank's state files (disk storage)."""
        if self._folder is None or not self._folder.exists():
            return 0
        return sum(f.stat().st_size for f in self._folder.iterdir())

    def state(self, n: int) -> State:
        """s_n, if the tape holds it.

        Raises:
            FemAnimError: revolve storage does not keep s_n.
        """
        if n in self._stored:
            return self._stored[n]
        if n in self._observed:
            return self._observed[n]
        if self.storage == "disk" and 0 <= n <= self.steps:
            return self._read(n)
        raise FemAnimError(f"gradient: the state of step {n} is not kept (storage = "
                           f"{self.storage!r}); an objective must list the steps it reads "
                           "(Objective.steps)")

    # -- recording ------------------------------------------------------------------------
    def _keep(self, n: int, state: State, sim, keep: bool, observed: bool) -> None:
        self._prints.append(_fingerprint(state))
        if self.storage == "memory" or keep:
            self._stored[n] = state
            if self.storage == "revolve":
                self._carry[n] = _carry(sim, n == 0)
        elif self.storage == "disk":
            self._write(n, state)
        if observed and self.storage == "revolve":  # a checkpoint is dropped in the sweep
            self._observed[n] = State(u=state.u.copy(), v=state.v.copy(), a=None,
                                      time=state.time, step=state.step)
        self._account()

    def _account(self) -> None:
        """Update the peaks of the stored states' count and bytes."""
        self.peak_stored = max(self.peak_stored, len(self._stored))
        self.peak_nbytes = max(self.peak_nbytes,
                               sum(state_bytes(s) for s in self._stored.values()))

    def _write(self, n: int, state: State) -> None:
        path = Path(tempfile.gettempdir())
        try:
            if self._folder is None:  # this rank's own folder
                self._folder = Path(tempfile.mkdtemp(prefix="fem_anim_tape_"))
                self._finalizer = weakref.finalize(self, shutil.rmtree, str(self._folder),
                                                   True)
            arrays = {k: getattr(state, k) for k in FIELDS if getattr(state, k) is not None}
            path = self._folder / f"state_{n:07d}.npz"
            np.savez(path, time=np.array(state.time), step=np.array(state.step), **arrays)
        except OSError as err:
            self.close()
            raise FemAnimError(f"gradient: cannot write the forward states: "
                               f"{describe_os_error(err, path)}") from None

    def _read(self, n: int) -> State:
        path = self._folder / f"state_{n:07d}.npz"
        try:
            with np.load(path) as data:
                arrays = {k: data[k] for k in FIELDS if k in data.files}
                return State(u=arrays["u"], v=arrays["v"], a=arrays["a"],
                             u_old=arrays.get("u_old"), v_old=arrays.get("v_old"),
                             time=float(data["time"]), step=int(data["step"]))
        except OSError as err:
            raise FemAnimError(f"gradient: cannot read the forward states back: "
                               f"{describe_os_error(err, path)}") from None

    def close(self) -> None:
        """Remove this rank's state files (disk storage); idempotent."""
        if self._finalizer is not None:
            self._finalizer()

    # -- the sweep's order ------------------------------------------------------------------
    def reverse(self, sim):
        """Yield (n, s_n, s_{n+1}) for n = N - 1, ..., 0 (collective: revolve re-runs steps).

        Between two yields the simulation may be re-stepped; the caller stages what it
        needs after each yield. A tape is reversed once.
        """
        self.recomputed = 0
        if self.steps == 0:
            return
        if "end" not in self._work:  # revolve's checkpoints are dropped on the way
            raise RuntimeError("a tape is reversed once")
        end = self._work.pop("end")
        if self.storage == "revolve":
            schedule = BinomialSchedule(self.steps, self.checkpoints)
            yield from self._revolve(sim, schedule, 0, self.steps, schedule.slots, end)
            return
        for n in range(self.steps - 1, -1, -1):
            start = self.state(n)
            yield n, start, end
            end = start

    def _revolve(self, sim, schedule, a: int, b: int, slots: int, end: State):
        """Reverse s_a ... s_{b-1} (s_a stored, s_b = ``end`` held) with ``slots`` free."""
        if b - a == 1:
            yield a, self._stored[a], end
            return
        if slots == 0:
            for n in range(b - 1, a - 1, -1):
                start = self._advance(sim, a, n)
                yield n, start, end
                end = start
            return
        m = a + int(schedule.split[slots, b - a])
        if m not in self._stored:
            self._stored[m] = self._advance(sim, a, m)
            self._carry[m] = _carry(sim)
            self._account()
        yield from self._revolve(sim, schedule, m, b, slots - 1, end)
        middle = self._stored.pop(m)
        self._carry.pop(m, None)
        yield from self._revolve(sim, schedule, a, m, slots, middle)

    def _advance(self, sim, a: int, n: int) -> State:
        """s_n from the checkpoint s_a by the forward steps (kept s_{N-1} of the recording
        run used once)."""
        if n == a:
            return self._stored[a]
        if self._work.get("last", (None,))[0] == n:
            return self._work.pop("last")[1]
        state = self._stored[a]
        _restore(sim, self._carry[a], state)
        for k in range(a, n):
            state, stats = sim.step(state, self.h)
            self.recomputed += 1
            if stats.reason not in CONVERGED_REASONS:
                raise ConvergenceError(f"recomputing step {k + 1} for the gradient: it "
                                       f"stopped without converging (SNES reason "
                                       f"{stats.reason}), the recorded run's did not")
            ipc = sim.problem.ipc  # kappa is global: every rank decides alike
            kappa = self.barrier_stiffness[k] if ipc is not None else 0.0
            if ipc is not None and abs(float(ipc.kappa) - kappa) > 1e-9 * abs(kappa):
                raise FemAnimError(f"gradient: recomputing step {k + 1} gave barrier "
                                   f"stiffness {ipc.kappa!r}, the recorded run {kappa!r} "
                                   "(use storage = \"memory\" or \"disk\")")
            if _fingerprint(state) != self._prints[k + 1]:
                self.replay_mismatches += 1
        return state


class _StateView:
    """``tape.states``: indexable like the list of states it replaces."""

    def __init__(self, tape: Tape):
        self.tape = tape

    def __len__(self) -> int:
        return self.tape.steps + 1

    def __getitem__(self, n: int) -> State:
        if n < 0:
            n += len(self)
        return self.tape.state(n)

    def __iter__(self):
        return (self.tape.state(n) for n in range(len(self)))


def _grows(sim) -> bool:
    """Whether the step Hessian's pattern grows with contact (AIJ with IPC contact)."""
    p = sim.problem
    return p.ipc is not None and not p.mixed and "baij" not in sim.minimiser.A.getType()


def fresh_hessian(sim, couplings=None) -> None:
    """Give the forward's Newton a new Hessian with the cells' pattern plus ``couplings``
    (:func:`~fem_anim.simulation.hessian_pattern.extra_couplings`' of a checkpoint; rank 0's;
    None: the cells' only), as the run had it there (collective).

    The direct solvers' ordering and pivoting depend on the pattern, which IPC's pairs grow
    (:mod:`fem_anim.simulation.hessian_pattern`): a recomputed step rounds as the recorded
    one only with the recorded pattern, and a recording run is the same function of the
    parameters each time only if it starts from the cells' pattern.
    """
    from fem_anim.simulation.checkpoint import dof_identity
    from fem_anim.simulation.hessian_pattern import restore_couplings

    m, p = sim.minimiser, sim.problem
    A = p.create_matrix("baij" if "baij" in m.A.getType() else None)
    if couplings is not None:
        restore_couplings(A, p.V, dof_identity(p.V, sim.domain), couplings)
    m.A.destroy()
    m.A = A
    m.snes.setJacobian(m.reuse.jacobian, A)
    if m.hessian.mode == "auto":
        m.hessian.enable_inertia(A)


def _carry(sim, start: bool = False) -> dict:
    """What the simulation carries from one step to the next besides the state (at s_0
    with ``start``: the cells' Hessian pattern)."""
    out = {}
    if _grows(sim):
        from fem_anim.simulation.checkpoint import dof_identity
        from fem_anim.simulation.hessian_pattern import extra_couplings

        out["couplings"] = None if start else extra_couplings(
            sim.minimiser.A, sim.problem.V, dof_identity(sim.problem.V, sim.domain))
    ipc = sim.problem.ipc
    if ipc is not None:
        out["ipc"] = {k: getattr(ipc, k) for k in
                      ("kappa", "kappa_floor", "balanced", "_distance", "kappa_max")
                      if hasattr(ipc, k)}
    shift = sim.minimiser.shift
    if shift is not None:
        out["shift"] = shift.c
    return out


def _restore(sim, carry: dict, state: State) -> None:
    """Put back :func:`_carry`'s values and the velocity the problem held after s_n."""
    ipc = sim.problem.ipc
    for k, value in carry.get("ipc", {}).items():
        setattr(ipc, k, value)
    if "shift" in carry:
        sim.minimiser.shift.c = carry["shift"]
    if "couplings" in carry:
        fresh_hessian(sim, carry["couplings"])
    sim.problem.v.x.array[:] = state.v


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


def record_forward(sim, parameters, steps: int, h: float, storage: str = "memory",
                   checkpoints: int | None = None, observed=None) -> Tape:
    """Run ``steps`` steps of size ``h`` and keep the states as ``storage`` says (collective).

    Args:
        sim: The :class:`~fem_anim.simulation.loop.Simulation`.
        parameters: Its :class:`~fem_anim.adjoint.parameters.ParameterSet` (already assigned).
        steps: Number of steps.
        h: Step size (s).
        storage: ``"memory"``, ``"revolve"`` or ``"disk"`` (:func:`choose_storage` resolves
            ``"auto"``).
        checkpoints: Revolve's most stored states (>= 1).
        observed: The steps whose u and v an objective reads (None: all of them).

    Returns:
        The :class:`Tape`.

    Raises:
        ConvergenceError: a step failed, or stopped without meeting its convergence test
            (its derivative is then undefined).
        FemAnimError: the disk storage cannot write its files.
    """
    start = time.perf_counter()
    tape = Tape(h=h, steps=steps, storage=storage,
                checkpoints=int(checkpoints) if storage == "revolve" else None)
    chain = set(BinomialSchedule(steps, tape.checkpoints).first_chain()) \
        if storage == "revolve" else set()
    seen = set(range(steps + 1)) if observed is None else set(observed)
    ipc = sim.problem.ipc
    if ipc is not None:  # IPC's adaptive stiffness schedule from its start, every run
        ipc.restore({"kappa_floor": 0.0, "kappa_balanced": 0.0})
        ipc.kappa = float(ipc.cfg["stiffness"]) if ipc.cfg["stiffness"] != "adaptive" else 0.0
        ipc._distance = np.inf
    if _grows(sim):  # and its Hessian from the cells' pattern
        fresh_hessian(sim)
    state = start_state(sim, parameters)
    tape._keep(0, state, sim, True, 0 in seen)
    for n in range(steps):
        previous = state
        state, stats = sim.step(state, h)
        if ipc is not None:
            tape.barrier_stiffness.append(float(ipc.kappa))
        if stats.reason not in CONVERGED_REASONS:
            tape.close()
            raise ConvergenceError(
                f"step {state.step} (t = {state.time:.6g} s) stopped without converging "
                f"(SNES reason {stats.reason}): the gradient is undefined there")
        # s_N is the sweep's first end, held there (revolve: not a checkpoint)
        tape._keep(n + 1, state, sim, n + 1 in chain, n + 1 in seen and n + 1 < steps)
        if n + 1 == steps and storage == "revolve" and steps - 1 not in tape._stored:
            tape._work["last"] = (steps - 1, previous)  # the sweep's first start
    tape._work["end"] = state
    if storage == "revolve" and steps > 0 and steps in seen:
        tape._observed[steps] = state
    tape.forward_s = time.perf_counter() - start
    return tape
