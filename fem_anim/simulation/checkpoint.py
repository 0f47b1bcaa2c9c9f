"""Checkpoints: everything a run needs to continue exactly where it was.

Every ``output.checkpoint_every`` frames rank 0 writes ``checkpoint.npz`` atomically
(temp file, fsync, rename: a kill leaves the previous checkpoint or the new one, never a
half-written file). It holds the state arrays in global dof order (u, v, a and, for BDF2,
u_{n-1}, v_{n-1}; the pressure of the mixed formulation, Newton's start for its next
step), time, step and frame counters, the adaptive time-step state, the Hessian shift,
the contact's state across steps (IPC's adaptive barrier stiffness), the number of
trajectory frames written, the stats rows so far, the scene's physics and the solver
settings. A resumed run therefore repeats exactly the arithmetic of an uninterrupted one
when the solver settings are the same (:doc:`/resume`).

Dofs are keyed by identity, not by the global dof numbering (which depends on the mesh
partition): a dof at a vertex by the vertex's row in the input mesh (DOLFINx keeps it as
``geometry.input_global_indices``), a dof on an edge (P2) by its two vertices' rows. A
checkpoint therefore resumes on any number of processes and at any scene extent.

The physics must be the same: every key but ``[solver]``, ``[output]`` and ``[render]``
(a change is refused, naming the key). The solver settings may change; :func:`describe_resume`
says which ones the resumed run continues with.

A run with a shell body beside solids keeps the same record (:func:`run_meta`,
:func:`invalid_record`) and one set of state arrays per part (:func:`part_arrays`,
:func:`part_fields`): :mod:`fem_anim.simulation.joint_checkpoint`.
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

from fem_anim import compat
from fem_anim.errors import FemAnimError
from fem_anim.output.rundir import write_atomically
from fem_anim.simulation.frame_clock import frame_clock
from fem_anim.simulation.hessian_pattern import extra_couplings, restore_couplings
from fem_anim.simulation.integrators import State

__all__ = ["Checkpoint", "save_checkpoint", "load_checkpoint", "scene_hash", "physics_data",
           "dof_identity", "describe_resume", "restore_pattern", "NOT_PHYSICS", "part_arrays",
           "part_fields", "run_meta", "write_checkpoint", "read_checkpoint", "invalid_record",
           "invalid_arrays", "solver_settings"]

FIELDS = ("u", "v", "a", "u_old", "v_old")
#: Scene tables that do not shape the motion: a resumed run may change them.
NOT_PHYSICS = ("solver", "output", "render")


def physics_data(scene) -> dict:
    """The validated scene without :data:`NOT_PHYSICS`: everything that shapes the motion."""
    return {k: v for k, v in scene.data.items() if k not in NOT_PHYSICS}


def scene_hash(scene) -> str:
    """A fingerprint of :func:`physics_data`."""
    return hashlib.sha256(json.dumps(physics_data(scene), sort_keys=True).encode()).hexdigest()


def _flat(data, prefix: str = "") -> dict[str, object]:
    """Nested tables as ``{"a.b.c": value}`` (lists of tables by index: ``body.1.name``)."""
    if isinstance(data, dict):
        items = data.items()
    elif isinstance(data, list) and any(isinstance(v, (dict, list)) for v in data):
        items = ((str(i), v) for i, v in enumerate(data))
    else:
        return {prefix: data}
    out: dict[str, object] = {}
    for key, value in items:
        out |= _flat(value, f"{prefix}.{key}" if prefix else str(key))
    return out


def _changes(old: dict, new: dict) -> list[str]:
    """``key = new (was old)`` for every key that differs between two nested tables."""
    a, b = _flat(old), _flat(new)
    return [f"{key} = {json.dumps(b.get(key))} (was {json.dumps(a.get(key))})"
            for key in sorted(a.keys() | b.keys()) if a.get(key) != b.get(key)]


@dataclass
class Checkpoint:
    """What :func:`load_checkpoint` returns."""

    state: State  # a joint run's: a JointState (fem_anim.simulation.joint_loop)
    frame: int
    frames_written: int
    rows: list[dict]
    stepper: dict
    shift: float
    contact: dict  # the IPC contact's state across steps (fem_anim.contact.ipc), or {}
    pressure: np.ndarray | None  # the mixed formulation's p / mu (local dofs of Q), or None
    solver: dict  # the solver settings it was written with: [solver] and PETSc options
    couplings: np.ndarray | None = None  # the Hessian's contact couplings (hessian_pattern)


def dof_identity(V, domain) -> np.ndarray:
    """One key per local dof block of a Lagrange space of degree <= 2 (owned and ghost).

    A vertex dof is keyed by the vertex's input row i (as i N + i), an edge dof by its
    vertices' rows i < j (as i N + j), N the number of input points: the same on any
    partition and at any coordinates. The cell's dofs are its vertices' (reference order,
    as the geometry's nodes), then one per edge in basix's reference edge order.

    Args:
        V: The space (P1 or P2, scalar or blocked).
        domain: The :class:`~fem_anim.mesh.simplex.SimplexMesh` it lives on.

    Returns:
        int64 keys, one per local dof block.
    """
    import basix

    mesh = domain.mesh
    tdim = mesh.topology.dim
    nodes = compat.geometry_dofmap(mesh)
    num_cells = nodes.shape[0]
    dofs = compat.cell_dofs(V)[:num_cells]
    vertex = np.asarray(domain.input_index, np.int64)[nodes[:, : tdim + 1]]
    base = mesh.comm.allreduce(int(domain.input_index.max(initial=-1)) + 1, op=MPI.MAX)
    edges = basix.topology(compat.basix_cell(("triangle", "tetrahedron")[tdim - 2]))[1]
    keys = np.full(V.dofmap.index_map.size_local + V.dofmap.index_map.num_ghosts, -1, np.int64)
    keys[dofs[:, : tdim + 1]] = vertex * (base + 1)
    for position, (i, j) in enumerate(edges[: dofs.shape[1] - tdim - 1], start=tdim + 1):
        lo = np.minimum(vertex[:, i], vertex[:, j])
        keys[dofs[:, position]] = lo * base + np.maximum(vertex[:, i], vertex[:, j])
    return keys


def _gather_owned(comm: MPI.Comm, local: np.ndarray) -> np.ndarray | None:
    """Rank 0 gets the owned rows of every rank, concatenated in rank order."""
    parts = comm.gather(local, root=0)
    return np.concatenate(parts) if comm.rank == 0 else None


def solver_settings(sim) -> dict:
    """The settings a resumed run may change: ``[solver]`` and the merged PETSc options."""
    return {"solver": sim.scene.data.get("solver", {}), "petsc": dict(sim.options)}


def _grows(sim) -> bool:
    """Whether the step Hessian's pattern grows with contact (AIJ with ``[contact]``)."""
    kind = sim.minimiser.A.getType()
    return sim.problem.ipc is not None and not sim.problem.mixed and kind.endswith("aij") \
        and "baij" not in kind


def restore_pattern(sim, ck: "Checkpoint") -> None:
    """Give the resumed run's Hessian the pattern the checkpointed one had (collective;
    :mod:`fem_anim.simulation.hessian_pattern`)."""
    if _grows(sim):
        restore_couplings(sim.minimiser.A, sim.problem.V, dof_identity(sim.problem.V,
                                                                       sim.domain),
                          ck.couplings)


def part_arrays(comm: MPI.Comm, V, domain, state: State, prefix: str = "") -> dict:
    """One part's checkpoint arrays (rank 0; collective): ``{prefix}keys`` (the owned dofs'
    :func:`dof_identity`) and ``{prefix}u``, ... of :data:`FIELDS` that every rank holds,
    one row per owned dof block, in rank order."""
    n_owned = V.dofmap.index_map.size_local
    bs = V.dofmap.index_map_bs
    arrays = {f"{prefix}keys": _gather_owned(comm, dof_identity(V, domain)[:n_owned])}
    for name in FIELDS:
        values = getattr(state, name)
        if comm.allreduce(values is not None, op=MPI.LAND):
            arrays[f"{prefix}{name}"] = _gather_owned(
                comm, values[: n_owned * bs].reshape(n_owned, bs))
    return arrays


def run_meta(scene, solver: dict, state, frame: int, frames_written: int, rows: list[dict],
             stepper: dict, shift: float, contact: dict) -> dict:
    """The record of a run a checkpoint holds besides its arrays (the one-body run's and a
    joint run's alike; :func:`invalid_record` checks it)."""
    return {"scene": scene_hash(scene), "physics": physics_data(scene), "solver": solver,
            "time": state.time, "step": state.step, "frame": frame,
            "frames_written": frames_written, "stepper": stepper,
            "every": scene["output"]["every"], "shift": shift, "rows": rows,
            "contact": contact}


def write_checkpoint(path: Path, meta: dict, arrays: dict) -> None:
    """``meta`` and ``arrays`` into ``path`` as one ``.npz``, atomically (rank 0)."""
    buffer = io.BytesIO()
    np.savez(buffer, meta=np.frombuffer(json.dumps(meta).encode(), dtype=np.uint8),
             **arrays)
    write_atomically(Path(path), buffer.getvalue())


def save_checkpoint(path: Path, sim, state: State, frame: int, frames_written: int,
                    rows: list[dict], stepper: dict) -> None:
    """Write ``path`` (rank 0) with the full state after ``frame`` frames (collective)."""
    comm = sim.comm
    p = sim.problem
    V = p.V
    arrays = part_arrays(comm, V, sim.domain, state)
    if p.mixed:  # Newton's start of the next step keeps the last pressure
        Q = p.fields.Q
        q_owned = Q.dofmap.index_map.size_local
        arrays["p_keys"] = _gather_owned(comm, dof_identity(Q, sim.domain)[:q_owned])
        arrays["p"] = _gather_owned(comm, p.p.x.array[:q_owned].reshape(q_owned, 1))
    if _grows(sim):  # the contact pairs met so far, as the Hessian's pattern holds them
        arrays["couplings"] = extra_couplings(sim.minimiser.A, V, dof_identity(V, sim.domain))
    if comm.rank != 0:
        return
    shift = sim.minimiser.shift.c if sim.minimiser.shift else 0.0
    ipc = p.ipc
    meta = run_meta(sim.scene, solver_settings(sim), state, frame, frames_written, rows,
                    stepper, shift, ipc.state() if ipc is not None else {})
    write_checkpoint(path, meta, arrays)


def _invalid(meta, data: dict, sim) -> str | None:
    """What is wrong with a checkpoint's contents for ``sim``, or None.

    A checkpoint is written after frame k, 1 <= k < K (the frame clock's last frame), at the
    frame's time (:func:`~fem_anim.simulation.frame_clock.frame_clock`) after ``step``
    accepted substeps (one stats row each), with at most k / every + 1 trajectory frames;
    its arrays are one row per dof block of this scene's mesh, all finite.
    """
    clock = frame_clock(sim.scene)
    problem = invalid_record(meta, sim.scene, clock.count, clock.step, clock.time)
    if problem:
        return problem
    bs = sim.problem.V.dofmap.index_map_bs
    shapes = {"keys": (FIELDS, bs)}
    if sim.problem.mixed:
        shapes["p_keys"] = (("p",), 1)
        if "p" not in data:
            return "its pressure (element.formulation = \"mixed\") is missing"
    return invalid_arrays(data, shapes)


def invalid_record(meta, scene, steps: int, h: float, time_of) -> str | None:
    """What is wrong with a checkpoint's record (:func:`run_meta`) of a run of ``scene``
    with frames 0..``steps`` at ``time_of(k)`` reached by steps of at most ``h``, or None.

    The physics must be ``scene``'s (else the message names the changed keys); the record
    is after frame k, 1 <= k < ``steps``, at its time, after ``step`` accepted substeps
    (one stats row each), with at most k / every + 1 trajectory frames.
    """
    if not isinstance(meta, dict) or meta.get("scene") != scene_hash(scene):
        changed = _changes(meta.get("physics", {}), physics_data(scene)) \
            if isinstance(meta, dict) and isinstance(meta.get("physics"), dict) else []
        what = f": {'; '.join(changed)}" if changed else ""
        return f"it was written for a different scene (the scene's physics changed{what}; " \
               f"only {', '.join(f'[{t}]' for t in NOT_PHYSICS)} may change on resume)"
    every = scene["output"]["every"]
    ints = ("step", "frame", "frames_written")
    if not all(type(meta.get(k)) is int for k in ints) or \
            not all(isinstance(meta.get(k), (int, float)) for k in ("time", "shift")) or \
            not isinstance(meta.get("rows"), list) or not isinstance(meta.get("stepper"), dict):
        return "its record of the run is incomplete"
    frame, step, written = meta["frame"], meta["step"], meta["frames_written"]
    if type(meta.get("every")) is int and meta["every"] >= 1:  # output.every may change
        every = meta["every"]
    if not 1 <= frame < steps:
        return f"frame {frame} is outside 1..{steps - 1} (the run's last frame is {steps})"
    if not math.isclose(meta["time"], time_of(frame), rel_tol=1e-9, abs_tol=1e-9 * h):
        return f"time {meta['time']!r} is not frame {frame}'s time {time_of(frame)!r}"
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
    return None


def invalid_arrays(data: dict, shapes: dict[str, tuple[tuple[str, ...], int]]) -> str | None:
    """What is wrong with a checkpoint's arrays, or None.

    Args:
        data: The arrays by name.
        shapes: For each key array's name, the names of the arrays with one row per key
            and their width; the first three names (u, v, a) must be present.
    """
    for key_name, (names, width) in shapes.items():
        keys = data.get(key_name)
        if keys is None or keys.ndim != 1 or keys.dtype != np.int64:
            return "its dof keys are missing"
        for name in names:
            if name in data:
                a = data[name]
                if a.shape != (keys.size, width) or a.dtype.kind != "f":
                    return f"array {name} has shape {a.shape}, not ({keys.size}, {width})"
                if not np.all(np.isfinite(a)):
                    return f"array {name} holds non-finite values"
    for names, _ in shapes.values():
        if len(names) >= 3 and not all(name in data for name in names[:3]):
            return f"its state arrays {', '.join(names[:3])} are incomplete"
    couplings = data.get("couplings")
    if couplings is not None and (couplings.ndim != 2 or couplings.shape[1] != 2
                                  or couplings.dtype != np.int64):
        return f"its contact couplings have shape {couplings.shape}, not (n, 2) integers"
    return None


def _rows_of(stored: np.ndarray, local: np.ndarray, comm: MPI.Comm, path: Path) -> np.ndarray:
    """The row of ``stored`` holding each of ``local``'s keys (collective).

    Raises:
        FemAnimError: (on every rank) if a key is missing or stored twice.
    """
    order = np.argsort(stored, kind="stable")
    sorted_keys = stored[order]
    where = np.minimum(np.searchsorted(sorted_keys, local), max(sorted_keys.size - 1, 0))
    bad = sorted_keys.size == 0 or bool(np.any(sorted_keys[where] != local)) or \
        bool(np.any(sorted_keys[1:] == sorted_keys[:-1]))
    if comm.allreduce(bad, op=MPI.LOR):
        raise FemAnimError(f"checkpoint {path} does not match this mesh")
    return order[where]


def read_checkpoint(path: Path, comm: MPI.Comm, check) -> tuple[dict, dict]:
    """The record and arrays of ``path``, read on every rank (collective).

    Args:
        path: The checkpoint file.
        comm: The communicator.
        check: ``check(meta, data)``: what is wrong with them, or None.

    Raises:
        FemAnimError: (on every rank) if the file is missing or unreadable or ``check``
            finds a fault.
    """
    error, data, meta = None, None, None
    try:
        with np.load(path) as npz:
            data = {k: npz[k] for k in npz.files}
        meta = json.loads(data.pop("meta").tobytes().decode())
    except FileNotFoundError:
        error = f"no checkpoint to resume from: {path} does not exist"
    except Exception as err:  # a corrupt file: np.load raises many types
        error = f"checkpoint {path} cannot be read: {err}"
    else:
        problem = check(meta, data)
        if problem:
            error = f"checkpoint {path} is not valid: {problem}; nothing was resumed"
    if comm.allreduce(error is not None, op=MPI.LOR):  # collective: every rank raises
        message = comm.bcast(error, root=0)
        raise FemAnimError(message or "the checkpoint could not be read on every process")
    return meta, data


def part_fields(data: dict, V, domain, comm: MPI.Comm, path: Path,
                prefix: str = "") -> dict[str, np.ndarray | None]:
    """This partition's local dof values (ghosts included) of each of :data:`FIELDS` saved
    by :func:`part_arrays` (None where not saved), picked by their keys (collective)."""
    rows = _rows_of(data[f"{prefix}keys"], dof_identity(V, domain), comm, path)
    return {name: data[f"{prefix}{name}"][rows].ravel() if f"{prefix}{name}" in data
            else None for name in FIELDS}


def load_checkpoint(path: Path, sim) -> Checkpoint:
    """Read ``path`` on every rank and pick this partition's dofs by their keys (collective).

    Raises:
        FemAnimError: if the file is missing or unreadable, was written for another
            scene (naming the physics keys that changed) or mesh, or holds an impossible
            record (``_invalid``).
    """
    comm = sim.comm
    meta, data = read_checkpoint(path, comm, lambda meta, data: _invalid(meta, data, sim))
    p = sim.problem
    fields = part_fields(data, p.V, sim.domain, comm, path)
    pressure = None
    if p.mixed:
        pressure = data["p"][_rows_of(data["p_keys"], dof_identity(p.fields.Q, sim.domain),
                                      comm, path)].ravel()
    state = State(**fields, time=meta["time"], step=meta["step"])
    return Checkpoint(state, meta["frame"], meta["frames_written"], meta["rows"],
                      meta["stepper"], meta["shift"], meta.get("contact", {}), pressure,
                      meta.get("solver", {}), data.get("couplings"))


def describe_resume(ck: Checkpoint, sim, path: Path) -> str:
    """One line: where the run continues and with which solver settings.

    Args:
        ck: The loaded checkpoint.
        sim: The resumed :class:`~fem_anim.simulation.loop.Simulation`.
        path: The run directory.

    Returns:
        ``resuming PATH at frame k of N (t = ...) with the same solver settings`` or
        ``... with changed solver settings: solver.hessian = "shift" (was "exact"), ...``.
    """
    steps = sim.scene["time"]["steps"]
    where = f"resuming {path} at frame {ck.frame} of {steps} (t = {ck.state.time:.6g} s)"
    if not ck.solver:
        return f"{where} (its checkpoint does not record the solver settings)"
    now = solver_settings(sim)
    changed = _changes({"solver": ck.solver.get("solver", {})}, {"solver": now["solver"]}) + \
        _changes({"petsc": ck.solver.get("petsc", {})}, {"petsc": now["petsc"]})
    if not changed:
        return f"{where} with the same solver settings"
    return f"{where} with changed solver settings: {', '.join(changed)}"
