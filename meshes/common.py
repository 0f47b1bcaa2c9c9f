"""Helpers shared by the gmsh builders: physical groups, element size, entity lookup."""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["boundary_of", "entities_in_box", "name_group", "padded_origin", "set_element_size"]


def padded_origin(origin: Sequence[float] | None, dim: int) -> list[float]:
    """The origin as three coordinates (``z = 0`` in 2D; default the coordinate origin)."""
    origin = [0.0] * dim if origin is None else [float(c) for c in origin]
    if len(origin) != dim:
        raise ValueError(f"origin must have {dim} entries, got {origin}")
    return origin + [0.0] * (3 - dim)


def name_group(model, dim: int, entities: Sequence[int], tag: int, name: str) -> int:
    """Add the physical group ``tag`` of the ``dim``-entities ``entities`` and call it ``name``."""
    group = model.addPhysicalGroup(dim, list(entities), tag)
    model.setPhysicalName(dim, group, name)
    return group


def set_element_size(model, element_size: float) -> None:
    """Target edge length ``element_size`` everywhere (points and a constant background field).

    Sizes on points alone leave the inside of curved OCC surfaces (a torus has a single
    point) to gmsh's interpolation; the background field holds them to ``element_size``.
    """
    model.mesh.setSize(model.getEntities(0), element_size)
    field = model.mesh.field.add("MathEval")
    model.mesh.field.setString(field, "F", repr(float(element_size)))
    model.mesh.field.setAsBackgroundMesh(field)


def boundary_of(model, dim: int, entities: Sequence[int]) -> list[int]:
    """Tags of the ``(dim - 1)``-entities bounding the ``dim``-entities ``entities``."""
    pairs = model.getBoundary([(dim, t) for t in entities], combined=True, oriented=False)
    return sorted({t for _, t in pairs})


def entities_in_box(model, dim: int, lo: Sequence[float], hi: Sequence[float],
                    scale: float) -> list[int]:
    """Tags of the ``dim``-entities whose bounding box lies in ``[lo, hi]``, give or take.

    OCC pads bounding boxes by its tolerance (1e-7), so the box is widened by
    ``max(1e-6 scale, 1e-6)``; ``scale`` is the size of the body.
    """
    eps = max(1e-6 * scale, 1e-6)
    box = [c - eps for c in lo] + [c + eps for c in hi]
    return [tag for _, tag in model.getEntitiesInBoundingBox(*box, dim)]
