"""Cross-key rules of a scene: what no single key's type or range can say (STYLE rule 8).

:mod:`fem_anim.scene` checks each key on its own (type, length, range) against its
``SCHEMA``; :func:`check_consistency` then checks the keys against each other on the
validated data, before anything is built: list lengths match ``mesh.dim``, the mesh is
not absurdly fine (:data:`MAX_CELLS`), pin and region boxes are not empty, each
``[[obstacle]]`` has the keys of its type, ``[initial]`` and ``[render]`` settings fit
together, and solver settings are compatible with the element and material choices.
Every rule raises :class:`SceneError` naming the key path, the constraint and the value.
"""

from __future__ import annotations

import math
from typing import Any

from .errors import SceneError, show_value

__all__ = ["check_consistency", "check_render", "HESSIAN_METHODS", "MAX_CELLS",
           "OBSTACLE_KEYS", "REGION_MATERIAL_KEYS"]

MAX_CELLS = 2.0e7  # ~24 GB of memory for a P1 Newton step; larger is a typo, not a scene
#: Keys each obstacle type needs, and the geometric keys it must not be given.
OBSTACLE_KEYS = {"plane": ("normal",), "sphere": ("center", "radius")}
#: ``solver.method`` values that solve with a Hessian (``solver.hessian``, ``solver.forcing``).
HESSIAN_METHODS = ("newton", "trust_region")
#: Keys of a ``[[region]]`` that override the body's ``[material]``.
REGION_MATERIAL_KEYS = ("model", "youngs_modulus", "poisson_ratio", "density")


def _estimated_cells(mesh: dict[str, Any]) -> float:
    """A rough count of the simplices gmsh makes (d! per cube of the element size)."""
    d, h = mesh["dim"], mesh["element_size"]
    r, length, a = mesh["radius"], mesh["length"], mesh["minor_radius"]
    measure = {
        "box": math.prod(mesh["size"]) if len(mesh["size"]) == d else 0.0,
        "sphere": (4 / 3 * math.pi * r ** 3) if d == 3 else math.pi * r ** 2,
        "cylinder": (math.pi * r ** 2 * length) if d == 3 else 2 * r * length,
        "torus": (2 * math.pi ** 2 * r * a ** 2) if d == 3 else 4 * math.pi * r * a,
        "capsule": (math.pi * r ** 2 * (length + 4 / 3 * r)) if d == 3
        else 2 * r * length + math.pi * r ** 2,
    }.get(mesh["shape"], 0.0)
    return measure / h ** d * math.factorial(d)


def check_consistency(data: dict[str, Any]) -> None:
    """Cross-key rules: dimensions agree, files exist, settings are compatible."""
    d = data["mesh"]["dim"]
    mesh = data["mesh"]
    if mesh["shape"] == "box" and len(mesh["size"]) != d:
        raise SceneError(f"mesh.size must have {d} entries for mesh.dim = {d}, got {mesh['size']}")
    if mesh["origin"] is not None and len(mesh["origin"]) != d:
        raise SceneError(f"mesh.origin must have {d} entries for mesh.dim = {d}, "
                         f"got {mesh['origin']}")
    if mesh["shape"] == "file" and mesh["file"] is None:
        raise SceneError("mesh.file is required when mesh.shape = \"file\"")
    if mesh["shape"] == "box" and mesh["element_size"] > max(mesh["size"]):
        raise SceneError(f"mesh.element_size must not exceed the box size "
                         f"{max(mesh['size'])}, got {mesh['element_size']}")
    if mesh["shape"] == "torus" and mesh["minor_radius"] >= mesh["radius"]:
        raise SceneError(f"mesh.minor_radius must be < mesh.radius = {mesh['radius']}, got "
                         f"{mesh['minor_radius']}")
    cells = _estimated_cells(mesh)
    if cells > MAX_CELLS:
        raise SceneError(f"mesh.element_size = {mesh['element_size']} would make about "
                         f"{cells:.2g} cells for this {mesh['shape']} (at most {MAX_CELLS:.0e}); "
                         "use a larger element size")
    if "gravity" in data and len(data["gravity"]["acceleration"]) != d:
        raise SceneError(f"gravity.acceleration must have {d} entries for mesh.dim = {d}, "
                         f"got {data['gravity']['acceleration']}")
    for i, pin in enumerate(data["pin"]):
        lo, hi = pin["min"], pin["max"]
        if len(lo) != d or len(hi) != d:
            raise SceneError(f"pin[{i}].min and pin[{i}].max must have {d} entries for "
                             f"mesh.dim = {d}, got {lo} and {hi}")
        if any(a > b for a, b in zip(lo, hi)):
            raise SceneError(f"pin[{i}] ({pin['name']}) is an empty box: min {lo} exceeds "
                             f"max {hi}")
        for key in ("velocity", "center"):
            if pin[key] is not None and len(pin[key]) != d:
                raise SceneError(f"pin[{i}].{key} must have {d} entries for mesh.dim = {d}, "
                                 f"got {pin[key]}")
        if pin["axis"] is not None:
            if d == 2:
                raise SceneError(f"pin[{i}].axis is for mesh.dim = 3 (2D rotations are about "
                                 "the z axis)")
            if not any(pin["axis"]):
                raise SceneError(f"pin[{i}].axis must not be the zero vector")
        if pin["angular_velocity"] != 0 and d == 3 and pin["axis"] is None:
            raise SceneError(f"pin[{i}].axis is required with pin[{i}].angular_velocity")
    _check_regions(data)
    _check_initial(data)
    for i, obstacle in enumerate(data["obstacle"]):
        _check_obstacle(i, obstacle, d)
    if data["time"]["min_dt"] is not None and data["time"]["min_dt"] > data["time"]["dt"]:
        raise SceneError(f"time.min_dt must not exceed time.dt = {data['time']['dt']}, got "
                         f"{data['time']['min_dt']}")
    check_render(data["render"])
    if data["element"]["degree"] == 2 and data["material"]["mass"] == "lumped":
        raise SceneError("material.mass = \"lumped\" is not supported with element.degree = 2 "
                         "(row-sum lumping of P2 gives zero or negative vertex masses); use "
                         "\"consistent\"")
    solver = data["solver"]
    if solver["hessian"] != "exact" and solver["method"] not in HESSIAN_METHODS:
        raise SceneError(f"solver.hessian = \"{solver['hessian']}\" modifies Newton's "
                         f"Hessian; solver.method = \"{solver['method']}\" uses none")
    if solver["hessian"] == "trust_region_filter" and solver["method"] != "newton":
        raise SceneError("solver.hessian = \"trust_region_filter\" chooses each iteration's "
                         "filter from the line search's step; solver.method = "
                         f"\"{solver['method']}\" has none (use \"newton\")")
    if solver["forcing"] != "tight" and solver["method"] not in HESSIAN_METHODS:
        raise SceneError(f"solver.forcing = {solver['forcing']!r} sets the Krylov tolerance of "
                         f"Newton's linear solves; solver.method = {solver['method']!r} has "
                         "none (use 'newton' or 'trust_region')")


def _check_regions(data: dict[str, Any]) -> None:
    """``[[region]]``: a box (``min`` and ``max``) or a mesh group name; names unique;
    at least one material key; settings the regions' models allow."""
    d = data["mesh"]["dim"]
    seen: dict[str, int] = {}
    for i, region in enumerate(data["region"]):
        where = f"region[{i}] ({region['name']})"
        if region["name"] in seen:
            raise SceneError(f"{where}: the name is already used by region[{seen[region['name']]}]")
        seen[region["name"]] = i
        lo, hi = region["min"], region["max"]
        if (lo is None) != (hi is None):
            raise SceneError(f"{where}: give both min and max (a box of cells by centroid), or "
                             "neither (the name is then a physical group of the mesh)")
        if lo is not None:
            if len(lo) != d or len(hi) != d:
                raise SceneError(f"region[{i}].min and region[{i}].max must have {d} entries "
                                 f"for mesh.dim = {d}, got {lo} and {hi}")
            if any(a > b for a, b in zip(lo, hi)):
                raise SceneError(f"{where} is an empty box: min {lo} exceeds max {hi}")
        if all(region[k] is None for k in REGION_MATERIAL_KEYS):
            raise SceneError(f"{where} sets no material key (give at least one of "
                             f"{', '.join(REGION_MATERIAL_KEYS)})")
    models = {data["material"]["model"]} | {r["model"] for r in data["region"] if r["model"]}
    hessian = data["solver"]["hessian"]
    if len(models) > 1 and hessian in ("project", "abs", "trust_region_filter", "auto"):
        raise SceneError(f"solver.hessian = \"{hessian}\" takes one material model per body (it "
                         f"filters that model's tangent); the regions use "
                         f"{', '.join(sorted(models))} (use \"shift\")")


def _check_initial(data: dict[str, Any]) -> None:
    """``[initial]``: vectors of the mesh dimension; omega a number in 2D, 3 numbers in 3D."""
    if "initial" not in data:
        return
    d, initial = data["mesh"]["dim"], data["initial"]
    for key in ("velocity", "center"):
        if initial[key] is not None and len(initial[key]) != d:
            raise SceneError(f"initial.{key} must have {d} entries for mesh.dim = {d}, "
                             f"got {initial[key]}")
    omega = initial["angular_velocity"]
    if d == 2 and isinstance(omega, list):
        raise SceneError("initial.angular_velocity must be a number (rad/s about z) for "
                         f"mesh.dim = 2, got {show_value(omega)}")
    if d == 3 and omega is not None and not (
            isinstance(omega, list) and len(omega) == 3
            and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in omega)):
        raise SceneError("initial.angular_velocity must be a list of 3 numbers (the angular "
                         f"velocity vector, rad/s) for mesh.dim = 3, got {show_value(omega)}")
    if all(initial[k] is None for k in ("velocity", "angular_velocity")):
        raise SceneError("[initial] needs velocity or angular_velocity")


def _check_obstacle(i: int, obstacle: dict[str, Any], d: int) -> None:
    """An obstacle has the keys of its type, of the scene's dimension, and no others."""
    kind = obstacle["type"]
    for key in OBSTACLE_KEYS[kind]:
        if obstacle[key] is None:
            raise SceneError(f"obstacle[{i}].{key} is required for type = \"{kind}\"")
    other = [k for t, keys in OBSTACLE_KEYS.items() if t != kind for k in keys] + \
        (["point"] if kind == "sphere" else [])
    for key in other:
        if obstacle[key] is not None:
            raise SceneError(f"obstacle[{i}].{key} does not apply to type = \"{kind}\"")
    for key in ("point", "normal", "center"):
        if obstacle[key] is not None and len(obstacle[key]) != d:
            raise SceneError(f"obstacle[{i}].{key} must have {d} entries for mesh.dim = {d}, "
                             f"got {obstacle[key]}")
    if kind == "plane" and math.hypot(*obstacle["normal"]) == 0.0:
        raise SceneError(f"obstacle[{i}].normal must be a nonzero vector, got "
                         f"{obstacle['normal']}")


def check_render(render: dict[str, Any]) -> None:
    """A camera given by position: the focal point and up vector need it, and differ from it."""
    position = render["camera_position"]
    for key in ("focal_point", "view_up"):
        if render[key] is not None and position is None:
            raise SceneError(f"render.{key} needs render.camera_position (or use render.view)")
    if position is not None and render["focal_point"] == position:
        raise SceneError(f"render.focal_point must differ from render.camera_position, got "
                         f"{position}")
