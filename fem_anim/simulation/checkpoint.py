"""Checkpoints: everything a run needs to continue exactly where it was.

Every ``output.checkpoint_every`` frames rank 0 writes ``checkpoint.npz`` atomically
(temp file, fsync, rename: a kill leaves the previous checkpoint or the new one, never a
half-written file). It holds the state arrays in global dof order (u, v, a and, for BDF2,
u_{n-1}, v_{n-1}), time, step and frame counters, the adaptive time-step state, the
Hessian shift, the number of trajectory frames written and the stats rows so far. A
resumed run therefore repeats exactly the arithmetic of an uninterrupted one.

Dofs are keyed by their coordinates (quantised to 1e-9 of the mesh extent), not by the
global dof numbering, which depends on the mesh partition and is not reproducible between
parallel runs: a checkpoint resumes on any number of processes. The scene must be the same
(its validated data are hashed).
"""

from __future__ import annotations

import hashlib
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim.errors import FemAnimError
from fem_anim.simulation.integrators import State
from fem_anim.output.files import write_atomically

__all__ = ["Checkpoint", "save_checkpoint", "load_checkpoint", "scene_hash"]

FIELDS = ("u", "v", "a", "u_old", "v_old")


def scene_hash(scene) -> str:
    """A fingerprint of the validated scene: everything that shapes the motion (the output
    and render settings excluded)."""
    data = {k: v for k, v in scene.data.items() if k not in ("output", "render")}
    return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()


@dataclass
class Checkpoint:
    """What :func:`load_checkpoint` returns."""

    state: State
    frame: int
    frames_written: int
    rows: list[dict]
    stepper: dict
    shift: float
    contact: dict  # the IPC contact's state across steps (fem_anim.contact.ipc), or {}


def _dof_keys(V, comm: MPI.Comm) -> np.ndarray:
    """One key per local dof block (owned and ghost): its quantised coordinates as bytes."""
    x = V.tabulate_dof_coordinates()
    lo, hi = np.empty(3), np.empty(3)
    comm.Allreduce(x.min(axis=0) if x.size else np.full(3, np.inf), lo, op=MPI.MIN)
    comm.Allreduce(x.max(axis=0) if x.size else np.full(3, -np.inf), hi, op=MPI.MAX)
    extent = max(float(np.max(hi - lo)), 1e-300)
    q = np.round((x - lo) / extent * 1e9) + 0.0  # + 0.0 turns -0.0 into 0.0
    return np.ascontiguousarray(q).view(np.dtype((np.void, q.dtype.itemsize * 3))).ravel()


def _gather_owned(comm: MPI.Comm, local: np.ndarray) -> np.ndarray | None:
    """Rank 0 gets the owned rows of every rank, concatenated in rank order."""
    parts = comm.gather(local, root=0)
    return np.concatenate(parts) if comm.rank == 0 else None


def save_checkpoint(path: Path, sim, state: State, frame: int, frames_written: int,
                    rows: list[dict], stepper: dict) -> None:
    """Write ``path`` (rank 0) with the full state after ``frame`` frames (collective)."""
    comm = sim.comm
    V = sim.problem.V
    n_owned = V.dofmap.index_map.size_local
    bs = V.dofmap.index_map_bs
    arrays = {"keys": _gather_owned(comm, _dof_keys(V, comm)[:n_owned])}
    for name in FIELDS:
        values = getattr(state, name)
        if comm.allreduce(values is not None, op=MPI.LAND):
            arrays[name] = _gather_owned(comm, values[: n_owned * bs].reshape(n_owned, bs))
    if comm.rank != 0:
        return
    shift = sim.minimiser.shift.c if sim.minimiser.shift else 0.0
    ipc = sim.problem.ipc
    meta = {"scene": scene_hash(sim.scene), "time": state.time, "step": state.step,
            "frame": frame, "frames_written": frames_written, "stepper": stepper,
            "shift": shift, "rows": rows, "contact": ipc.state() if ipc is not None else {}}
    buffer = io.BytesIO()
    np.savez(buffer, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
             **arrays)
    write_atomically(Path(path), buffer.getvalue())


def _invalid(meta, data: dict, sim) -> str | None:
    """What is wrong with a checkpoint's contents for ``sim``, or None.

    A checkpoint is written after frame k, 1 <= k < steps, at t = k h after ``step``
    accepted substeps (one stats row each), with at most k / every + 1 trajectory frames;
    its arrays are one row per dof block of this scene's mesh, all finite.
    """
    if not isinstance(meta, dict) or meta.get("scene") != scene_hash(sim.scene):
        return "it was written for a different scene (the scene's physics changed)"
    cfg = sim.scene["time"]
    h, steps, every = cfg["dt"], cfg["steps"], sim.scene["output"]["every"]
    ints = ("step", "frame", "frames_written")
    if not all(type(meta.get(k)) is int for k in ints) or \
            not all(isinstance(meta.get(k), (int, float)) for k in ("time", "shift")) or \
            not isinstance(meta.get("rows"), list) or not isinstance(meta.get("stepper"), dict):
        return "its record of the run is incomplete"
    frame, step, written = meta["frame"], meta["step"], meta["frames_written"]
    if not 1 <= frame < steps:
        return f"frame {frame} is outside 1..{steps - 1} (time.steps = {steps})"
    if not math.isclose(meta["time"], frame * h, rel_tol=1e-9, abs_tol=1e-9 * h):
        return f"time {meta['time']!r} is not frame {frame} x time.dt = {frame * h!r}"
    if step < frame or len(meta["rows"]) != step:
        return f"step {step} does not match frame {frame} and its {len(meta['rows'])} stats rows"
    if not 1 <= written <= frame // every + 1:
        return f"{written} trajectory frames cannot have been written by frame {frame}"
    dts = [meta["stepper"].get(k) for k in ("dt", "last_dt")]
    if not all(isinstance(v, (int, float)) and 0.0 < v <= h * (1 + 1e-12) for v in dts):
        return f"its time steps {dts} are not in (0, time.dt]"
    if not (math.isfinite(meta["shift"]) and meta["shift"] >= 0.0):
        return f"its Hessian shift {meta['shift']!r} is not a finite number >= 0"
    contact = meta.get("contact", {})
    if not isinstance(contact, dict) or not all(
            isinstance(v, (int, float)) and math.isfinite(v) and v >= 0.0
            for v in contact.values()):
        return f"its contact state {contact!r} is not a table of finite numbers >= 0"
    keys = data.get("keys")
    bs = sim.problem.V.dofmap.index_map_bs
    if keys is None or keys.ndim != 1:
        return "its dof keys are missing"
    for name in FIELDS:
        if name in data:
            a = data[name]
            if a.shape != (keys.size, bs) or a.dtype.kind != "f":
                return f"array {name} has shape {a.shape}, not ({keys.size}, {bs})"
            if not np.all(np.isfinite(a)):
                return f"array {name} holds non-finite values"
    if not all(name in data for name in ("u", "v", "a")):
        return "its state arrays u, v, a are incomplete"
    return None


def load_checkpoint(path: Path, sim) -> Checkpoint:
    """Read ``path`` on every rank and pick this partition's dofs by their keys (collective).

    Raises:
        FemAnimError: if the file is missing or unreadable, was written for another
            scene or mesh, or holds an impossible record (``_invalid``).
    """
    comm = sim.comm
    error, data = None, None
    try:
        with np.load(path) as npz:
            data = {k: npz[k] for k in npz.files}
        meta = json.loads(data.pop("meta").tobytes().decode())
    except FileNotFoundError:
        error = f"no checkpoint to resume from: {path} does not exist"
    except Exception as err:  # a corrupt file: np.load raises many types
        error = f"checkpoint {path} cannot be read: {err}"
    else:
        problem = _invalid(meta, data, sim)
        if problem:
            error = f"checkpoint {path} is not valid: {problem}; nothing was resumed"
    if comm.allreduce(error is not None, op=MPI.LOR):  # collective: every rank raises
        message = comm.bcast(error, root=0)
        raise FemAnimError(message or "the checkpoint could not be read on every process")
    local = _dof_keys(sim.problem.V, comm)
    order = np.argsort(data["keys"])
    sorted_keys = data["keys"][order]
    where = np.minimum(np.searchsorted(sorted_keys, local), sorted_keys.size - 1)
    if comm.allreduce(bool(np.any(sorted_keys[where] != local)), op=MPI.LOR):
        raise FemAnimError(f"checkpoint {path} does not match this mesh")
    rows_of_local = order[where]
    fields = {name: data[name][rows_of_local].ravel() if name in data else None
              for name in FIELDS}
    state = State(**fields, time=meta["time"], step=meta["step"])
    return Checkpoint(state, meta["frame"], meta["frames_written"], meta["rows"],
                      meta["stepper"], meta["shift"], meta.get("contact", {}))
