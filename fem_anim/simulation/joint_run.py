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
* ``stats.csv``: one row per substep (Newton and linear iterations, the energies of both
  bodies and the barrier, the contact pairs and smallest distance, wall times);
* ``scene.json`` (the scene as validated) and ``summary.json`` (steps, iterations, the
  energy report of :func:`~fem_anim.simulation.energy_report.energy_report` over both
  bodies, software versions, PETSc options).

Not done for such a run yet: checkpoints and ``--resume``, rendered
pictures and the USD export (both read one ``trajectory.xdmf``; ParaView reads the two
trajectories); the run says so in one line when ``output.render`` or ``output.usd`` is on.
"""

from __future__ import annotations

import sys
from pathlib import Path

from mpi4py import MPI

from fem_anim.errors import FemAnimError, describe_os_error
from fem_anim.output.files import (CellGather, RunDirectory, StatsWriter, VertexGather,
                                   write_final, write_scene)
from fem_anim.output.trajectory import TrajectoryWriter
from fem_anim.scene.loading import Scene
from fem_anim.simulation.energy_report import energy_report, roundoff_energy, write_summary
from fem_anim.simulation.adaptive import AdaptiveStepper
from fem_anim.simulation.joint_loop import JointSimulation, JointState

__all__ = ["PART_FILES", "run_joint"]

#: The file stem of each part's trajectory and final state, in the parts' order.
PART_FILES = ("solids", "shell")


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
              provenance: dict | None = None,
              preset: str | None = None) -> tuple[list[dict], dict]:
    """Run a scene with a shell body for ``time.steps`` steps, writing ``out`` (collective).

    Args:
        scene: The validated scene (:func:`fem_anim.scene.joint_rules.check_joint` passed).
        out: The output directory.
        comm: The communicator.
        cli_options: PETSc options of the command line.
        quiet: No notes on stderr.
        provenance: Extra entries of ``summary.json`` (software versions).
        preset: A linear-solver preset replacing ``solver.preset`` (``--solver``).

    Returns:
        The stats rows and the energy report.

    Raises:
        ConvergenceError: a step did not converge (the directory keeps its previous
            results; the staged frames so far stay in ``out/.partial``).
        FemAnimError: an output file cannot be written.
    """
    sim = JointSimulation.from_scene(scene, comm, cli_options, preset)
    dt = float(scene["time"]["dt"])
    steps, every = int(scene["time"]["steps"]), int(scene["output"]["every"])
    skipped = [key for key in ("render", "usd") if scene["output"][key]]
    if skipped and not quiet and comm.rank == 0:
        print(f"fem-anim: {' and '.join('output.' + k for k in skipped)}: not made for a "
              "shell with solids yet (ParaView reads solids.xdmf and shell.xdmf)",
              file=sys.stderr)
    gathers = [(VertexGather(d, p.V), CellGather(d)) for d, p in zip(sim.domains, sim.parts)]

    def fields(states):
        return [(vg.gather(s.u), cg.gather(p.cell_energy_density(s.u)))
                for (vg, cg), p, s in zip(gathers, sim.parts, states)]

    states = sim.initial_state()
    initial = sim.energies(states)
    initial["roundoff"] = sum(roundoff_energy(s, d) for s, d in zip(sim.scenes, sim.domains))
    run_dir = RunDirectory(Path(out), comm)
    rows: list[dict] = []
    try:
        writers = [_io(comm, run_dir.file(f"{name}.h5"), TrajectoryWriter,
                       run_dir.file(f"{name}.xdmf"), d)
                   for name, d in zip(PART_FILES, sim.domains)]
        stats_file = _io(comm, run_dir.file("stats.csv"), StatsWriter,
                         run_dir.file("stats.csv"), comm)
        try:
            for writer, (u, e) in zip(writers, fields(states)):
                _io(comm, writer.h5_path, writer.write, 0.0, u, e)
            stepper = AdaptiveStepper(sim, dt, scene["time"])
            state = JointState(states)
            for frame in range(1, steps + 1):
                for state, row in stepper.advance(state, frame * dt):
                    rows.append(row)
                    _io(comm, stats_file.path, stats_file.write, row)
                if frame % every == 0 or frame == steps:
                    for writer, (u, e) in zip(writers, fields(state.parts)):
                        _io(comm, writer.h5_path, writer.write, frame * dt, u, e)
            states = state.parts
        finally:
            stats_file.close()
        finals = fields(states)
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
        run_dir.commit()
    finally:
        run_dir.close()
    return rows, report
