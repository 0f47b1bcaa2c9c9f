"""Write the small example meshes of this folder (run from anywhere; about a second).

    python meshes/data/make_examples.py

* ``cube.stl``: the closed surface of the cube ``[0, 0.2]^3`` m, 12 triangles (binary STL).
* ``icosphere.stl``: a twice-subdivided icosahedron of radius 0.1 m about the origin,
  320 triangles, outward oriented (binary STL).
* ``two_region_box.msh``: the box ``[0, 0.2] x [0, 0.1] x [0, 0.1]`` m in tetrahedra,
  physical volumes 1 (``x < 0.1``, ``left``) and 2 (``x > 0.1``, ``right``), gmsh 4.1 ASCII.
"""

from __future__ import annotations

from pathlib import Path

import gmsh
import meshio
import numpy as np

HERE = Path(__file__).resolve().parent


def cube_surface(edge: float) -> tuple[np.ndarray, np.ndarray]:
    """The 8 corners of ``[0, edge]^3`` and 12 outward-oriented triangles.

    Args:
        edge: The cube's edge length (m).
    """
    points = edge * np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    triangles = np.array([[a, b, c] for a, b, c, d in quads] + [[a, c, d] for a, b, c, d in quads])
    return points, triangles


def icosphere(radius: float, subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """Points and outward-oriented triangles of a subdivided icosahedron on a sphere.

    Args:
        radius: The sphere's radius (m), centred at the origin.
        subdivisions: How many times each triangle is split into four.
    """
    t = (1.0 + 5.0**0.5) / 2.0
    points = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                       [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]])
    triangles = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
                          [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
                          [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                          [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    for _ in range(subdivisions):  # split each triangle into four at its edge midpoints
        edges = np.sort(triangles[:, [[0, 1], [1, 2], [2, 0]]].reshape(-1, 2), axis=1)
        unique, inverse = np.unique(edges, axis=0, return_inverse=True)
        mid = points.shape[0] + inverse.reshape(-1, 3)  # midpoint of edges 01, 12, 20
        points = np.vstack([points, 0.5 * (points[unique[:, 0]] + points[unique[:, 1]])])
        a, b, c = triangles.T
        ab, bc, ca = mid.T
        triangles = np.concatenate([np.stack(v, axis=1) for v in
                                    ([a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca])])
    points = radius * points / np.linalg.norm(points, axis=1, keepdims=True)
    return points, triangles


def write_two_region_box(path: Path) -> None:
    """Mesh the two-region box with gmsh and write it (gmsh 4.1 ASCII).

    Args:
        path: The ``.msh`` file to write.
    """
    gmsh.initialize()
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.option.setNumber("General.NumThreads", 1)
        gmsh.option.setNumber("Mesh.MshFileVersion", 4.1)
        gmsh.model.add("two_region_box")
        left = gmsh.model.occ.addBox(0.0, 0.0, 0.0, 0.1, 0.1, 0.1)
        right = gmsh.model.occ.addBox(0.1, 0.0, 0.0, 0.1, 0.1, 0.1)
        gmsh.model.occ.fragment([(3, left)], [(3, right)])
        gmsh.model.occ.synchronize()
        for tag, name, x in ((1, "left", 0.05), (2, "right", 0.15)):
            (_, volume), = gmsh.model.getEntitiesInBoundingBox(x - 0.051, -0.001, -0.001,
                                                               x + 0.051, 0.101, 0.101, 3)
            gmsh.model.setPhysicalName(3, gmsh.model.addPhysicalGroup(3, [volume], tag), name)
        gmsh.model.mesh.setSize(gmsh.model.getEntities(0), 0.05)
        gmsh.model.mesh.generate(3)
        gmsh.write(str(path))
    finally:
        gmsh.finalize()


def main() -> None:
    """Write the three example meshes into this folder."""
    for name, (points, triangles) in (("cube.stl", cube_surface(0.2)),
                                      ("icosphere.stl", icosphere(0.1, 2))):
        meshio.write(HERE / name, meshio.Mesh(points, [("triangle", triangles)]), binary=True)
    write_two_region_box(HERE / "two_region_box.msh")


if __name__ == "__main__":
    main()
