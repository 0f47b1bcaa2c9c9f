"""Running a scene from Python, and reading a finished run back.

:func:`run` does what ``fem-anim run`` does, without printing: it builds the
:class:`~fem_anim.simulation.loop.Simulation` of a scene, steps it ``time.steps`` frames (each
step the minimisation x_{n+1} = argmin 1/2 ||x - y||_M^2 + w E(x) of seed section 3.1),
writes the run directory (``trajectory.xdmf`` + ``.h5``, ``stats.csv``, ``final.vtu``,
``scene.json``, ``summary.json``, and the pictures when ``output.render``) and returns a
:class:`Run` that reads it. :func:`open_run` reads a run made earlier, by :func:`run` or by
the command line. A :class:`Run` holds no file open; it reads what is asked, when asked.
"""

from __future__ import annotations

import csv
import json
import shutil
import tempfile
import weakref
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from fem_anim.errors import ConvergenceError, FemAnimError, Interrupted
from fem_anim.output.rundir import STAGING, stopped_run_error

__all__ = ["Run", "run", "open_run", "RUN_FILES", "ENERGY_COLUMNS"]

#: What a finished run directory holds (besides ``trajectory.xdmf``, ``final.vtu`` and the
#: pictures): the frames, one statistics row per step, the summary.
RUN_FILES = ("trajectory.h5", "stats.csv", "summary.json")
#: :attr:`Run.energy`'s arrays -> the ``stats.csv`` column each comes from.
ENERGY_COLUMNS = {"time": "time", "kinetic": "kinetic", "elastic": "elastic",
                  "gravity": "gravity", "contact": "contact", "total": "total_energy"}


class Run:
    """A finished run, read from its directory.

    Made by :func:`run` or :func:`open_run`, not directly. Frames are the states written
    to the trajectory (every ``output.every``-th step and the last one; frame 0 is the rest
    state); statistics have one row per time step taken.

    Attributes:
        outdir: The run directory.

    Examples:
        >>> import fem_anim
        >>> scene = fem_anim.Scene.from_dict({
        ...     "mesh": {"dim": 2, "size": [1.0, 0.2], "divisions": [4, 1]},
        ...     "time": {"steps": 2}, "output": {"render": False},
        ...     "gravity": {"acceleration": [0.0, -9.81]},
        ...     "pin": [{"min": [-0.01, -1.0], "max": [0.01, 1.0]}]})
        >>> with fem_anim.run(scene) as result:
        ...     print(len(result.times), result.displacement(-1).shape, len(result.stats))
        ...     print(result.summary["steps"], result.energy["total"].shape)
        3 (10, 2) 2
        2 (2,)
    """

    def __init__(self, outdir: Path, owned: Path | None = None):
        self.outdir = Path(outdir)
        self._owned = owned
        self._cleanup = weakref.finalize(self, shutil.rmtree, owned, True) if owned else None

    def __repr__(self) -> str:
        return f"Run({str(self.outdir)!r})"

    def __enter__(self) -> Run:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        """Delete the run's directory if it is a temporary one of :func:`run`
        (``outdir=None``); a directory the caller named is kept. Also done when the
        :class:`Run` is garbage-collected."""
        if self._cleanup is not None:
            self._cleanup()

    @cached_property
    def summary(self) -> dict[str, Any]:
        """``summary.json``: steps, final time, iteration counts, the energy report
        (``summary["energy"]``: drift, excursion, flags) and provenance."""
        return json.loads((self.outdir / "summary.json").read_text())

    @cached_property
    def stats(self) -> list[dict[str, Any]]:
        """``stats.csv``, one dict per time step (columns as in
        :data:`fem_anim.output.files.STATS_COLUMNS`; an empty cell is ``None``)."""
        with open(self.outdir / "stats.csv", newline="") as f:
            return [{k: _number(v) for k, v in row.items()} for row in csv.DictReader(f)]

    @cached_property
    def energy(self) -> dict[str, np.ndarray]:
        """Energies per time step (J) and their times (s): ``time``, ``kinetic``,
        ``elastic``, ``gravity``, ``contact`` and their sum ``total``."""
        return {name: np.array([np.nan if row[column] is None else row[column]
                                for row in self.stats], dtype=float)
                for name, column in ENERGY_COLUMNS.items()}

    @cached_property
    def times(self) -> np.ndarray:
        """The time of each frame (s), frame 0 the initial state."""
        with self._h5() as h5:
            return np.asarray(h5.attrs["times"], dtype=float)

    @cached_property
    def points(self) -> np.ndarray:
        """The rest positions of the mesh vertices, ``(vertices, dim)`` (m)."""
        with self._h5() as h5:
            return np.asarray(h5["data0"])[:, :self.dim]

    @cached_property
    def cells(self) -> np.ndarray:
        """The cells (triangles or tetrahedra) as vertex numbers, ``(cells, dim + 1)``."""
        with self._h5() as h5:
            return np.asarray(h5["data1"])

    @cached_property
    def dim(self) -> int:
        """The space dimension, 2 or 3 (a shell's triangles lie in 3D: ``mesh.dim``)."""
        scene = json.loads((self.outdir / "scene.json").read_text())["scene"]
        return int(scene["mesh"]["dim"])

    def displacement(self, frame: int) -> np.ndarray:
        """The vertex displacements of one frame, ``(vertices, dim)`` (m); positions are
        ``points + displacement(frame)``.

        Args:
            frame: The frame number, ``0 .. len(times) - 1``; negative counts from the end.

        Raises:
            IndexError: for a frame the run does not have.
        """
        count = len(self.times)
        if not -count <= frame < count:
            raise IndexError(f"frame {frame} is not in this run (it has {count} frames)")
        with self._h5() as h5:
            return np.asarray(h5[f"data{frame % count + 2}"])[:, :self.dim]

    def _h5(self):
        import h5py

        return h5py.File(self.outdir / "trajectory.h5", "r")


def _number(text: str | None) -> int | float | None:
    """A ``stats.csv`` cell: an integer, a float, or ``None`` when empty."""
    if text is None or text == "":
        return None
    try:
        return int(text)
    except ValueError:
        return float(text)


def open_run(outdir: str | Path) -> Run:
    """Read back a finished run (by :func:`run` or ``fem-anim run``).

    Args:
        outdir: The run directory.

    Returns:
        The run; its files are read when an attribute asks for them.

    Raises:
        FemAnimError: when ``outdir`` is not a finished run, naming what is missing.

    Examples:
        >>> import fem_anim
        >>> fem_anim.open_run("no/such/run")
        Traceback (most recent call last):
        ...
        fem_anim.errors.FemAnimError: no/such/run is not a finished fem-anim run: it does \
not exist
    """
    path = Path(outdir)
    missing = [name for name in RUN_FILES if not (path / name).is_file()]
    if not path.exists():
        why = "it does not exist"
    elif not path.is_dir():
        why = "it is a file"
    elif not missing:
        return Run(path)
    elif (path / STAGING).is_dir():
        why = f"it is unfinished (its frames so far are in {path / STAGING})"
    else:
        why = f"no {', '.join(missing)} in it"
    raise FemAnimError(f"{path} is not a finished fem-anim run: {why}")


def run(scene, outdir: str | Path | None = None, quiet: bool = True,
        resume: bool = False) -> Run:
    """Simulate a scene, write its run directory and return the finished :class:`Run`.

    Collective under MPI (every rank calls it with the same scene). The FFCx JIT's build
    log is kept off the terminal (:func:`fem_anim.console.quiet_jit`). A scene with a shell
    ``[[body]]`` beside solids runs as ``fem-anim run`` runs it
    (:mod:`fem_anim.simulation.joint_run`); the :class:`Run` then reads its
    ``trajectory.h5``, the seen surface of both meshes.

    A run into ``outdir`` that stops with :class:`ConvergenceError` or :class:`Interrupted`
    keeps its frames and last checkpoint in ``outdir/.partial``, and the message says so and
    how to continue (``resume=True``); a temporary run directory (``outdir=None``) is
    deleted with what it held.

    Args:
        scene: A :class:`~fem_anim.scene.loading.Scene`.
        outdir: The run directory (created; an earlier run there is replaced). ``None``: a
            new temporary directory, deleted by :meth:`Run.close`, at the end of a
            ``with`` block, or when the :class:`Run` is garbage-collected.
        quiet: No progress bar.
        resume: Continue the run stopped in ``outdir`` from its last checkpoint, as
            ``fem-anim run SCENE --resume OUTDIR`` does (docs/resume.md): only
            ``[solver]``, ``[output]`` and ``[render]`` of ``scene`` may differ from the
            stopped run's.

    Returns:
        The finished run.

    Raises:
        TypeError: if ``scene`` is not a Scene.
        ConvergenceError: when a step does not converge even at ``time.min_dt``.
        Interrupted: after SIGINT, SIGTERM or SIGHUP, at the end of a frame.
        FemAnimError: for an output directory that cannot be written, ``resume`` without
            ``outdir`` or without a checkpoint there, and every other failure the command
            line reports.

    Examples:
        >>> import fem_anim
        >>> scene = fem_anim.Scene.from_toml('''
        ... [mesh]
        ... dim = 2
        ... size = [1.0, 0.2]
        ... divisions = [4, 1]
        ... [time]
        ... steps = 3
        ... [output]
        ... render = false
        ... [gravity]
        ... acceleration = [0.0, -9.81]
        ... [[pin]]
        ... min = [-0.01, -1.0]
        ... max = [0.01, 1.0]
        ... ''')
        >>> result = fem_anim.run(scene)
        >>> result.times.round(4).tolist()
        [0.0, 0.0167, 0.0333, 0.05]
        >>> tip = result.points[:, 0].argmax()
        >>> bool(result.displacement(-1)[tip, 1] < 0.0)  # gravity pulls the free end down
        True
        >>> result.close()
    """
    from mpi4py import MPI

    from fem_anim.scene.loading import Scene

    if not isinstance(scene, Scene):
        raise TypeError(f"fem_anim.run takes a fem_anim.Scene (Scene.load, from_toml, "
                        f"from_dict), got {type(scene).__name__}")
    comm = MPI.COMM_WORLD
    if resume and outdir is None:
        raise FemAnimError("fem_anim.run(..., resume=True) continues the run stopped in "
                           "outdir: give outdir")
    owned = None
    if outdir is None:
        owned = Path(tempfile.mkdtemp(prefix=f"fem_anim-{scene.name}-")) \
            if comm.rank == 0 else None
        owned = comm.bcast(owned, root=0)
        outdir = owned / "run"
    try:
        _run_into(scene, Path(outdir), comm, quiet, resume)
    except (ConvergenceError, Interrupted) as err:
        if owned is not None:
            comm.barrier()
            if comm.rank == 0:
                shutil.rmtree(owned, ignore_errors=True)
            raise
        continue_with = f"fem_anim.run(scene, {str(outdir)!r}, resume=True)"
        raise stopped_run_error(err, Path(outdir), continue_with,
                                " (e.g. with other [solver] settings)") from None
    except BaseException:
        if owned is not None and comm.rank == 0:
            shutil.rmtree(owned, ignore_errors=True)
        raise
    comm.barrier()
    return Run(Path(outdir), owned if comm.rank == 0 else None)


def _run_into(scene, outdir: Path, comm, quiet: bool, resume: bool) -> None:
    """Step ``scene`` and write its run directory ``outdir`` with its summary (collective)."""
    from fem_anim.console import quiet_jit
    from fem_anim.output.provenance import software_versions
    from fem_anim.output.rundir import read_manifest, write_manifest
    from fem_anim.scene.joint_rules import shell_body
    from fem_anim.simulation.energy_report import energy_report, initial_energies, write_summary
    from fem_anim.simulation.loop import Simulation

    if shell_body(scene.data) is not None:  # a shell beside solids: two meshes, one step
        from fem_anim.simulation.joint_run import run_joint

        with quiet_jit():
            run_joint(scene, outdir, comm, quiet=quiet,
                      provenance={"versions": software_versions(comm)}, resume=resume)
        return
    with quiet_jit():
        sim = Simulation(scene, comm)
        initial = initial_energies(sim)
        result = sim.run(outdir, quiet=quiet, resume=resume)
    report = energy_report(result.rows, initial, scene)
    if comm.rank == 0:
        write_summary(result.output_dir / "summary.json", scene, result.rows, report,
                      {"versions": software_versions(comm), "petsc_options": sim.options,
                       "wall": sim.clock.as_dict()})
        write_manifest(result.output_dir, read_manifest(result.output_dir) | {"summary.json"})
