"""An axis-aligned box (3D, tetrahedra) or rectangle (2D, triangles)."""

from __future__ import annotations

from collections.abc import Sequence

from fem_anim.meshes.common import entities_in_box, name_body, name_group, padded_origin

__all__ = ["build_box"]


def build_box(model, size: Sequence[float], element_size: float,
              origin: Sequence[float] | None = None):
    """Mesh the box ``origin + [0, size]`` with simplices of target edge ``element_size``.

    Physical groups: ``body`` (the volume, tag 1), ``surface`` (the whole boundary, tag 1 in
    dimension ``dim - 1``) and one per side, ``xmin``, ``xmax``, ``ymin``, ``ymax`` (and
    ``zmin``, ``zmax`` in 3D; tags 2 to 7), for scenes to refer to.

    Args:
        model: ``gmsh.model`` of an initialised gmsh session.
        size: Edge lengths, 2 or 3 entries (m).
        element_size: Target edge length (m).
        origin: Lower corner, default the coordinate origin.

    Returns:
        The model, meshed.
    """
    dim = len(size)
    lo = padded_origin(origin, dim)
    hi = [o + s for o, s in zip(lo, list(size) + [0.0] * (3 - dim))]
    model.add("box")
    if dim == 3:
        tag = model.occ.addBox(*lo, *size)
    else:
        tag = model.occ.addRectangle(*lo, *size)
    model.occ.synchronize()
    name_body(model, dim, [tag])
    names = ["xmin", "xmax", "ymin", "ymax", "zmin", "zmax"]
    for side, name in enumerate(names[: 2 * dim]):
        axis, upper = divmod(side, 2)
        plane_lo, plane_hi = list(lo), list(hi)
        plane_lo[axis] = plane_hi[axis] = hi[axis] if upper else lo[axis]
        faces = entities_in_box(model, dim - 1, plane_lo, plane_hi, max(size))
        name_group(model, dim - 1, faces, side + 2, name)
    model.mesh.setSize(model.getEntities(0), element_size)  # flat faces: points suffice
    model.mesh.generate(dim)
    return model
