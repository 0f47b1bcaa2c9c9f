"""``fem-anim run`` of a scene with a shell body beside solids: the steps and the files.

The scene is split into the solids' and the shell's scenes and stepped as one minimisation
per step (:class:`~fem_anim.simulation.joint_loop.JointSimulation`; seed eq. 4). The run
reaches ``time.steps`` frames of ``time.dt``, each by substeps retried with dt halved when
one does not converge (:class:`~fem_anim.simulation.adaptive.AdaptiveStepper`,
``time.adaptive``, ``time.min_dt``), and writes, like a one-mesh run, into a claimed output
directory whose files are installed only when the run succeeds
(:class:`~fem_anim.output.files.RunDirectory`):

* ``solids.xdmf`` + ``.h5`` and ``shell.xdmf`` + ``.h5``: each mesh's trajectory
  (displacement and cell energy density per frame, every ``output.every`` steps and the
  last; ParaView opens both), ``final_solids.vtu`` and ``final_shell.vtu``;
* ``trajectory.xdmf`` + ``.h5``: what is seen, one triangle surface in 3D: the solids'
  boundary triangles and the shell's triangles (all vertices of both meshes, solids first),
  with the displacement and, per triangle, the energy density of the solid's tetrahedron
  under it (J/m^3) or of the shell's triangle (J/m^2). ``fem-anim render`` draws it (each
  body its colour with ``render.color_by = "body"``), so ``output.render`` makes the usual
  pictures;
* ``stats.csv``: one row per substep (Newton and linear iterations, the energies of both
  bodies and the barrier, the contact pairs and smallest distance, wall times);
* ``scene.json`` (the scene as validated) and ``summary.json`` (steps, iterations, the
  energy report of :func:`~fem_anim.simulation.energy_report.energy_report` over both
  bodies, software versions, PETSc options).

With ``output.usd`` the run also writes ``<scene>.usdc`` (the solids' boundaries and the
cloth, one mesh per body: :mod:`fem_anim.export.usd_stage`), which ``fem-anim export``
writes from a finished run too.

Like a one-mesh run it writes ``checkpoint.npz`` every ``output.checkpoint_every`` frames
(:mod:`fem_anim.simulation.joint_checkpoint`), stops at the end of a frame on SIGINT, SIGTERM
or SIGHUP with a checkpoint there (a second signal stops it at once:
:mod:`fem_anim.simulation.interrupt`), and ``--resume`` continues it (:doc:`/resume`).
"""

from __future__ import annotations

import signal
import sys
from pathlib import Path

from types import SimpleNamespace

import numpy as np
from mpi4py import MPI

from fem_anim.errors import FemAnimError, Interrupted, describe_os_error
from fem_anim.export.usd_stage import export_staged_run, usd_file_name
from fem_anim.output.files import (CellGather, RunDirectory, StatsWriter, VertexGather,
                                   write_final, write_scene)
from fem_anim.output.trajectory import TrajectoryWriter
from fem_anim.scene.loading import Scene
from fem_anim.simulation.energy_report import energy_report, roundoff_energy, write_summary
from fem_anim.simulation.adaptive import AdaptiveStepper
from fem_anim.simulation.checkpoint import describe_resume
from fem_anim.simulation.interrupt import Interrupts, stop_at_once
from fem_anim.simulation.joint_checkpoint import (load_joint_checkpoint, restore_joint,
                                                  save_joint_checkpoint, solver_view)
from fem_anim.simulation.joint_loop import JointSimulation, JointState

__all__ = ["PART_FILES", "run_joint", "surface_of_parts"]

#: The file stem of each part's trajectory and final state, in the parts' order.
PART_FILES = ("solids", "shell")

#: The four faces of a tetrahedron (local vertices).
_TET_FACES = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])


def surface_of_parts(points: list[np.ndarray], cells: list[np.ndarray]) -> tuple[
        np.ndarray, np.ndarray, list[np.ndarray]]:
    """The seen surface of the parts' input meshes: a tetrahedral mesh's boundary triangles
    (faces of one tetrahedron only), a triangle mesh's triangles (rank 0 arrays).

    Args:
        points: Each part's input points.
        cells: Each part's input cells (tetrahedra or triangles).

    Returns:
        ``(points, triangles, parents)``: the parts' points stacked, the triangles on them,
        and for each part the cell each of its triangles comes from.
    """
    tris, parents, first = [], [], 0
    for X, c in zip(points, cells):
        if c.shape[1] == 4:
            faces = np.sort(c[:, _TET_FACES].reshape(-1, 3), axis=1)
            unique, index, counts = np.unique(faces, axis=0, return_index=True,
                                              return_counts=True)
            tris.append(unique[counts == 1] + first)
            parents.append(index[counts == 1] // 4)
        else:
            tris.append(c + first)
            parents.append(np.arange(len(c)))
        first += len(X)
    return np.concatenate(points), np.concatenate(tris).astype(np.int64), parents


def _io(comm: MPI.Comm, path: Path, write, *args):
    """``write(*args)`` (rank 0 writes; collective): an OS error is one message naming the
    file, raised on every rank."""
    error, result = None, None
    try:
        result = write(*args)
    except OSError as err:
        error = describe_os_error(err, path)
    error = comm.bcast(error, root=0)
    if error:
        raise FemAnimError(f"{error} (nothing was deleted)")
    return result


def run_joint(scene: Scene, out: Path, comm: MPI.Comm = MPI.COMM_WORLD,
              cli_options: dict[str, str] | None = None, quiet: bool = False,
              provenance: dict | None = None, preset: str | None = None,
              resume: bool = False,
              sim: JointSimulation | None = None) -> tuple[list[dict], dict]:
    """Run a scene with a shell body for ``time.steps`` steps, writing ``out`` (collective).

    Args:
        scene: The validated scene (:func:`fem_anim.scene.joint_rules.check_joint` passed).
        out: The output directory.
        comm: The communicator.
        cli_options: PETSc options of the command line.
        quiet: No notes on stderr.
        provenance: Extra entries of ``summary.json`` (software versions).
        preset: A linear-solver preset replacing ``solver.preset`` (``--solver``).
        resume: Continue the unfinished run staged in ``out`` from its last checkpoint
            (:mod:`fem_anim.simulation.joint_checkpoint`).
        sim: The scene's simulation, built already (by the command line, under
            :class:`~fem_anim.simulation.interrupt.stop_at_once`); None: built here.

    Returns:
        The stats rows and the energy report.

    Raises:
        ConvergenceError: a step did not converge (the directory keeps its previous
            results; the staged frames so far and the last checkpoint stay in
            ``out/.partial``, for ``--resume``).
        Interrupted: after SIGINT, SIGTERM or SIGHUP, at the end of a frame, once its
            checkpoint is written (a second signal: at once;
            :mod:`fem_anim.simulation.interrupt`).
        FemAnimError: an output file cannot be written, or a checkpoint to resume from is
            missing, unreadable or of another scene (naming the physics keys that changed).
    """
    if sim is None:
        sim = JointSimulation.from_scene(scene, comm, cli_options, preset)
    gathers = [(VertexGather(d, p.V), CellGather(d)) for d, p in zip(sim.domains, sim.parts)]

    def fields(states):
        return [(vg.gather(s.u), cg.gather(p.cell_energy_density(s.u)))
                for (vg, cg), p, s in zip(gathers, sim.parts, states)]

    surface = None  # the seen surface (rank 0; TrajectoryWriter reads these three names)
    if comm.rank == 0:
        X, tris, parents = surface_of_parts([d.points for d in sim.domains],
                                            [d.cells for d in sim.domains])
        surface = SimpleNamespace(points=X, cells=tris, mesh=SimpleNamespace(comm=comm))
    else:
        surface = SimpleNamespace(points=None, cells=None, mesh=SimpleNamespace(comm=comm))

    def seen(parts):
        """The seen surface's displacement and triangle energy densities (rank 0)."""
        if comm.rank != 0:
            return None, None
        return (np.concatenate([u for u, _ in parts]),
                np.concatenate([e[k] for (_, e), k in zip(parts, parents)]))

    with stop_at_once():  # nothing to keep yet
        states = sim.initial_state()
        initial = sim.energies(states)
        initial["roundoff"] = sum(roundoff_energy(s, d)
                                  for s, d in zip(sim.scenes, sim.domains))
    run_dir = RunDirectory(Path(out), comm, resume)
    try:  # nothing is deleted on failure: the staging area is what --resume continues
        with Interrupts(comm) as interrupts:
            try:
                states, rows, writers = _frames(sim, scene, run_dir, states, fields, seen,
                                                surface, quiet, resume, interrupts)
                finals = fields(states)
                _io(comm, writers[-1].h5_path, writers[-1].finish)
                for name, writer, d, (u, e) in zip(PART_FILES, writers, sim.domains, finals):
                    _io(comm, writer.h5_path, writer.finish)
                    path = run_dir.file(f"final_{name}.vtu")
                    _io(comm, path, write_final, path, d, u, e)
                _io(comm, run_dir.file("scene.json"), write_scene, run_dir.file("scene.json"),
                    scene, comm)
                report = energy_report(rows, initial, scene)
                path = run_dir.file("summary.json")

                def summary() -> None:
                    if comm.rank == 0:
                        write_summary(path, scene, rows, report,
                                      (provenance or {}) | {"petsc_options": sim.options})

                _io(comm, path, summary)
                if scene["output"]["usd"]:  # installed with the run's other files
                    _io(comm, run_dir.file(usd_file_name(scene.name)), export_staged_run,
                        run_dir.staging, scene.name, comm, int(scene["output"]["start_frame"]))
            except FemAnimError as err:
                if interrupts.received is None or isinstance(err, Interrupted):
                    raise
                name = signal.Signals(interrupts.received).name  # a 2nd signal inside PETSc
                raise Interrupted(f"interrupted by {name} (twice)",
                                  interrupts.received) from None
        run_dir.commit()
    finally:
        run_dir.close()
    if scene["output"]["render"]:
        _render(comm, Path(out), scene["render"], quiet)
    return rows, report


def _frames(sim, scene: Scene, run_dir: RunDirectory, states, fields, seen, surface,
            quiet: bool, resume: bool, interrupts: Interrupts):
    """The frames of :func:`run_joint` with their files: stats rows, the three
    trajectories' frames every ``output.every`` frames, a checkpoint every
    ``output.checkpoint_every`` frames and at a signal (collective).

    Returns:
        The parts' final states, the stats rows and the trajectory writers (solids, shell,
        seen surface).

    Raises:
        Interrupted: after a signal, at the end of a frame, once its checkpoint is written.
    """
    comm = sim.comm
    dt = float(scene["time"]["dt"])
    steps, every = int(scene["time"]["steps"]), int(scene["output"]["every"])
    checkpoint_every = scene["output"]["checkpoint_every"] or max(1, steps // 10)
    stepper = AdaptiveStepper(sim, dt, scene["time"])
    first, rows, kept, ck = 1, [], None, None
    if resume:  # before any file is opened: a refused resume changes nothing
        ck = load_joint_checkpoint(run_dir.file("checkpoint.npz"), sim, scene)
        first, rows, kept = ck.frame + 1, ck.rows, ck.frames_written
        restore_joint(sim, stepper, ck)
        state = ck.state
    else:
        state = JointState(states)
    writers = [_io(comm, run_dir.file(f"{name}.h5"), TrajectoryWriter,
                   run_dir.file(f"{name}.xdmf"), d, kept)
               for name, d in zip(PART_FILES + ("trajectory",), sim.domains + [surface])]
    stats_file = _io(comm, run_dir.file("stats.csv"), StatsWriter,
                     run_dir.file("stats.csv"), comm, rows)

    def checkpoint(frame: int) -> None:
        path = run_dir.file("checkpoint.npz")
        _io(comm, path, save_joint_checkpoint, path, sim, scene, state, frame,
            len(writers[0].times) if writers[0].rank0 else 0, rows,
            {"dt": stepper.dt, "last_dt": stepper.last_dt})

    if ck is not None and comm.rank == 0:
        line = describe_resume(ck, solver_view(sim, scene), run_dir.path)
        if not quiet or "with changed solver settings" in line:
            print(f"fem-anim: {line}", file=sys.stderr)
    try:
        if not resume:
            parts = fields(state.parts)
            for writer, (u, e) in zip(writers, parts + [seen(parts)]):
                _io(comm, writer.h5_path, writer.write, 0.0, u, e)
        for frame in range(first, steps + 1):
            for state, row in stepper.advance(state, frame * dt):
                rows.append(row)
                _io(comm, stats_file.path, stats_file.write, row)
            if frame % every == 0 or frame == steps:
                parts = fields(state.parts)
                for writer, (u, e) in zip(writers, parts + [seen(parts)]):
                    _io(comm, writer.h5_path, writer.write, frame * dt, u, e)
            saved = frame % checkpoint_every == 0 and frame < steps
            if saved:
                checkpoint(frame)
            signum = interrupts.pending() if frame < steps else None
            if signum:
                if not saved:
                    checkpoint(frame)
                raise Interrupted(f"interrupted by {signal.Signals(signum).name} at frame "
                                  f"{frame} of {steps} (t = {state.time:.6g} s)", signum)
    finally:
        stats_file.close()
    return state.parts, rows, writers


def _render(comm: MPI.Comm, path: Path, settings: dict, quiet: bool) -> None:
    """The run's pictures from ``trajectory.xdmf`` (rank 0, in the render process; errors
    collective). A failed rendering keeps the run's data."""
    error = None
    if comm.rank == 0:
        from fem_anim.render.process import render_run

        try:
            render_run(path, settings, quiet=quiet)
        except (FemAnimError, RuntimeError) as err:
            error = f"{err} (the run's data are kept in {path}: render them again with " \
                    f"`fem-anim render {path}`)"
    error = comm.bcast(error, root=0)
    if error:
        raise FemAnimError(error)
