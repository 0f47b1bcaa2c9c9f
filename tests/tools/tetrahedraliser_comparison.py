"""fTetWild (pytetwild) against TetGen after MeshFix (tetgen + pymeshfix) on broken surfaces.

Regenerates the table of ``docs/artist_meshes.md``::

    .venv/bin/pip install tetgen pymeshfix      # not fem_anim dependencies (AGPL, GPL)
    .venv/bin/python tests/tools/tetrahedraliser_comparison.py

Each surface is meshed with a target edge of 0.03 m (fTetWild: ``edge_length_abs``, one
thread; TetGen: ``maxvolume`` of the regular tetrahedron of that edge); the table gives the
wall time, the tetrahedra, the volume against the closed solid's, and the radius ratio
3 r_in / r_circ (1: regular) of the worst tetrahedron and on average.
"""

from __future__ import annotations

import os
import tempfile
import time

import numpy as np
import trimesh


def volumes(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    a, b, c, d = (p[t[:, i]] for i in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def radius_ratio(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    a, b, c, d = (p[t[:, i]] for i in range(4))
    V = np.abs(volumes(p, t))

    def area(x, y, z):
        return 0.5 * np.linalg.norm(np.cross(y - x, z - x), axis=1)

    r_in = 3 * V / (area(a, b, c) + area(a, b, d) + area(a, c, d) + area(b, c, d))
    A = np.stack([b - a, c - a, d - a], axis=1)
    rhs = 0.5 * np.stack([np.sum((x - a) ** 2, axis=1) for x in (b, c, d)], axis=1)
    r_circ = np.linalg.norm(np.linalg.solve(A, rhs[..., None])[..., 0], axis=1)
    return 3 * r_in / r_circ


def surfaces():
    """(name, points, triangles, volume of the closed solid)."""
    s = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    yield "sphere, 4 triangles removed", s.vertices, np.delete(s.faces, [0, 1, 2, 40], 0), \
        s.volume
    b = trimesh.creation.box(extents=[0.2, 0.1, 0.1]).subdivide().subdivide()
    yield "box, 4 faces duplicated", b.vertices, \
        np.vstack([b.faces, b.faces[:3], b.faces[5:6, ::-1]]), 0.002
    b1 = trimesh.creation.box(extents=[0.2, 0.1, 0.1])
    b2 = trimesh.creation.box(extents=[0.1, 0.1, 0.2])
    b2.apply_translation([0.05, 0.03, 0.02])
    yield "two overlapping boxes", np.vstack([b1.vertices, b2.vertices]), \
        np.vstack([b1.faces, b2.faces + 8]), 0.004 - 0.1 * 0.07 * 0.1
    s1 = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    s2 = s1.copy()
    s2.apply_translation([0.08, 0, 0])
    lens = np.pi * (4 * 0.1 + 0.08) * (0.2 - 0.08) ** 2 / 12 * s1.volume / (4 / 3 * np.pi * 1e-3)
    yield "two overlapping spheres", np.vstack([s1.vertices, s2.vertices]), \
        np.vstack([s1.faces, s2.faces + len(s1.vertices)]), 2 * s1.volume - lens


def main() -> None:
    import pymeshfix
    import pytetwild
    import tetgen

    os.chdir(tempfile.mkdtemp(prefix="tetrahedraliser_"))  # fTetWild writes a file here
    edge = 0.03
    print("| surface | mesher | time (s) | tetrahedra | volume / closed "
          "| worst, mean radius ratio |")
    print("|---|---|---|---|---|---|")
    for name, v, f, reference in surfaces():
        v, f = np.asarray(v, float), np.asarray(f, np.int32)
        start = time.perf_counter()
        p, t = pytetwild.tetrahedralize(v, f, edge_length_abs=edge, num_threads=1, quiet=True)
        rows = [("fTetWild", time.perf_counter() - start, p, t)]
        start = time.perf_counter()
        fix = pymeshfix.MeshFix(v, f)
        fix.repair()
        p, t = tetgen.TetGen(fix.points, fix.faces).tetrahedralize(
            order=1, mindihedral=10, minratio=1.5, maxvolume=edge**3 / (6 * np.sqrt(2)))[:2]
        rows.append(("MeshFix + TetGen", time.perf_counter() - start, p, t))
        for mesher, seconds, p, t in rows:
            q = radius_ratio(p, t)
            print(f"| {name} | {mesher} | {seconds:.2f} | {len(t)} | "
                  f"{abs(volumes(p, t).sum()) / reference:.4f} | {q.min():.2f}, {q.mean():.2f} |")


if __name__ == "__main__":
    main()
