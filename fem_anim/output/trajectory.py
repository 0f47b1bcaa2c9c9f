"""``trajectory.xdmf`` + ``trajectory.h5``: displacement and energy density per frame.

The finished file has meshio's layout (``data0`` points, ``data1`` cells, ``data{k+2}``
frame k's vertex displacements, ``energy_density{k}`` its cells' mean psi, attribute
``times``), so meshio's TimeSeriesReader and ParaView read it, plus ``body``, each cell's body
number (0-based, in ``[[body]]`` order), given to every frame as cell data ``body``.

``output.fields`` adds every dof of a field, not only its vertex values
(:class:`~fem_anim.output.dof_gather.DofGather`'s rank-independent rows):
``{name}_dofs{k}`` (frame k) with ``{name}_nodes`` (the input vertex pair ``(i, j)`` of each
row: a vertex when ``i == j``, else the midpoint of edge ``(i, j)``), for ``velocity``,
``pressure`` (a mixed run) and, for a P2 body, ``displacement`` (its edge dofs; seed
section 4.2). With them a step's discrete equations (seed eq. 4) can be re-assembled from
the file. They are HDF5 datasets only: XDMF has no P2 field on the P1 mesh.

While the run is in progress every file is written whole or not at all, so a kill at any
moment (SIGKILL included, in the middle of a frame) leaves a trajectory a resumed run can
continue:

* ``trajectory.h5`` holds the mesh and its cells' ``body`` only (written once, atomically);
* each frame k is its own small HDF5 file ``trajectory.frames/frame{k:06d}.h5``
  (``displacement``, ``energy_density``, ``{name}_dofs`` of ``output.fields``, attribute
  ``time``), built in memory and written atomically (temp file, fsync, rename);
* ``trajectory.xdmf`` is rewritten atomically after each frame and lists the complete
  frames, reading each from its file.

:meth:`TrajectoryWriter.finish` merges the frames into ``trajectory.h5`` (a temp file
renamed over the mesh file) and points the XDMF file at it. A resumed run keeps the first
``keep_frames`` frames (the checkpoint's count) and drops everything after them; a frame
missing from the frame folder is taken from a merged ``trajectory.h5`` (a kill between the
merge and the end of the run). Only rank 0 touches the files.
"""

from __future__ import annotations

import io
import os
import shutil
from pathlib import Path

import numpy as np

from fem_anim.mesh.simplex import SimplexMesh
from fem_anim.output.files import _pad3, body_numbers
from fem_anim.output.rundir import write_atomically

__all__ = ["TrajectoryWriter", "FRAMES_FOLDER"]

#: The staged frames' folder beside ``trajectory.xdmf`` (``trajectory.frames``).
FRAMES_FOLDER = "{stem}.frames"


def _h5_image(datasets: dict[str, np.ndarray], attrs: dict) -> bytes:
    """The bytes of an HDF5 file holding ``datasets`` and root ``attrs``."""
    import h5py

    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        for name, data in datasets.items():
            f.create_dataset(name, data=data)
        for name, value in attrs.items():
            f.attrs[name] = value
    return buffer.getvalue()


class TrajectoryWriter:
    """Writes a run's trajectory frame by frame (rank 0; module docstring for the files).

    Args:
        path: The ``.xdmf`` file; ``.h5`` and the frame folder sit beside it.
        domain: The mesh (its input points and cells are written once).
        keep_frames: None for a new trajectory; for a resumed run, the number of frames
            to keep (later ones are dropped).
        nodes: (rank 0) For each field written at all its dofs (``output.fields``), the
            ``(i, j)`` input vertex pairs of its rows (:attr:`DofGather.nodes
            <fem_anim.output.dof_gather.DofGather>`).

    Raises:
        OSError: (rank 0) naming the file, if a resumed trajectory's ``.h5`` cannot be
            read or it holds fewer than ``keep_frames`` frames.
    """

    CELL_TYPES = {3: ("triangle", "Triangle"), 4: ("tetra", "Tetrahedron")}

    def __init__(self, path: Path, domain: SimplexMesh, keep_frames: int | None = None,
                 nodes: dict[str, np.ndarray] | None = None):
        self.rank0 = domain.mesh.comm.rank == 0
        self.nodes = dict(nodes or {})
        self.path = Path(path)
        self.h5_path = self.path.with_suffix(".h5")
        self.frames = self.path.with_name(FRAMES_FOLDER.format(stem=self.path.stem))
        self.times: list[float] = []
        if not self.rank0:
            return
        self.points = _pad3(domain.points)
        self.cells = domain.cells
        if keep_frames is None:
            if self.frames.exists():
                shutil.rmtree(self.frames)  # a failed start's frames (the staging area's)
            self.frames.mkdir()
            self._write_mesh()
        else:
            self._continue(keep_frames)
        self._sync()

    def _write_mesh(self) -> None:
        write_atomically(self.h5_path, _h5_image(
            {"data0": self.points, "data1": self.cells, "body": body_numbers(self.cells)}
            | {f"{name}_nodes": n for name, n in self.nodes.items()}, {}))

    def frame_file(self, k: int) -> Path:
        """The staged file of frame ``k`` (0-based)."""
        return self.frames / f"frame{k:06d}.h5"

    def _continue(self, keep: int) -> None:
        """Keep frames 0..keep-1 of a staged trajectory, drop the rest (resume)."""
        import h5py

        try:
            with h5py.File(self.h5_path, "r") as h5:
                self.frames.mkdir(exist_ok=True)
                merged = np.asarray(h5.attrs.get("times", np.zeros(0)))
                for k in range(keep):
                    if not self.frame_file(k).is_file() and k < merged.size \
                            and f"data{k + 2}" in h5:  # merged before the kill
                        self._write_frame(k, float(merged[k]), h5[f"data{k + 2}"][()],
                                          h5[f"energy_density{k}"][()],
                                          {name: h5[f"{name}_dofs{k}"][()]
                                           for name in self.nodes
                                           if f"{name}_dofs{k}" in h5})
        except (OSError, KeyError) as err:  # h5py reports damage as OSError / KeyError
            raise OSError(getattr(err, "errno", 0) or 0, f"cannot be read ({err}); the run "
                          "cannot be continued from it", str(self.h5_path)) from None
        for k in range(keep):
            try:
                with h5py.File(self.frame_file(k), "r") as f:
                    self.times.append(float(f.attrs["time"]))
                    missing = [name for name in self.nodes if f"{name}_dofs" not in f]
            except (OSError, KeyError) as err:
                raise OSError(getattr(err, "errno", 0) or 0,
                              f"holds {k} readable frames where the checkpoint expects {keep} "
                              f"({err}; the run cannot be continued from it)",
                              str(self.frame_file(k))) from None
            if missing:  # a run begun with other output.fields
                raise OSError(0, f"has no {', '.join(missing)} field, which output.fields "
                              "lists now: continue with the output.fields the run began "
                              "with", str(self.frame_file(k)))
        # every kept frame is in its own file now: the mesh file is free (and gets the cells'
        # body and the fields' nodes if a run begun before they were written lacks them)
        self._write_mesh()
        for stale in self.frames.iterdir():  # frames after the checkpoint, cut-short writes
            if stale.name.startswith(".") or stale.name > self.frame_file(keep - 1).name:
                stale.unlink()

    def _write_frame(self, k: int, time: float, displacement: np.ndarray,
                     energy_density: np.ndarray, dofs: dict[str, np.ndarray]) -> None:
        write_atomically(self.frame_file(k), _h5_image(
            {"displacement": _pad3(displacement), "energy_density": energy_density}
            | {f"{name}_dofs": values for name, values in dofs.items()},
            {"time": time}))

    def write(self, time: float, displacement: np.ndarray | None,
              energy_density: np.ndarray | None,
              dofs: dict[str, np.ndarray] | None = None) -> None:
        """Append a frame (rank 0 writes; other ranks pass None).

        Args:
            time: The frame's time (s).
            displacement: Vertex displacements (num_points, gdim) in input order.
            energy_density: Each cell's mean energy density (num_cells,) in input order.
            dofs: Every dof of each field of ``nodes`` (rows in its nodes' order).

        Raises:
            ValueError: ``dofs`` does not hold exactly the fields of ``nodes``.
        """
        if not self.rank0:
            return
        dofs = dict(dofs or {})
        if set(dofs) != set(self.nodes):
            raise ValueError(f"frame fields {sorted(dofs)} are not the trajectory's "
                             f"{sorted(self.nodes)}")
        self._write_frame(len(self.times), time, displacement, energy_density, dofs)
        self.times.append(time)
        self._sync()

    def finish(self) -> None:
        """Merge the frames into ``trajectory.h5`` (meshio's layout) and drop the folder.

        The merged file is written beside it and renamed over the mesh file, then the XDMF
        file is pointed at it: a kill at any point leaves a trajectory :class:`TrajectoryWriter`
        continues.
        """
        if not self.rank0:
            return
        import h5py

        tmp = self.h5_path.with_name(f".{self.h5_path.name}.tmp")
        try:
            with h5py.File(tmp, "w") as out:
                out.create_dataset("data0", data=self.points)
                out.create_dataset("data1", data=self.cells)
                out.create_dataset("body", data=body_numbers(self.cells))
                for name, nodes in self.nodes.items():
                    out.create_dataset(f"{name}_nodes", data=nodes)
                for k in range(len(self.times)):
                    with h5py.File(self.frame_file(k), "r") as f:
                        out.create_dataset(f"energy_density{k}", data=f["energy_density"][()])
                        out.create_dataset(f"data{k + 2}", data=f["displacement"][()])
                        for name in self.nodes:
                            out.create_dataset(f"{name}_dofs{k}", data=f[f"{name}_dofs"][()])
                out.attrs["times"] = np.asarray(self.times)
            with open(tmp, "rb") as f:
                os.fsync(f.fileno())
            os.replace(tmp, self.h5_path)
        except OSError as err:
            tmp.unlink(missing_ok=True)
            raise OSError(err.errno, err.strerror or str(err), str(self.h5_path)) from None
        write_atomically(self.path, self._xdmf(merged=True).encode())
        shutil.rmtree(self.frames)

    def _sync(self) -> None:
        write_atomically(self.path, self._xdmf(merged=False).encode())

    def _xdmf(self, merged: bool) -> str:
        h5 = self.h5_path.name
        n, m = self.points.shape[0], self.cells.shape[0]

        def source(k: int, name: str) -> str:
            if merged:
                return f"{h5}:/{'data' + str(k + 2) if name == 'displacement' else name + str(k)}"
            return f"{self.frames.name}/{self.frame_file(k).name}:/{name}"

        topology = self.CELL_TYPES[self.cells.shape[1]][1]
        mesh = ('xpointer(//Grid[@Name=&quot;mesh&quot;]/*[self::Topology or '
                'self::Geometry])')
        frames = "".join(
            f'<Grid><xi:include xpointer="{mesh}" /><Time Value="{t!r}" />'
            f'<Attribute Name="displacement" AttributeType="Vector" Center="Node">'
            f'<DataItem DataType="Float" Dimensions="{n} 3" Format="HDF" Precision="8">'
            f"{source(k, 'displacement')}</DataItem></Attribute>"
            f'<Attribute Name="energy_density" AttributeType="Scalar" Center="Cell">'
            f'<DataItem DataType="Float" Dimensions="{m}" Format="HDF" Precision="8">'
            f"{source(k, 'energy_density')}</DataItem></Attribute>"
            f'<Attribute Name="body" AttributeType="Scalar" Center="Cell">'
            f'<DataItem DataType="Int" Dimensions="{m}" Format="HDF" Precision="8">'
            f"{h5}:/body</DataItem></Attribute></Grid>"
            for k, t in enumerate(self.times))
        return (
            '<Xdmf xmlns:xi="http://www.w3.org/2003/XInclude" Version="3.0"><Domain>'
            '<Grid Name="TimeSeries_fem_anim" GridType="Collection" CollectionType="Temporal">'
            f'{frames}</Grid><Grid Name="mesh" GridType="Uniform"><Geometry GeometryType="XYZ">'
            f'<DataItem DataType="Float" Dimensions="{n} 3" Format="HDF" Precision="8">'
            f'{h5}:/data0</DataItem></Geometry><Topology TopologyType="{topology}" '
            f'NumberOfElements="{m}"><DataItem DataType="Int" Dimensions="{m} '
            f'{self.cells.shape[1]}" Format="HDF" Precision="8">{h5}:/data1</DataItem>'
            "</Topology></Grid></Domain></Xdmf>\n")
