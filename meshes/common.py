"""Helpers shared by the gmsh builders: physical groups, element size, entity lookup.

Every builder names the groups :func:`name_body` makes (``body`` and ``surface``, tag 1);
the bodies along x (cylinder, capsule) also name their ends and side (:func:`name_ends`).
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["boundary_of", "entities_in_box", "name_body", "name_ends", "name_group",
           "padded_origin", "set_element_size"]


def padded_origin(origin: Sequence[float] | None, dim: int) -> list[float]:
    """The origin as three coordinates (``z = 0`` in 2D; default the coordinate origin).

    Args:
        origin: ``dim`` coordinates, or None.
        dim: The dimension (2 or 3).

    Raises:
        ValueError: if ``origin`` has not ``dim`` entries.
    """
    origin = [0.0] * dim if origin is None else [float(c) for c in origin]
    if len(origin) != dim:
        raise ValueError(f"origin must have {dim} entries, got {origin}")
    return origin + [0.0] * (3 - dim)


def name_group(model, dim: int, entities: Sequence[int], tag: int, name: str) -> int:
    """Add a named physical group.

    Args:
        model: The gmsh model.
        dim: The entities' dimension.
        entities: Their tags.
        tag: The group's tag.
        name: The group's name.

    Returns:
        The group's tag.
    """
    group = model.addPhysicalGroup(dim, list(entities), tag)
    model.setPhysicalName(dim, group, name)
    return group


def name_body(model, dim: int, body: Sequence[int]) -> list[int]:
    """Name ``body`` (the ``dim``-entities ``body``) and ``surface`` (their boundary), tag 1.

    Args:
        model: The gmsh model.
        dim: The body's dimension.
        body: The tags of its ``dim``-entities.

    Returns:
        The tags of the boundary's ``(dim - 1)``-entities, for naming parts of it.
    """
    name_group(model, dim, body, 1, "body")
    boundary = boundary_of(model, dim, body)
    name_group(model, dim - 1, boundary, 1, "surface")
    return boundary


def name_ends(model, dim: int, boundary: Sequence[int], x_ranges, centre: Sequence[float],
              radius: float, scale: float) -> None:
    """Name the ends of a body along x, ``xmin`` and ``xmax`` (tags 2, 3), and ``side`` (tag 4).

    An end is the boundary entities in the box of x in its range of ``x_ranges`` (one
    ``(lo, hi)`` per end) within ``radius`` of the axis through ``centre`` (y and, in 3D, z);
    ``side`` is the rest of ``boundary``.

    Args:
        model: The gmsh model.
        dim: The body's dimension.
        boundary: The tags of its boundary entities.
        x_ranges: ``((lo, hi), (lo, hi))``: the x range of each end.
        centre: A point of the axis (3 coordinates).
        radius: The body's radius about the axis.
        scale: The size of the body (:func:`entities_in_box`).
    """
    r = radius if dim == 3 else 0.0
    ends = []
    for tag, (name, (lo, hi)) in enumerate(zip(("xmin", "xmax"), x_ranges), start=2):
        faces = entities_in_box(model, dim - 1, [lo, centre[1] - radius, centre[2] - r],
                                [hi, centre[1] + radius, centre[2] + r], scale)
        name_group(model, dim - 1, faces, tag, name)
        ends += faces
    name_group(model, dim - 1, [t for t in boundary if t not in ends], 4, "side")


def set_element_size(model, element_size: float) -> None:
    """Target edge length ``element_size`` everywhere (points and a constant background field).

    Sizes on points alone leave the inside of curved OCC surfaces (a torus has a single
    point) to gmsh's interpolation; the background field holds them to ``element_size``.

    Args:
        model: The gmsh model.
        element_size: The target edge length (m).
    """
    model.mesh.setSize(model.getEntities(0), element_size)
    field = model.mesh.field.add("MathEval")
    model.mesh.field.setString(field, "F", repr(float(element_size)))
    model.mesh.field.setAsBackgroundMesh(field)


def boundary_of(model, dim: int, entities: Sequence[int]) -> list[int]:
    """Tags of the ``(dim - 1)``-entities bounding some ``dim``-entities.

    Args:
        model: The gmsh model.
        dim: The entities' dimension.
        entities: Their tags.

    Returns:
        The boundary's tags, sorted.
    """
    pairs = model.getBoundary([(dim, t) for t in entities], combined=True, oriented=False)
    return sorted({t for _, t in pairs})


def entities_in_box(model, dim: int, lo: Sequence[float], hi: Sequence[float],
                    scale: float) -> list[int]:
    """Tags of the ``dim``-entities whose bounding box lies in ``[lo, hi]``, give or take.

    OCC pads bounding boxes by its tolerance (1e-7), so the box is widened by
    ``max(1e-6 scale, 1e-6)``.

    Args:
        model: The gmsh model.
        dim: The entities' dimension.
        lo: The box's lower corner (3 coordinates).
        hi: The box's upper corner (3 coordinates).
        scale: The size of the body.

    Returns:
        The tags of the entities inside.
    """
    eps = max(1e-6 * scale, 1e-6)
    box = [c - eps for c in lo] + [c + eps for c in hi]
    return [tag for _, tag in model.getEntitiesInBoundingBox(*box, dim)]
