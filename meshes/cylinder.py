"""A circular cylinder along x (3D, tetrahedra) or its axial section, a rectangle (2D)."""

from __future__ import annotations

from collections.abc import Sequence

from fem_anim.meshes.common import name_body, name_ends, padded_origin, set_element_size

__all__ = ["build_cylinder"]


def build_cylinder(model, radius: float, length: float, element_size: float,
                   origin: Sequence[float] | None = None, dim: int = 3):
    """Mesh the cylinder of axis ``origin + s e_x``, ``0 <= s <= length``, and given radius.

    In 2D the cylinder is its section through the axis, the rectangle
    ``[ox, ox + length] x [oy - radius, oy + radius]``.

    Physical groups: ``body`` (tag 1); on the boundary ``surface`` (all of it, tag 1),
    ``xmin`` and ``xmax`` (the end faces at ``x = ox`` and ``x = ox + length``, tags 2, 3)
    and ``side`` (the lateral surface, tag 4).

    Args:
        model: ``gmsh.model`` of an initialised gmsh session.
        radius: Radius (m).
        length: Length along x (m).
        element_size: Target edge length (m).
        origin: Centre of the ``xmin`` end, ``dim`` entries; default the coordinate origin.
        dim: 3 for a cylinder, 2 for a rectangle.

    Returns:
        The model, meshed.
    """
    o = padded_origin(origin, dim)
    model.add("cylinder")
    if dim == 3:
        tag = model.occ.addCylinder(*o, length, 0.0, 0.0, radius)
    else:
        tag = model.occ.addRectangle(o[0], o[1] - radius, 0.0, length, 2.0 * radius)
    model.occ.synchronize()
    boundary = name_body(model, dim, [tag])
    x0, x1 = o[0], o[0] + length
    name_ends(model, dim, boundary, [(x0, x0), (x1, x1)], o, radius, max(radius, length))
    set_element_size(model, element_size)
    model.mesh.generate(dim)
    return model
