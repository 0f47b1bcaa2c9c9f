"""A ball (3D, tetrahedra) or disk (2D, triangles)."""

from __future__ import annotations

from collections.abc import Sequence

from fem_anim.meshes.common import name_body, padded_origin, set_element_size

__all__ = ["build_sphere"]


def build_sphere(model, radius: float, element_size: float,
                 origin: Sequence[float] | None = None, dim: int = 3):
    """Mesh the ball ``|x - origin| <= radius`` (a disk in 2D) with target edge ``element_size``.

    The mesh is inscribed in the sphere: its volume falls short of ``4/3 pi r^3`` (``pi r^2``)
    by about ``(h / r)^2 / 3`` relative, ``h`` the element size.

    Physical groups: ``body`` (the ball, tag 1) and ``surface`` (its boundary, tag 1 in
    dimension ``dim - 1``).

    Args:
        model: ``gmsh.model`` of an initialised gmsh session.
        radius: Radius (m).
        element_size: Target edge length (m).
        origin: Centre, ``dim`` entries; default the coordinate origin.
        dim: 3 for a ball, 2 for a disk.

    Returns:
        The model, meshed.
    """
    centre = padded_origin(origin, dim)
    model.add("sphere")
    if dim == 3:
        tag = model.occ.addSphere(*centre, radius)
    else:
        tag = model.occ.addDisk(*centre, radius, radius)
    model.occ.synchronize()
    name_body(model, dim, [tag])
    set_element_size(model, element_size)
    model.mesh.generate(dim)
    return model
