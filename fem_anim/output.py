"""Run outputs: trajectory, per-step statistics and the final state (rank 0 writes).

Displacements are gathered to rank 0 in the input mesh's vertex order
(:class:`VertexGather`), so a run under ``mpirun -n N`` writes the same files as a serial
run. Everything is written into a staging directory ``OUTDIR/.partial`` and moved into
``OUTDIR`` only when the run succeeds (:class:`RunDirectory`): a failed run leaves no
file posing as a result.

Files: ``trajectory.xdmf`` + ``trajectory.h5`` (displacement per frame, ParaView and
meshio read it), ``stats.csv`` (one row per step), ``final.vtu`` (point data
``displacement``) and, from :mod:`fem_anim.render`, ``final.png``.
"""

from __future__ import annotations

import contextlib
import csv
import os
import shutil
from pathlib import Path

import numpy as np
from mpi4py import MPI

from . import compat
from .mesh import SimplexMesh

__all__ = ["VertexGather", "RunDirectory", "StatsWriter", "TrajectoryWriter", "write_final",
           "STATS_COLUMNS"]

STATS_COLUMNS = ["step", "time", "dt", "retries", "newton_its", "linear_its", "snes_reason",
                 "residual_norm", "newton_decrement", "shift", "kinetic", "elastic", "gravity",
                 "total_energy", "assembly_s", "factor_s", "linear_solve_s", "other_s",
                 "solve_wall_s", "step_wall_s"]


class VertexGather:
    """Collects a vector Function's vertex values on rank 0 in input vertex order."""

    def __init__(self, domain: SimplexMesh, V):
        mesh = domain.mesh
        self.comm: MPI.Comm = mesh.comm
        self.domain = domain
        tdim = mesh.topology.dim
        nodes = compat.geometry_dofmap(mesh)
        num_cells = nodes.shape[0]
        dofs = V.dofmap.list.array.reshape(num_cells, -1)[:, : tdim + 1]
        node_to_dof = np.empty(mesh.geometry.x.shape[0], dtype=np.int64)
        node_to_dof[nodes.ravel()] = dofs.ravel()
        self.node_to_dof = node_to_dof
        self.input_index = domain.input_index
        self.bs = V.dofmap.index_map_bs
        self.num_points = self.comm.bcast(domain.points.shape[0] if self.comm.rank == 0
                                          else None, root=0)

    def gather(self, values: np.ndarray) -> np.ndarray | None:
        """Vertex values (num_points, bs) on rank 0, ``None`` elsewhere."""
        local = values.reshape(-1, self.bs)[self.node_to_dof]
        parts = self.comm.gather((self.input_index, local), root=0)
        if self.comm.rank != 0:
            return None
        out = np.empty((self.num_points, self.bs))
        for index, part in parts:
            out[index] = part
        return out


def _pad3(a: np.ndarray) -> np.ndarray:
    """ParaView warps and glyphs want 3-vectors: pad 2D arrays with a zero column."""
    return a if a.shape[1] == 3 else np.hstack([a, np.zeros((a.shape[0], 3 - a.shape[1]))])


class RunDirectory:
    """The output directory with a staging area; only rank 0 touches the file system."""

    def __init__(self, path: Path, comm: MPI.Comm):
        self.path = Path(path)
        self.comm = comm
        self.staging = self.path / ".partial"
        if comm.rank == 0:
            if self.staging.exists():
                shutil.rmtree(self.staging)
            self.staging.mkdir(parents=True)

    def file(self, name: str) -> Path:
        """Where to write ``name`` while the run is in progress."""
        return self.staging / name

    def commit(self) -> None:
        """Move every staged file into place (each rename is atomic)."""
        if self.comm.rank == 0:
            for item in self.staging.iterdir():
                os.replace(item, self.path / item.name)
            self.staging.rmdir()
        self.comm.barrier()

    def abandon(self) -> None:
        """Remove the staging area (and the directory, if the run created nothing else)."""
        if self.comm.rank == 0 and self.staging.exists():
            shutil.rmtree(self.staging, ignore_errors=True)
            try:
                self.path.rmdir()
            except OSError:
                pass


class StatsWriter:
    """``stats.csv``: one row per completed step, flushed as it is written (rank 0)."""

    def __init__(self, path: Path, comm: MPI.Comm):
        self.rank0 = comm.rank == 0
        if self.rank0:
            self._file = open(path, "w", newline="")
            self._writer = csv.DictWriter(self._file, fieldnames=STATS_COLUMNS)
            self._writer.writeheader()

    def write(self, row: dict) -> None:
        if self.rank0:
            self._writer.writerow({k: row[k] for k in STATS_COLUMNS})
            self._file.flush()

    def close(self) -> None:
        if self.rank0:
            self._file.close()


class TrajectoryWriter:
    """``trajectory.xdmf`` + ``.h5``: the displacement at each written frame (rank 0)."""

    def __init__(self, path: Path, domain: SimplexMesh):
        self.rank0 = domain.mesh.comm.rank == 0
        if self.rank0:
            import meshio

            path = Path(path).resolve()
            self._writer = meshio.xdmf.TimeSeriesWriter(str(path))
            # meshio 5.3 opens the .h5 by bare file name, i.e. in the working directory.
            with contextlib.chdir(path.parent):
                self._writer.__enter__()
            cell_type = {2: "triangle", 3: "tetra"}[domain.points.shape[1]]
            self._writer.write_points_cells(_pad3(domain.points), [(cell_type, domain.cells)])

    def write(self, time: float, displacement: np.ndarray | None) -> None:
        if self.rank0:
            self._writer.write_data(time, point_data={"displacement": _pad3(displacement)})

    def close(self) -> None:
        if self.rank0:
            self._writer.__exit__(None, None, None)


def write_final(path: Path, domain: SimplexMesh, displacement: np.ndarray | None) -> None:
    """``final.vtu``: the input mesh with point data ``displacement`` (rank 0)."""
    if domain.mesh.comm.rank != 0:
        return
    import meshio

    cell_type = {2: "triangle", 3: "tetra"}[domain.points.shape[1]]
    meshio.write(path, meshio.Mesh(_pad3(domain.points), [(cell_type, domain.cells)],
                                   point_data={"displacement": _pad3(displacement)}))
