"""A run as mesh sequences: one OBJ or PLY file per body per frame.

Each body's boundary surface (:mod:`fem_anim.export.boundary`, triangles wound
counter-clockwise seen from outside; a P2 body's refined through its edge dofs) is written
at every frame as
``<body>_<frame>.<obj|ply>``, the frame number ``start_frame + k`` zero-padded to at least
four digits (Blender's and Houdini's sequence importers count the files by that number).
The writers are plain numpy: OBJ as text (``o <body>``, ``v`` lines to nine significant
digits, float32's round trip, and 1-based ``f`` lines), PLY as binary little-endian
(double vertices, int32 indices); both are read back by meshio and by Blender's importers.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fem_anim.export.run_reader import RunData

__all__ = ["FORMATS", "write_obj", "write_ply", "sequence_files", "write_sequence"]

#: The mesh-sequence formats (file suffixes).
FORMATS = ("obj", "ply")


def write_obj(path: Path, name: str, points: np.ndarray, triangles: np.ndarray) -> None:
    """Write one triangle mesh as a Wavefront OBJ file.

    Args:
        path: The file to write.
        name: The object's name (its ``o`` line).
        points: Vertex positions ``(n, 3)``.
        triangles: Vertex numbers ``(f, 3)`` (0-based; written 1-based).
    """
    v = "\n".join("v " + " ".join(f"{c:.9g}" for c in row) for row in points.tolist())
    f = "\n".join(f"f {a} {b} {c}" for a, b, c in (triangles + 1).tolist())
    Path(path).write_text(f"o {name}\n{v}\n{f}\n")


def write_ply(path: Path, points: np.ndarray, triangles: np.ndarray) -> None:
    """Write one triangle mesh as a binary little-endian PLY file.

    Args:
        path: The file to write.
        points: Vertex positions ``(n, 3)`` (written as doubles).
        triangles: Vertex numbers ``(f, 3)`` (0-based).
    """
    header = ("ply\nformat binary_little_endian 1.0\n"
              f"element vertex {points.shape[0]}\n"
              "property double x\nproperty double y\nproperty double z\n"
              f"element face {triangles.shape[0]}\n"
              "property list uchar int vertex_indices\nend_header\n")
    faces = np.empty(triangles.shape[0], dtype=[("n", "u1"), ("v", "<i4", (3,))])
    faces["n"], faces["v"] = 3, triangles
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(np.ascontiguousarray(points, dtype="<f8").tobytes())
        f.write(faces.tobytes())


def sequence_files(run: RunData, names: list[str], fmt: str,
                   start_frame: int) -> list[list[str]]:
    """The file names of a sequence: ``[frame][body]``, ``<body>_<frame>.<fmt>``.

    Args:
        run: The run.
        names: The bodies' file-name stems.
        fmt: ``"obj"`` or ``"ply"``.
        start_frame: The number of frame 0.

    Returns:
        The names, frame numbers zero-padded to the width of the last (at least 4).
    """
    last = start_frame + len(run.times) - 1
    width = max(4, len(str(last)))
    return [[f"{name}_{start_frame + k:0{width}d}.{fmt}" for name in names]
            for k in range(len(run.times))]


def write_sequence(run: RunData, folder: Path, fmt: str, names: list[str],
                   start_frame: int = 1) -> list[str]:
    """Write every body at every frame into ``folder``.

    Args:
        run: The run.
        folder: An existing folder (files of the same names are replaced; the caller
            checks ownership).
        fmt: ``"obj"`` or ``"ply"``.
        names: The bodies' file-name stems (and OBJ object names).
        start_frame: The number of frame 0.

    Returns:
        The names of the files written.
    """
    surfaces, rest = run.surfaces(), run.surface_points()
    files = sequence_files(run, names, fmt, start_frame)
    for k, row in enumerate(files):
        x = rest + run.surface_displacement(k)
        for surface, name, file in zip(surfaces, names, row):
            if fmt == "obj":
                write_obj(folder / file, name, x[surface.vertices], surface.triangles)
            else:
                write_ply(folder / file, x[surface.vertices], surface.triangles)
    return [file for row in files for file in row]
