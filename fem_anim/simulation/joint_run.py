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
writes from a finished run too. Not done for such a run yet: checkpoints and ``--resume``.
"""

from __future__ import annotations

from pathlib import Path

from types import SimpleNamespace

import numpy as np
from mpi4py import MPI

from fem_anim.errors import FemAnimError, describe_os_error
from fem_anim.export.usd_stage import export_staged_run, usd_file_name
from fem_anim.output.files import (CellGather, RunDirectory, StatsWriter, VertexGather,
                                   write_final, write_scene)
from fem_anim.output.trajectory import TrajectoryWriter
from fem_anim.scene.loading import Scene
from fem_anim.simulation.energy_report import energy_report, roundoff_energy, write_summary
from fem_anim.simulation.adaptive import AdaptiveStepper
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

    states = sim.initial_state()
    initial = sim.energies(states)
    initial["roundoff"] = sum(roundoff_energy(s, d) for s, d in zip(sim.scenes, sim.domains))
    run_dir = RunDirectory(Path(out), comm)
    rows: list[dict] = []
    try:
        writers = [_io(comm, run_dir.file(f"{name}.h5"), TrajectoryWriter,
                       run_dir.file(f"{name}.xdmf"), d)
                   for name, d in zip(PART_FILES + ("trajectory",),
                                      sim.domains + [surface])]
        stats_file = _io(comm, run_dir.file("stats.csv"), StatsWriter,
                         run_dir.file("stats.csv"), comm)
        try:
            parts = fields(states)
            for writer, (u, e) in zip(writers, parts + [seen(parts)]):
                _io(comm, writer.h5_path, writer.write, 0.0, u, e)
            stepper = AdaptiveStepper(sim, dt, scene["time"])
            state = JointState(states)
            for frame in range(1, steps + 1):
                for state, row in stepper.advance(state, frame * dt):
                    rows.append(row)
                    _io(comm, stats_file.path, stats_file.write, row)
                if frame % every == 0 or frame == steps:
                    parts = fields(state.parts)
                    for writer, (u, e) in zip(writers, parts + [seen(parts)]):
                        _io(comm, writer.h5_path, writer.write, frame * dt, u, e)
            states = state.parts
        finally:
            stats_file.close()
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
        run_dir.commit()
    finally:
        run_dir.close()
    if scene["output"]["render"]:
        _render(comm, Path(out), scene["render"], quiet)
    return rows, report


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
