"""Run outputs: trajectory, per-step statistics and the final state (rank 0 writes).

Displacements are gathered to rank 0 in the input mesh's vertex order
(:class:`VertexGather`), so a run under ``mpirun -n N`` writes the same files as a serial
run. Everything is written into a staging directory ``OUTDIR/.partial`` and moved into
``OUTDIR`` only when the run succeeds (:class:`RunDirectory`): a failed run leaves no
file posing as a result, and keeps its staging area for ``--resume``.

Files: ``trajectory.xdmf`` + ``trajectory.h5`` (displacement and cell energy density
per frame and the cells' ``body`` number, ParaView and meshio read it; written by
:mod:`fem_anim.output.trajectory`), ``stats.csv`` (one row per step), ``final.vtu`` (point
data ``displacement``, cell data ``energy_density`` and ``body``), ``scene.json`` (the
validated scene) and, from :mod:`fem_anim.render.animation` and :mod:`fem_anim.render.plots`,
the pictures in :data:`RENDER_PRODUCTS`.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim import compat
from fem_anim.errors import FemAnimError, describe_os_error
from fem_anim.mesh.connectivity import cell_components
from fem_anim.mesh.simplex import SimplexMesh
from fem_anim.output.rundir import (RENDER_PRODUCTS, STAGING, claim, install, read_manifest,
                                    write_atomically)

__all__ = ["VertexGather", "CellGather", "RunDirectory", "StatsWriter", "write_final",
           "write_scene", "write_atomically", "STATS_COLUMNS", "RENDER_PRODUCTS", "body_numbers"]

STATS_COLUMNS = ["step", "time", "dt", "retries", "newton_its", "linear_its", "snes_reason",
                 "residual_norm", "initial_residual_norm", "newton_decrement", "shift",
                 "exact_its", "shift_its", "clamp_its", "abs_its", "kinetic", "elastic",
                 "gravity", "contact", "total_energy", "assembly_s", "factor_s",
                 "linear_solve_s", "other_s", "solve_wall_s", "step_wall_s", "contact_s",
                 "contact_pairs", "residual_ratio", "hessian_assemblies", "factorisations",
                 "barrier_stiffness", "dhat", "min_distance", "friction_lags", "handle_work",
                 "retry_wall_s", "inertia_checks", "inertia_fallbacks"]


class VertexGather:
    """Collects a vector Function's vertex values on rank 0 in input vertex order.

    Args:
        domain: The mesh with its input points and each local vertex's input index.
        V: The P1 (vector or scalar) function space the values live in.
    """

    def __init__(self, domain: SimplexMesh, V):
        mesh = domain.mesh
        self.comm: MPI.Comm = mesh.comm
        self.domain = domain
        tdim = mesh.topology.dim
        nodes = compat.geometry_dofmap(mesh)
        num_cells = nodes.shape[0]
        dofs = compat.cell_dofs(V)[:num_cells, : tdim + 1]
        node_to_dof = np.empty(mesh.geometry.x.shape[0], dtype=np.int64)
        node_to_dof[nodes.ravel()] = dofs.ravel()
        self.node_to_dof = node_to_dof
        self.input_index = domain.input_index
        self.bs = V.dofmap.index_map_bs
        self.num_points = self.comm.bcast(domain.points.shape[0] if self.comm.rank == 0
                                          else None, root=0)

    def gather(self, values: np.ndarray) -> np.ndarray | None:
        """Gather the vertex values of a local dof array (collective).

        Args:
            values: The Function's local dof array (owned and ghost entries).

        Returns:
            The values (num_points, bs) in input vertex order on rank 0; None elsewhere.
        """
        local = values.reshape(-1, self.bs)[self.node_to_dof]
        parts = self.comm.gather((self.input_index, local), root=0)
        if self.comm.rank != 0:
            return None
        out = np.empty((self.num_points, self.bs))
        for index, part in parts:
            out[index] = part
        return out


class CellGather:
    """Collects per-cell values of the owned cells on rank 0 in input cell order.

    DOLFINx keeps each cell's row in the input array (``topology.original_cell_index``);
    the owned cells of all ranks together are the input cells, each once.

    Args:
        domain: The mesh with its input cells.
    """

    def __init__(self, domain: SimplexMesh):
        topology = domain.mesh.topology
        self.comm: MPI.Comm = domain.mesh.comm
        num_owned = topology.index_map(topology.dim).size_local
        self.input_index = np.asarray(topology.original_cell_index, np.int64)[:num_owned]
        self.num_cells = self.comm.bcast(domain.cells.shape[0] if self.comm.rank == 0
                                         else None, root=0)

    def gather(self, values: np.ndarray) -> np.ndarray | None:
        """Gather one value per owned cell (collective).

        Args:
            values: One value per owned cell, in local cell order.

        Returns:
            The values (num_cells,) in input cell order on rank 0; None elsewhere.
        """
        parts = self.comm.gather((self.input_index, values), root=0)
        if self.comm.rank != 0:
            return None
        out = np.empty(self.num_cells)
        for index, part in parts:
            out[index] = part
        return out


def _pad3(a: np.ndarray) -> np.ndarray:
    """ParaView warps and glyphs want 3-vectors: pad 2D arrays with a zero column."""
    return a if a.shape[1] == 3 else np.hstack([a, np.zeros((a.shape[0], 3 - a.shape[1]))])


class RunDirectory:
    """The output directory with a staging area; only rank 0 touches the file system.

    Claimed (marked and locked, :func:`fem_anim.output.rundir.claim`) at construction; the
    staging area ``OUTDIR/.partial`` receives every file while the run is in progress
    and is installed by :meth:`commit` only after success. Nothing ever deletes it on
    failure: its checkpoint and frames are what ``--resume`` continues. A fresh run
    refuses a directory whose staging area holds a checkpoint (an unfinished run that
    could be resumed); one without a checkpoint is only a failed start, and is replaced.
    Every decision is taken on rank 0 and raised on every rank.

    Args:
        path: The output directory (created if missing).
        comm: The run's communicator.
        resume: Continue the unfinished run staged there instead of starting afresh.

    Raises:
        FemAnimError: (collectively) if the directory is not fem_anim's, is in use, holds
            an unfinished run (fresh start) or none (``resume``), or cannot be written.
    """

    def __init__(self, path: Path, comm: MPI.Comm, resume: bool = False):
        self.path = Path(path)
        self.comm = comm
        self.staging = self.path / STAGING
        self._lock = None
        error = None
        if comm.rank == 0:
            try:
                self._lock = claim(self.path)
                self._prepare(resume)
            except FemAnimError as err:
                error = str(err)
            except OSError as err:
                error = f"output directory {self.path} cannot be written: " \
                        f"{describe_os_error(err, self.staging)}"
            if error and self._lock is not None:
                os.close(self._lock)
                self._lock = None
        error = comm.bcast(error, root=0)  # decided on rank 0, raised on every rank
        if error:
            raise FemAnimError(error)

    def _prepare(self, resume: bool) -> None:
        if resume:
            if not self.staging.is_dir():
                raise FemAnimError(f"nothing to resume in {self.path}: no unfinished run there")
            return
        if (self.staging / "checkpoint.npz").is_file():
            raise FemAnimError(f"{self.path} holds an unfinished run with a checkpoint: "
                               f"continue it with --resume {self.path}, or delete "
                               f"{self.staging} to start again")
        if self.staging.exists():
            shutil.rmtree(self.staging)  # a failed start: fem_anim's files only
        self.staging.mkdir()

    def file(self, name: str) -> Path:
        """Where to write a result file while the run is in progress.

        Args:
            name: The file's name in the output directory.

        Returns:
            Its path in the staging area.
        """
        return self.staging / name

    def commit(self) -> None:
        """Install the staged files (each rename atomic), collectively.

        Drops the checkpoint and the pictures of an older run
        (:func:`fem_anim.output.rundir.install`).

        Raises:
            FemAnimError: (collectively) if the files cannot be moved into place.
        """
        error = None
        if self.comm.rank == 0:
            try:
                (self.staging / "checkpoint.npz").unlink(missing_ok=True)
                for leftover in self.staging.glob(".*.tmp"):  # a write cut short
                    leftover.unlink()
                owned = read_manifest(self.path)
                old_pictures = {name for name in owned
                                if name.split("/")[0] in RENDER_PRODUCTS}
                install(self.staging, self.path, replaces=old_pictures)
            except OSError as err:
                error = f"the run's results cannot be moved into {self.path}: " \
                        f"{describe_os_error(err, self.staging)}"
        error = self.comm.bcast(error, root=0)
        if error:
            raise FemAnimError(error)

    def close(self) -> None:
        """Release the directory's lock (also released if the process dies)."""
        if self._lock is not None:
            os.close(self._lock)
            self._lock = None


class StatsWriter:
    """``stats.csv``: one row per completed step, flushed as it is written (rank 0).

    Args:
        path: The file to write (overwritten).
        comm: The run's communicator (only rank 0 writes).
        rows: Rows already written by a run being resumed, written first.
    """

    def __init__(self, path: Path, comm: MPI.Comm, rows: list[dict] = ()):
        self.rank0 = comm.rank == 0
        self.path = Path(path)
        if self.rank0:
            self._file = open(path, "w", newline="")
            self._writer = csv.DictWriter(self._file, fieldnames=STATS_COLUMNS)
            self._writer.writeheader()
            for row in rows:  # a resumed run: the rows up to its checkpoint
                self.write(row)

    def write(self, row: dict) -> None:
        """Append one row and flush it.

        Args:
            row: The step's statistics by :data:`STATS_COLUMNS` name (missing ones empty).
        """
        if self.rank0:
            # a checkpoint written before a column existed resumes with it empty
            self._writer.writerow({k: row.get(k, "") for k in STATS_COLUMNS})
            self._file.flush()

    def close(self) -> None:
        """Close the file; after a failed write (a full disk) its error was reported."""
        if self.rank0:
            try:
                self._file.close()
            except OSError:
                pass


def write_final(path: Path, domain: SimplexMesh, displacement: np.ndarray | None,
                energy_density: np.ndarray | None = None) -> None:
    """Write ``final.vtu``: the input mesh with the final state (rank 0 writes).

    Args:
        path: The file to write.
        domain: The mesh (input points and cells).
        displacement: Point data ``displacement`` (num_points, gdim), input order.
        energy_density: Cell data ``energy_density`` (num_cells,), if given.
    """
    if domain.mesh.comm.rank != 0:
        return
    import meshio

    cell_type = {3: "triangle", 4: "tetra"}[domain.cells.shape[1]]
    cell_data = {"body": [body_numbers(domain.cells)]}
    if energy_density is not None:
        cell_data["energy_density"] = [energy_density]
    meshio.write(path, meshio.Mesh(_pad3(domain.points), [(cell_type, domain.cells)],
                                   point_data={"displacement": _pad3(displacement)},
                                   cell_data=cell_data))


def body_numbers(cells: np.ndarray) -> np.ndarray:
    """The body number of each cell (cell data ``body``): the mesh's connected parts,
    numbered by first cell, which are a ``[[body]]`` scene's bodies in order (each body is
    one piece, and their cells are concatenated).

    Args:
        cells: The input cells.

    Returns:
        ``(num_cells,)`` int64, 0 for a one-body scene.
    """
    return cell_components(cells, int(cells.max()) + 1).astype(np.int64)


def write_scene(path: Path, scene, comm: MPI.Comm) -> None:
    """Write ``scene.json``: the validated scene of the run, for ``fem-anim render``.

    Args:
        path: The file to write (atomically, by rank 0).
        scene: The validated :class:`~fem_anim.scene.schema.Scene`.
        comm: The run's communicator.
    """
    if comm.rank == 0:
        write_atomically(path, (json.dumps({"source": scene.source, "scene": scene.data},
                                           indent=1) + "\n").encode())
