"""The frame loop of :meth:`Simulation.run <fem_anim.simulation.loop.Simulation.run>`:
frames at k / ``output.fps`` up to ``time.steps * time.dt`` (the frame clock,
:mod:`fem_anim.simulation.frame_clock`), each reached by adaptive substeps no longer than
``time.dt`` (:class:`~fem_anim.simulation.adaptive.AdaptiveStepper`), with the run's files.

Per frame it writes the stats rows and, every ``output.every`` frames, the trajectory
frame (displacement and cell energy density, and every dof of the fields
``output.fields`` asks for: :meth:`Simulation.frame_dofs
<fem_anim.simulation.loop.Simulation.frame_dofs>`), and every ``output.checkpoint_every`` frames
a checkpoint (:mod:`fem_anim.simulation.checkpoint`); at the end the final state and the
scene. Every file operation is collective: rank 0 writes, an OS error becomes one message
naming the file, raised on every rank.
"""

from __future__ import annotations

import signal
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fem_anim.errors import FemAnimError, Interrupted, describe_os_error
from fem_anim.export.usd_stage import export_staged_run, usd_file_name
from fem_anim.output.files import RunDirectory, StatsWriter, write_final, write_scene
from fem_anim.output.trajectory import TrajectoryWriter
from fem_anim.simulation.adaptive import AdaptiveStepper
from fem_anim.simulation.checkpoint import (Checkpoint, describe_resume, load_checkpoint,
                                            restore_pattern, save_checkpoint)
from fem_anim.simulation.frame_clock import FrameClock, frame_clock
from fem_anim.simulation.integrators import State
from fem_anim.simulation.interrupt import Interrupts
from fem_anim.simulation.progress import Progress

__all__ = ["RunResult", "run_frames"]


@dataclass
class RunResult:
    """What a finished run produced."""

    state: State
    rows: list[dict]
    output_dir: Path | None
    final_displacement: np.ndarray | None  # rank 0, input vertex order
    resumed_rows: int = 0  # rows taken over from the checkpoint of a resumed run


def run_frames(sim, output_dir: Path | None, quiet: bool, resume: bool) -> RunResult:
    """:meth:`Simulation.run <fem_anim.simulation.loop.Simulation.run>` (see there)."""
    clock, every = frame_clock(sim.scene), sim.scene["output"]["every"]
    run_dir = RunDirectory(output_dir, sim.comm, resume) if output_dir is not None \
        else None
    start = time.perf_counter()
    try:  # nothing is deleted on failure: the staging area is what --resume continues
        with Interrupts(sim.comm) as interrupts:
            try:
                result = _loop(sim, clock, every, run_dir, quiet, resume, interrupts)
            except FemAnimError as err:
                if interrupts.received is None or isinstance(err, Interrupted):
                    raise
                name = signal.Signals(interrupts.received).name  # a 2nd signal inside PETSc
                raise Interrupted(f"interrupted by {name} (twice)",
                                  interrupts.received) from None
        loop_s = time.perf_counter() - start
        stepping = sum(row["step_wall_s"] + row.get("retry_wall_s", 0.0)  # discarded tries too
                       for row in result.rows[result.resumed_rows:])
        sim.clock.add("stepping", stepping)
        sim.clock.add("output", loop_s - stepping)  # frames, stats, checkpoints, finals
        if run_dir is not None:
            with sim.clock.phase("output"):
                if sim.scene["output"]["usd"]:  # installed with the run's other files
                    _io(sim, run_dir.file(usd_file_name(sim.scene.name)), export_staged_run,
                        run_dir.staging, sim.scene.name, sim.comm, clock.start_frame)
                run_dir.commit()
            if sim.scene["output"]["render"]:
                with sim.clock.phase("render"):
                    _render(sim, run_dir.path, quiet)
    finally:
        if run_dir is not None:
            run_dir.close()
    return result


def _render(sim, path: Path, quiet: bool) -> None:
    """Pictures of the committed run (rank 0, in another process); errors are collective.

    A failed rendering keeps the run's data: ``fem-anim render`` can try again.
    """
    error = None
    if sim.comm.rank == 0:
        from fem_anim.render.process import render_run

        try:
            render_run(path, sim.scene["render"], quiet=quiet)
        except (FemAnimError, RuntimeError) as err:
            error = f"{err} (the run's data are kept in {path}: render them again with " \
                    f"`fem-anim render {path}`)"
    error = sim.comm.bcast(error, root=0)
    if error:
        raise FemAnimError(error)


def _io(sim, path: Path, write, *args):
    """``write(*args)`` (rank 0 writes; collective): an OS error becomes one message naming
    the file, raised on every rank."""
    error, result = None, None
    try:
        result = write(*args)
    except OSError as err:
        error = describe_os_error(err, path)
    error = sim.comm.bcast(error, root=0)
    if error:
        raise FemAnimError(f"{error} (nothing was deleted)")
    return result


def _restore(sim, stepper: AdaptiveStepper, ck: Checkpoint) -> None:
    """Put a checkpoint's state across steps back: the adaptive step, the Hessian shift,
    the contact's barrier stiffness and the Hessian's pattern, the mixed formulation's
    pressure, the velocity the energies report (collective)."""
    stepper.dt, stepper.last_dt = min(ck.stepper["dt"], stepper.h), ck.stepper["last_dt"]
    if sim.minimiser.shift:
        sim.minimiser.shift.c = ck.shift
    p = sim.problem
    if p.ipc is not None:
        p.ipc.restore(ck.contact)
    if ck.pressure is not None:  # the unknown (u, p) as the last step left it
        p.fields.w.x.array[p.fields.p_dofs] = ck.pressure
        p.fields.set_displacement(ck.state.u)
        p.p.x.array[:] = ck.pressure
    p.u.x.array[:] = ck.state.u
    p.v.x.array[:] = ck.state.v
    try:
        restore_pattern(sim, ck)
    except KeyError as err:
        raise FemAnimError(f"the checkpoint does not match this mesh: {err.args[0]}") from None


def _on_frame(state: State, clock: FrameClock, frame: int) -> State:
    """The state with its time set to frame ``frame``'s exact time k/fps.

    The stepper lands on the frame time up to the round-off of summing substeps; the frame
    is written (and its time recorded) at k/fps exactly, so time codes are whole numbers.

    Raises:
        FemAnimError: if the state is not at that frame's time (a checkpoint of another
            frame clock, e.g. written before ``output.fps`` or with other time keys).
    """
    t = clock.time(frame)
    if abs(state.time - t) > 1e-9 * clock.step:
        raise FemAnimError(f"the state at t = {state.time!r} s is not frame {frame} at "
                           f"t = {t!r} s of output.fps = {clock.fps:g} (were time.dt or "
                           "output.fps changed?)")
    return replace(state, time=t)


def _loop(sim, clock: FrameClock, every, run_dir, quiet, resume, interrupts) -> RunResult:
    stepper = AdaptiveStepper(sim, clock.step, sim.scene["time"])
    steps = clock.count
    checkpoint_every = sim.scene["output"]["checkpoint_every"] or max(1, steps // 10)
    first, rows, kept, resumed_rows = 1, [], None, 0
    if resume:
        ck = load_checkpoint(run_dir.file("checkpoint.npz"), sim)
        state, first, rows, kept = ck.state, ck.frame + 1, ck.rows, ck.frames_written
        state = _on_frame(state, clock, ck.frame)
        resumed_rows = len(rows)
        _restore(sim, stepper, ck)
    else:
        state = sim.initial_state()
    stats_file = trajectory = None
    if run_dir:  # the trajectory first: a resume it refuses leaves stats.csv as it was
        trajectory = _io(sim, run_dir.file("trajectory.h5"), TrajectoryWriter,
                         run_dir.file("trajectory.xdmf"), sim.domain, kept,
                         {name: g.nodes for name, g in sim.dof_gathers.items()})
        stats_file = _io(sim, run_dir.file("stats.csv"), StatsWriter,
                         run_dir.file("stats.csv"), sim.comm, rows)

    def checkpoint(frame: int) -> None:
        """Write the checkpoint of ``frame`` (collective)."""
        path = run_dir.file("checkpoint.npz")
        _io(sim, path, save_checkpoint, path, sim, state, frame,
            len(trajectory.times) if trajectory.rank0 else 0, rows,
            {"dt": stepper.dt, "last_dt": stepper.last_dt})

    if resume and sim.comm.rank == 0:
        line = describe_resume(ck, sim, run_dir.path)
        if not quiet or "with changed solver settings" in line:
            print(f"fem-anim: {line}", file=sys.stderr)
    progress = Progress(steps, disable=quiet or sim.comm.rank != 0)
    progress.update(0, advance=first - 1)
    try:
        if trajectory and not resume:
            _io(sim, trajectory.h5_path, trajectory.write, 0.0, *sim.frame_fields(state),
                sim.frame_dofs(state))
        for frame in range(first, steps + 1):
            for state, row in stepper.advance(state, clock.time(frame)):
                rows.append(row)
                if stats_file:
                    _io(sim, stats_file.path, stats_file.write, row)
            state = _on_frame(state, clock, frame)
            if trajectory and (frame % every == 0 or frame == steps):
                _io(sim, trajectory.h5_path, trajectory.write, state.time,
                    *sim.frame_fields(state), sim.frame_dofs(state))
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
    final, energy_density = sim.frame_fields(state)
    if run_dir is not None:
        _io(sim, trajectory.h5_path, trajectory.finish)
        _io(sim, run_dir.file("final.vtu"), write_final, run_dir.file("final.vtu"),
            sim.domain, final, energy_density)
        _io(sim, run_dir.file("scene.json"), write_scene, run_dir.file("scene.json"),
            sim.scene, sim.comm)
    return RunResult(state, rows, run_dir.path if run_dir else None, final, resumed_rows)
