"""Off-screen rendering with pyvista: the deformed mesh coloured by displacement.

Without a display, VTK's EGL render window is selected (no X server needed).

Rendering runs in its own process (:func:`render_file`, ``python -m fem_anim.render``):
the VTK wheel's C++ runtime clashes with libraries DOLFINx loads (std::regex in VTK's
scalar bar aborts in a process that has imported dolfinx), and a separate process also
lets a saved run be re-rendered without simulating again.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

__all__ = ["render_frame", "render_file"]


def _pyvista():
    if not os.environ.get("DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
    import pyvista

    pyvista.OFF_SCREEN = True
    return pyvista


def render_frame(path: Path, points: np.ndarray, cells: np.ndarray, displacement: np.ndarray,
                 title: str = "", window_size: tuple[int, int] = (1024, 768)) -> None:
    """Render the mesh deformed by ``displacement`` to a PNG, coloured by |displacement|.

    Args:
        path: PNG file to write.
        points: Rest positions (n, 2 or 3).
        cells: Simplices (m, 3 or 4).
        displacement: Vertex displacements (n, 2 or 3).
        title: Text drawn in the top-left corner.
        window_size: Image size in pixels.
    """
    pv = _pyvista()
    d = points.shape[1]
    pad = np.zeros((points.shape[0], 3 - d))
    x = np.hstack([points + displacement[:, :d], pad])
    cell_type = pv.CellType.TETRA if cells.shape[1] == 4 else pv.CellType.TRIANGLE
    grid = pv.UnstructuredGrid(
        np.hstack([np.full((cells.shape[0], 1), cells.shape[1]), cells]).ravel(),
        np.full(cells.shape[0], cell_type, dtype=np.uint8), x)
    grid.point_data["|displacement| (m)"] = np.linalg.norm(displacement, axis=1)
    plotter = pv.Plotter(off_screen=True, window_size=list(window_size))
    plotter.add_mesh(grid, scalars="|displacement| (m)", show_edges=True, cmap="viridis")
    rest = pv.UnstructuredGrid(grid.cells, grid.celltypes, np.hstack([points, pad]))
    plotter.add_mesh(rest, style="wireframe", color="grey", opacity=0.25)
    if title:
        plotter.add_text(title, font_size=10)
    if d == 2:
        plotter.view_xy()
    else:
        plotter.view_vector((0.35, -1.0, 0.3), viewup=(0.0, 0.0, 1.0))  # side view, z up
    plotter.show_axes()
    plotter.screenshot(str(path))
    plotter.close()


def render_vtu(vtu: Path, png: Path, title: str = "") -> None:
    """Render a ``final.vtu``-style file (point data ``displacement``) to a PNG."""
    import meshio

    m = meshio.read(vtu)
    d = 3 if "tetra" in m.cells_dict else 2
    cells = m.cells_dict["tetra" if d == 3 else "triangle"]
    render_frame(png, m.points[:, :d], cells, m.point_data["displacement"][:, :d], title)


def render_file(vtu: Path, png: Path, title: str = "") -> None:
    """Render ``vtu`` to ``png`` in a fresh Python process (see the module docstring).

    Raises:
        RuntimeError: with the renderer's error output if it fails.
    """
    env = dict(os.environ)
    for key in [k for k in env if k.startswith(("OMPI_", "PMIX_", "PMI_"))]:
        del env[key]  # the renderer is not part of the MPI job
    proc = subprocess.run([sys.executable, "-m", "fem_anim.render", str(vtu), str(png),
                           "--title", title], capture_output=True, text=True, env=env)
    if proc.returncode != 0 or not Path(png).is_file():
        raise RuntimeError(f"rendering {vtu} failed: {proc.stderr.strip()[-2000:]}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m fem_anim.render")
    parser.add_argument("vtu")
    parser.add_argument("png")
    parser.add_argument("--title", default="")
    args = parser.parse_args(argv)
    render_vtu(Path(args.vtu), Path(args.png), args.title)
    return 0


if __name__ == "__main__":
    sys.exit(main())
