"""Cost of the independent check's enclosure test on frames of the demos' size.

Usage (from the tree's top): ``.venv/bin/python tests/tools/enclosure_cost.py``.

Prints, side by side in one run (ratios, not absolute times, are what a loaded machine
keeps), the seconds per frame of :func:`fem_anim.contact.intersection.enclosed_vertices`
and of the crossing test it is added to, on:

* demos/pile.toml's four bodies (their full meshes), as placed at rest (apart) and with
  every body moved to one centre (each vertex in every other body's bounding box: the
  prefilter's worst case), against ipctk's ``has_intersections``;
* demos/drape_soft.toml's sizes (a 0.24 x 0.24 x 0.16 m block at 0.04 m, a 0.6 m cloth at
  0.03 m, structured meshes), the cloth t above the block's top and through its middle,
  against :func:`~fem_anim.contact.intersection.crossing_pairs`.
"""

from __future__ import annotations

import time
from pathlib import Path

import ipctk
import numpy as np

from fem_anim.contact.intersection import (boundary_triangles, crossing_pairs,
                                           enclosed_vertices, surface_collision_mesh,
                                           surface_components)
from fem_anim.meshes.sheet import structured_sheet
from fem_anim.meshes.structured import structured_box

ROOT = Path(__file__).resolve().parents[2]


def seconds(f, repeat: int = 3) -> float:
    """The smallest wall time of ``repeat`` calls of f (s)."""
    best = np.inf
    for _ in range(repeat):
        start = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - start)
    return best


def pile() -> None:
    from fem_anim.scene import load_scene
    from fem_anim.simulation import Simulation

    sim = Simulation(load_scene(ROOT / "demos" / "pile.toml", ["output.render=false"]))
    points, cells = sim.domain.points, sim.domain.cells
    F = boundary_triangles(cells)
    components = surface_components(F)
    oriented, piece, closed = components
    mesh, used = surface_collision_mesh(points, cells)
    body = np.full(len(points), -1)
    body[oriented.ravel()] = np.repeat(piece, 3)
    centred = points.copy()
    for k in range(piece.max() + 1):
        centred[body == k] -= points[body == k].mean(axis=0)
    print(f"pile: {len(points)} vertices, {len(F)} boundary triangles, "
          f"{int(closed.sum())} closed pieces")
    for name, x in (("at rest", points), ("centred", centred)):
        enclosed = seconds(lambda: enclosed_vertices(x, F, components))
        ipc = seconds(lambda: ipctk.has_intersections(mesh, np.asfortranarray(x[used])))
        print(f"  {name}: enclosed_vertices {enclosed:.4f} s "
              f"({len(enclosed_vertices(x, F, components))} inside), "
              f"ipctk has_intersections {ipc:.4f} s, ratio {enclosed / ipc:.2f}")


def drape() -> None:
    cube_points, cube_cells = structured_box([0.24, 0.24, 0.16], [6, 6, 4],
                                             origin=[-0.12, -0.12, 0.0])
    sheet, tris = structured_sheet([0.6, 0.6], [20, 20], triangulation="right")
    sheet = np.c_[sheet[:, :2] - 0.3, np.zeros(len(sheet))]
    soup = np.concatenate([boundary_triangles(cube_cells), tris + len(cube_points)])
    components = surface_components(soup)
    print(f"drape: {len(cube_points) + len(sheet)} vertices, {len(soup)} triangles")
    for name, z in (("cloth t above the top", 0.16 + 1e-3), ("cloth through the middle", 0.08)):
        x = np.concatenate([cube_points, sheet + [0.0, 0.0, z]])
        enclosed = seconds(lambda: enclosed_vertices(x, soup, components))
        crossing = seconds(lambda: crossing_pairs(x, soup))
        print(f"  {name}: enclosed_vertices {enclosed:.4f} s "
              f"({len(enclosed_vertices(x, soup, components))} inside), "
              f"crossing_pairs {crossing:.4f} s, ratio {enclosed / crossing:.2f}")


if __name__ == "__main__":
    pile()
    drape()
