"""An axis-aligned box (3D, tetrahedra) or rectangle (2D, triangles)."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["build_box"]


def build_box(model, size: Sequence[float], element_size: float,
              origin: Sequence[float] | None = None):
    """Mesh the box ``origin + [0, size]`` with simplices of target edge ``element_size``.

    Physical groups: ``body`` (the volume, tag 1) and one per side, ``xmin``, ``xmax``,
    ``ymin``, ``ymax`` (and ``zmin``, ``zmax`` in 3D), for scenes to refer to.

    Args:
        model: ``gmsh.model`` of an initialised gmsh session.
        size: Edge lengths, 2 or 3 entries (m).
        element_size: Target edge length (m).
        origin: Lower corner, default the coordinate origin.

    Returns:
        The model, meshed.
    """
    dim = len(size)
    origin = list(origin) if origin is not None else [0.0] * dim
    model.add("box")
    if dim == 3:
        tag = model.occ.addBox(*origin, *size)
    else:
        tag = model.occ.addRectangle(*origin, 0.0, *size)
    model.occ.synchronize()
    model.addPhysicalGroup(dim, [tag], 1)
    model.setPhysicalName(dim, 1, "body")
    names = ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"]
    eps = 1e-9 * max(size)
    for side, name in enumerate(names[: 2 * dim]):
        axis, upper = divmod(side, 2)
        lo = [o - eps for o in origin] + [-eps] * (3 - dim)
        hi = [o + s + eps for o, s in zip(origin, size)] + [eps] * (3 - dim)
        plane = origin[axis] + (size[axis] if upper else 0.0)
        lo[axis], hi[axis] = plane - eps, plane + eps
        faces = [t for _, t in model.getEntitiesInBoundingBox(*lo, *hi, dim - 1)]
        group = model.addPhysicalGroup(dim - 1, faces, side + 2)
        model.setPhysicalName(dim - 1, group, name)
    model.mesh.setSize(model.getEntities(0), element_size)
    model.mesh.generate(dim)
    return model
