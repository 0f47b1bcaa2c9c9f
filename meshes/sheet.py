"""A rectangular sheet of triangles in 3D (a shell's mid-surface): gmsh and numpy.

The rectangle ``origin + [0, size_x] x [0, size_y]`` lies in the plane ``z = origin_z``.
It is cut into a grid of squares (rectangles), each split into two triangles along a
diagonal chosen by ``triangulation``:

* ``"right"``: every cell along the diagonal from its lower-left to its upper-right corner,
* ``"left"``: along the other diagonal,
* ``"alternate"``: the two diagonals alternating like a chessboard,
* ``"crossed"``: both diagonals, four triangles per square around a vertex at its centre
  (numpy builder only; the most isotropic of the four).

The hinge bending energy of a P1 surface depends on its triangulation
(:mod:`fem_anim.forms.shell_bending`; docs/cloth.md), so the choice is the scene's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from fem_anim.meshes.common import entities_in_box, name_body, name_group

__all__ = ["TRIANGULATIONS", "build_sheet", "sheet_divisions", "structured_sheet",
           "structured_tube"]

#: ``triangulation`` -> gmsh's transfinite ``arrangement`` (None: numpy only).
TRIANGULATIONS = {"right": "Right", "left": "Left", "alternate": "Alternate",
                  "crossed": None}


def _origin3(origin: Sequence[float] | None) -> list[float]:
    origin = [0.0, 0.0, 0.0] if origin is None else [float(c) for c in origin]
    if len(origin) != 3:
        raise ValueError(f"origin of a sheet must have 3 entries, got {origin}")
    return origin


def sheet_divisions(size: Sequence[float], element_size: float) -> list[int]:
    """Squares per side for a target edge ``element_size``: ``ceil(size / element_size)``.

    Raises:
        ValueError: if ``size`` has not two positive entries.
    """
    if len(size) != 2 or min(size) <= 0:
        raise ValueError(f"size of a sheet must be 2 positive lengths, got {list(size)}")
    return [max(1, math.ceil(s / element_size - 1e-9)) for s in size]


def structured_sheet(size: Sequence[float], divisions: Sequence[int],
                     origin: Sequence[float] | None = None, triangulation: str = "right"
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Vertices and triangles of the sheet cut into ``divisions`` squares (numpy, no gmsh).

    Args:
        size: ``(size_x, size_y)`` (m).
        divisions: Squares along x and y, each >= 1.
        origin: Lower corner (3 coordinates), default the coordinate origin.
        triangulation: A key of :data:`TRIANGULATIONS`.

    Returns:
        ``points`` ((nx + 1)(ny + 1), 3) and ``cells`` (2 nx ny, 3), all triangles with the
        normal +z.

    Raises:
        ValueError: on a bad ``divisions`` or ``triangulation``.
    """
    if triangulation not in TRIANGULATIONS:
        raise ValueError(f"triangulation must be one of {sorted(TRIANGULATIONS)}, "
                         f"got {triangulation!r}")
    nx, ny = (int(n) for n in divisions)
    if nx < 1 or ny < 1:
        raise ValueError(f"divisions must be 2 integers >= 1, got {list(divisions)}")
    o = _origin3(origin)
    X, Y = np.meshgrid(np.linspace(0, size[0], nx + 1), np.linspace(0, size[1], ny + 1),
                       indexing="ij")
    points = np.column_stack([X.ravel() + o[0], Y.ravel() + o[1], np.full(X.size, o[2])])
    i, j = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij"))
    a, b = i * (ny + 1) + j, (i + 1) * (ny + 1) + j  # lower-left, lower-right
    c, d = b + 1, a + 1  # upper-right, upper-left
    if triangulation == "crossed":
        centres = (points[a] + points[c]) / 2
        m = len(points) + np.arange(len(a))
        cells = np.concatenate([np.column_stack(t) for t in
                                ((a, b, m), (b, c, m), (c, d, m), (d, a, m))])
        return np.concatenate([points, centres]), cells.astype(np.int64)
    right = {"right": np.ones_like(i, bool), "left": np.zeros_like(i, bool),
             "alternate": (i + j) % 2 == 1}[triangulation]
    first = np.where(right[:, None], np.column_stack([a, b, c]), np.column_stack([a, b, d]))
    second = np.where(right[:, None], np.column_stack([a, c, d]), np.column_stack([b, c, d]))
    return points, np.concatenate([first, second]).astype(np.int64)


def structured_tube(radius: float, length: float, divisions: Sequence[int],
                    triangulation: str = "right") -> tuple[np.ndarray, np.ndarray]:
    """A cylindrical tube (axis x, from 0 to ``length``): the sheet of ``divisions``
    = (along x, around) squares rolled onto the radius, its seam merged (numpy, no gmsh).

    Args:
        radius: The tube's radius (m).
        length: Its length along x (m).
        divisions: Squares along x and around the circumference (at least 3 around).
        triangulation: ``"right"``, ``"left"`` or ``"alternate"`` (an even count around).

    Returns:
        ``points`` ((nx + 1) n_around, 3) and ``cells`` (2 nx n_around, 3), the normals
        pointing outwards.

    Raises:
        ValueError: on fewer than 3 squares around, or an odd count with ``"alternate"``.
    """
    nx, around = (int(n) for n in divisions)
    if around < 3 or (triangulation == "alternate" and around % 2):
        raise ValueError(f"a tube needs at least 3 squares around (even for alternate), "
                         f"got {around}")
    points, cells = structured_sheet([length, 2 * np.pi * radius], [nx, around],
                                     triangulation=triangulation)
    angle = points[:, 1] / radius
    rolled = np.column_stack([points[:, 0], radius * np.cos(angle), radius * np.sin(angle)])
    i, j = np.divmod(np.arange(len(points)), around + 1)
    seam = j == around  # the last row of vertices is the first one
    index = np.where(seam, i * (around + 1), np.arange(len(points)))
    keep = np.flatnonzero(~seam)
    renumber = np.full(len(points), -1, np.int64)
    renumber[keep] = np.arange(keep.size)
    return rolled[keep], renumber[index[cells]]


def build_sheet(model, size: Sequence[float], element_size: float,
                origin: Sequence[float] | None = None, triangulation: str = "right"):
    """Mesh the sheet with gmsh as a structured (transfinite) grid of triangles.

    Physical groups: ``body`` (the surface, tag 1), ``surface`` (its boundary curves,
    tag 1) and the four edges ``xmin``, ``xmax``, ``ymin``, ``ymax`` (tags 2 to 5).

    Args:
        model: ``gmsh.model`` of an initialised gmsh session.
        size: ``(size_x, size_y)`` (m).
        element_size: Target length of the squares' sides (m).
        origin: Lower corner (3 coordinates), default the coordinate origin.
        triangulation: A key of :data:`TRIANGULATIONS` but ``"crossed"``.

    Returns:
        The model, meshed (dimension 2).

    Raises:
        ValueError: on a bad ``size``, ``origin`` or ``triangulation``.
    """
    gmsh_names = [k for k, v in TRIANGULATIONS.items() if v is not None]
    if TRIANGULATIONS.get(triangulation) is None:
        raise ValueError(f"triangulation must be one of {gmsh_names}, got {triangulation!r}")
    nx, ny = sheet_divisions(size, element_size)
    o = _origin3(origin)
    model.add("sheet")
    tag = model.occ.addRectangle(*o, *size)
    model.occ.synchronize()
    boundary = name_body(model, 2, [tag])
    hi = [o[0] + size[0], o[1] + size[1], o[2]]
    for k, name in enumerate(["xmin", "xmax", "ymin", "ymax"]):
        axis, upper = divmod(k, 2)
        lo_k, hi_k = list(o), list(hi)
        lo_k[axis] = hi_k[axis] = hi[axis] if upper else o[axis]
        name_group(model, 1, entities_in_box(model, 1, lo_k, hi_k, max(size)), k + 2, name)
    for curve in boundary:
        x0, y0, _, x1, y1, _ = model.getBoundingBox(1, curve)
        along_x = abs(x1 - x0) > abs(y1 - y0)
        model.mesh.setTransfiniteCurve(curve, (nx if along_x else ny) + 1)
    model.mesh.setTransfiniteSurface(tag, arrangement=TRIANGULATIONS[triangulation])
    model.mesh.generate(2)
    return model
