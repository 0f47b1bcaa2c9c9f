"""A capsule along x: a cylinder capped by two half-balls (3D) or a stadium (2D)."""

from __future__ import annotations

from collections.abc import Sequence

from fem_anim.meshes.common import name_body, name_ends, padded_origin, set_element_size

__all__ = ["build_capsule"]


def build_capsule(model, radius: float, length: float, element_size: float,
                  origin: Sequence[float] | None = None, dim: int = 3):
    """Mesh the points within ``radius`` of the segment ``origin + s e_x``, ``0 <= s <= length``.

    That is the cylinder of :func:`~fem_anim.meshes.build_cylinder` fused with the balls
    of ``radius`` about both ends of its axis, so the body spans
    ``[ox - radius, ox + length + radius]`` in x. Volume ``pi r^2 L + 4/3 pi r^3``; in 2D
    the stadium, area ``2 r L + pi r^2``.

    Physical groups: ``body`` (tag 1); on the boundary ``surface`` (all of it, tag 1),
    ``xmin`` and ``xmax`` (the caps, tags 2, 3) and ``side`` (the straight part, tag 4).

    Args:
        model: ``gmsh.model`` of an initialised gmsh session.
        radius: Radius of the cylinder and caps (m).
        length: Length of the straight part along x (m).
        element_size: Target edge length (m).
        origin: Centre of the ``xmin`` cap, ``dim`` entries; default the coordinate origin.
        dim: 3 for a capsule, 2 for a stadium.

    Returns:
        The model, meshed.
    """
    o = padded_origin(origin, dim)
    end = [o[0] + length, o[1], o[2]]
    model.add("capsule")
    if dim == 3:
        parts = [(3, model.occ.addCylinder(*o, length, 0.0, 0.0, radius)),
                 (3, model.occ.addSphere(*o, radius)), (3, model.occ.addSphere(*end, radius))]
    else:
        parts = [(2, model.occ.addRectangle(o[0], o[1] - radius, 0.0, length, 2.0 * radius)),
                 (2, model.occ.addDisk(*o, radius, radius)),
                 (2, model.occ.addDisk(*end, radius, radius))]
    fused, _ = model.occ.fuse(parts[:1], parts[1:])
    model.occ.synchronize()
    body = [t for _, t in fused]
    boundary = name_body(model, dim, body)
    caps = [(o[0] - radius, o[0]), (end[0], end[0] + radius)]
    name_ends(model, dim, boundary, caps, o, radius, max(radius, length))
    set_element_size(model, element_size)
    model.mesh.generate(dim)
    return model
