"""A ring torus about the z axis (3D, tetrahedra) or an annulus (2D, triangles)."""

from __future__ import annotations

from collections.abc import Sequence

from fem_anim.meshes.common import (entities_in_box, name_body, name_group, padded_origin,
                                    set_element_size)

__all__ = ["build_torus"]


def build_torus(model, radius: float, minor_radius: float, element_size: float,
                origin: Sequence[float] | None = None, dim: int = 3):
    """Mesh the torus of major radius ``radius`` and tube radius ``minor_radius`` about z.

    The tube's centre line is the circle of radius ``radius`` about ``origin`` in the plane
    ``z = oz``; the volume is ``2 pi^2 R r^2``. In 2D the torus is seen from above: the
    annulus ``radius - minor_radius <= |x - origin| <= radius + minor_radius`` (area
    ``4 pi R r``).

    Physical groups: ``body`` (tag 1); on the boundary ``surface`` (tag 1) and, in 2D,
    ``outer`` and ``inner`` (the two circles, tags 2, 3).

    Args:
        model: ``gmsh.model`` of an initialised gmsh session.
        radius: Major radius ``R`` (m).
        minor_radius: Tube radius ``r < R`` (m).
        element_size: Target edge length (m).
        origin: Centre, ``dim`` entries; default the coordinate origin.
        dim: 3 for a torus, 2 for an annulus.

    Returns:
        The model, meshed.

    Raises:
        ValueError: if ``minor_radius >= radius`` (the tube would cross the axis).
    """
    if not minor_radius < radius:
        raise ValueError(f"minor_radius must be < radius = {radius} (the tube would cross "
                         f"the axis), got {minor_radius}")
    c = padded_origin(origin, dim)
    model.add("torus")
    if dim == 3:
        tag = model.occ.addTorus(*c, radius, minor_radius)
    else:
        outer = model.occ.addDisk(*c, radius + minor_radius, radius + minor_radius)
        inner = model.occ.addDisk(*c, radius - minor_radius, radius - minor_radius)
        (_, tag), = model.occ.cut([(2, outer)], [(2, inner)])[0]
    model.occ.synchronize()
    boundary = name_body(model, dim, [tag])
    if dim == 2:
        a = radius - minor_radius
        inner = entities_in_box(model, 1, [c[0] - a, c[1] - a, 0.0], [c[0] + a, c[1] + a, 0.0],
                                radius)
        name_group(model, 1, [t for t in boundary if t not in inner], 2, "outer")
        name_group(model, 1, inner, 3, "inner")
    set_element_size(model, element_size)
    model.mesh.generate(dim)
    return model
