"""Checkpoints of a run with a shell body beside solids (:mod:`fem_anim.simulation.joint_run`).

The one-body checkpoint's format and machinery (:mod:`fem_anim.simulation.checkpoint`), with
one set of state arrays per part: ``part{k}_keys`` (the dof identities of part k's space,
:func:`~fem_anim.simulation.checkpoint.dof_identity`) and ``part{k}_u``, ``_v``, ``_a``,
``_u_old``, ``_v_old`` (BDF2's previous step), k = 0 for the solids and 1 for the shell. The
record beside them is a one-body run's (:func:`~fem_anim.simulation.checkpoint.run_meta`):
the whole scene's physics and the solver settings, time, step and frame counters, the
adaptive stepper's ``dt`` and ``last_dt``, the joint barrier's state across steps (IPC's
adaptive stiffness floor, :meth:`~fem_anim.contact.ipc.IPCContact.state`), the number of
frames each of the run's three trajectories holds (``solids.xdmf``, ``shell.xdmf`` and
``trajectory.xdmf`` write the same frames) and the stats rows. The joint Hessian's pattern
grown by the contact pairs met so far (:mod:`fem_anim.simulation.hessian_pattern`) is kept
as pairs of joint dof identities, a part's identity i as ``i * parts + k``.

Each step minimises one objective over both parts (seed eq. 4, section 3.1); a resumed run
stages its next step from exactly the values the uninterrupted run held, so in serial it
repeats the uninterrupted run's arithmetic bit for bit (:doc:`/resume`).
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np

from fem_anim import compat
from fem_anim.errors import FemAnimError
from fem_anim.simulation.checkpoint import (FIELDS, Checkpoint, dof_identity, invalid_arrays,
                                            invalid_record, part_arrays, part_fields,
                                            read_checkpoint, run_meta, solver_settings,
                                            write_checkpoint)
from fem_anim.simulation.hessian_pattern import Blocks, extra_couplings, restore_couplings
from fem_anim.simulation.integrators import State

__all__ = ["save_joint_checkpoint", "load_joint_checkpoint", "restore_joint",
           "joint_blocks", "solver_view"]


def _prefix(k: int) -> str:
    return f"part{k}_"


def solver_view(sim, scene):
    """What :func:`~fem_anim.simulation.checkpoint.solver_settings` and
    :func:`~fem_anim.simulation.checkpoint.describe_resume` read of a run: the whole scene
    and the joint step's PETSc options."""
    return SimpleNamespace(scene=scene, options=sim.options)


def joint_blocks(sim) -> tuple[Blocks, np.ndarray]:
    """The joint unknown's dof blocks (:class:`~fem_anim.simulation.hessian_pattern.Blocks`:
    each part's local blocks in turn) and their identities, ``i * parts + k`` for block
    identity i of part k (collective)."""
    layout, n = sim.problem.layout, len(sim.parts)
    global_blocks, owned, cells, keys, first = [], [], [], [], 0
    for k, (part, domain) in enumerate(zip(sim.parts, sim.domains)):
        index_map = part.V.dofmap.index_map
        global_blocks.append(np.asarray(layout.joint_of_local(k), np.int64))
        owned.append(first + np.arange(index_map.size_local))
        cells.append(compat.cell_dofs(part.V) + first)
        keys.append(dof_identity(part.V, domain) * n + k)
        first += index_map.size_local + index_map.num_ghosts
    blocks = Blocks(layout.bs, layout.size, np.concatenate(global_blocks),
                    np.concatenate(owned), cells)
    return blocks, np.concatenate(keys)


def _grows(sim) -> bool:
    """Whether the joint Hessian's pattern grows with contact (scalar AIJ storage)."""
    kind = sim.minimiser.A.getType()
    return kind.endswith("aij") and "baij" not in kind


def save_joint_checkpoint(path: Path, sim, scene, state, frame: int, frames_written: int,
                          rows: list[dict], stepper: dict) -> None:
    """Write ``path`` (rank 0) with the joint run's full state after ``frame`` frames
    (collective).

    Args:
        path: The checkpoint file.
        sim: The :class:`~fem_anim.simulation.joint_loop.JointSimulation`.
        scene: The whole scene (solids and the shell body).
        state: The :class:`~fem_anim.simulation.joint_loop.JointState` at frame ``frame``.
        frames_written: Frames each of the three trajectories holds.
        rows: The stats rows so far.
        stepper: The adaptive stepper's ``dt`` and ``last_dt`` (s).
    """
    comm = sim.comm
    arrays: dict[str, np.ndarray | None] = {}
    for k, (part, domain, s) in enumerate(zip(sim.parts, sim.domains, state.parts)):
        arrays |= part_arrays(comm, part.V, domain, s, _prefix(k))
    if _grows(sim):  # the contact pairs met so far, as the Hessian's pattern holds them
        blocks, keys = joint_blocks(sim)
        arrays["couplings"] = extra_couplings(sim.minimiser.A, blocks, keys)
    if comm.rank != 0:
        return
    shift = sim.minimiser.shift.c if sim.minimiser.shift else 0.0
    meta = run_meta(scene, solver_settings(solver_view(sim, scene)), state, frame,
                    frames_written, rows, stepper, shift, sim.problem.ipc.state())
    meta["parts"] = len(sim.parts)
    write_checkpoint(path, meta, arrays)


def load_joint_checkpoint(path: Path, sim, scene) -> Checkpoint:
    """Read ``path`` on every rank and pick each part's dofs on this partition by their
    keys (collective).

    Returns:
        A :class:`~fem_anim.simulation.checkpoint.Checkpoint` whose ``state`` is a
        :class:`~fem_anim.simulation.joint_loop.JointState`.

    Raises:
        FemAnimError: if the file is missing or unreadable, was written for another scene
            (naming the physics keys that changed), another mesh or a one-body run, or
            holds an impossible record.
    """
    from fem_anim.simulation.joint_loop import JointState

    dt, steps = float(scene["time"]["dt"]), int(scene["time"]["steps"])
    n = len(sim.parts)

    def check(meta, data) -> str | None:
        problem = invalid_record(meta, scene, steps, dt, lambda k: k * dt)
        if problem:
            return problem
        if meta.get("parts") != n:
            return f"it holds {meta.get('parts', 1)} part(s), not this run's {n} (solids " \
                   "and a shell)"
        return invalid_arrays(data, {f"{_prefix(k)}keys": (
            tuple(f"{_prefix(k)}{name}" for name in FIELDS), 3) for k in range(n)})

    meta, data = read_checkpoint(path, sim.comm, check)
    parts = [State(**part_fields(data, part.V, domain, sim.comm, path, _prefix(k)),
                   time=meta["time"], step=meta["step"])
             for k, (part, domain) in enumerate(zip(sim.parts, sim.domains))]
    # written after a whole step (frame >= 1): every part holds the history of that step
    state = JointState(parts, meta["time"], meta["step"], True, True)
    return Checkpoint(state, meta["frame"], meta["frames_written"], meta["rows"],
                      meta["stepper"], meta["shift"], meta.get("contact", {}), None,
                      meta.get("solver", {}), data.get("couplings"))


def restore_joint(sim, stepper, ck: Checkpoint) -> None:
    """Put a joint checkpoint's state across steps back: the adaptive step, the Hessian
    shift, the joint barrier's stiffness and the Hessian's pattern, each part's u and the
    velocity its energies report (collective)."""
    stepper.dt, stepper.last_dt = min(ck.stepper["dt"], stepper.h), ck.stepper["last_dt"]
    if sim.minimiser.shift:
        sim.minimiser.shift.c = ck.shift
    sim.problem.ipc.restore(ck.contact)
    for part, s in zip(sim.parts, ck.state.parts):
        part.u.x.array[:] = s.u
        part.v.x.array[:] = s.v
    if _grows(sim):
        blocks, keys = joint_blocks(sim)
        try:
            restore_couplings(sim.minimiser.A, blocks, keys, ck.couplings)
        except KeyError as err:
            raise FemAnimError(f"the checkpoint does not match this mesh: {err.args[0]}") \
                from None
