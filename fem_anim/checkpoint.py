"""Checkpoints: everything a run needs to continue exactly where it was.

Every ``output.checkpoint_every`` frames rank 0 writes ``checkpoint.npz`` atomically
(temp file, fsync, rename: a kill leaves the previous checkpoint or the new one, never a
half-written file). It holds the state arrays in global dof order (u, v, a and, for BDF2,
u_{n-1}, v_{n-1}), time, step and frame counters, the adaptive time-step state, the
Hessian shift, the number of trajectory frames written and the stats rows so far. A
resumed run therefore repeats exactly the arithmetic of an uninterrupted one.

The global dof numbering depends on the mesh partition, so a checkpoint resumes on the
same number of processes; the scene must be the same (its validated data are hashed).
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mpi4py import MPI

from .errors import FemAnimError
from .integrator import State
from .output import write_atomically

__all__ = ["Checkpoint", "save_checkpoint", "load_checkpoint", "scene_hash"]

FIELDS = ("u", "v", "a", "u_old", "v_old")


def scene_hash(scene) -> str:
    """A fingerprint of the validated scene (output settings excluded)."""
    data = {k: v for k, v in scene.data.items() if k != "output"}
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


def _owned_range(V) -> tuple[int, int, int]:
    index_map = V.dofmap.index_map
    bs = V.dofmap.index_map_bs
    start, end = index_map.local_range
    return start * bs, end * bs, index_map.size_global * bs


def _gather(comm: MPI.Comm, local: np.ndarray, start: int, size: int) -> np.ndarray | None:
    parts = comm.gather((start, local), root=0)
    if comm.rank != 0:
        return None
    out = np.empty(size)
    for offset, part in parts:
        out[offset:offset + part.size] = part
    return out


def save_checkpoint(path: Path, sim, state: State, frame: int, frames_written: int,
                    rows: list[dict], stepper: dict) -> None:
    """Write ``path`` (rank 0) with the full state after ``frame`` frames (collective)."""
    comm = sim.comm
    start, end, size = _owned_range(sim.problem.V)
    arrays = {}
    for name in FIELDS:
        values = getattr(state, name)
        present = comm.allreduce(values is not None, op=MPI.LAND)
        if present:
            arrays[name] = _gather(comm, values[: end - start], start, size)
    if comm.rank != 0:
        return
    shift = sim.minimiser.shift.c if sim.minimiser.shift else 0.0
    meta = {"scene": scene_hash(sim.scene), "ranks": comm.size, "time": state.time,
            "step": state.step, "frame": frame, "frames_written": frames_written,
            "stepper": stepper, "shift": shift, "rows": rows}
    buffer = io.BytesIO()
    np.savez(buffer, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
             **arrays)
    write_atomically(Path(path), buffer.getvalue())


def load_checkpoint(path: Path, sim) -> Checkpoint:
    """Read ``path`` on every rank and scatter the state to this partition (collective).

    Raises:
        FemAnimError: if the file is missing or unreadable, or was written for another
            scene or another number of processes.
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
        if meta["scene"] != scene_hash(sim.scene):
            error = f"checkpoint {path} was written for a different scene"
        elif meta["ranks"] != comm.size:
            error = (f"checkpoint {path} was written by {meta['ranks']} processes; resume it "
                     f"with mpirun -n {meta['ranks']}")
    if comm.allreduce(error is not None, op=MPI.LOR):  # collective: every rank raises
        message = comm.bcast(error, root=0)
        raise FemAnimError(message or "the checkpoint could not be read on every process")
    start, end, _ = _owned_range(sim.problem.V)
    n_local = sim.problem.u.x.array.size
    fields = {}
    for name in FIELDS:
        if name not in data:
            fields[name] = None
            continue
        function = sim.problem.u_prev  # scratch Function to scatter owned -> ghosts
        function.x.array[: end - start] = data[name][start:end]
        function.x.scatter_forward()
        fields[name] = function.x.array[:n_local].copy()
    state = State(**fields, time=meta["time"], step=meta["step"])
    return Checkpoint(state, meta["frame"], meta["frames_written"], meta["rows"],
                      meta["stepper"], meta["shift"])
