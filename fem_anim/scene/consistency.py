"""Cross-key rules of a scene: what no single key's type or range can say.

:mod:`fem_anim.scene.validation` checks each key on its own (type, length, range) against
:data:`~fem_anim.scene.schema.SCHEMA`; :func:`check_consistency` then checks the keys
against each other on the validated data, before anything is built: list lengths match ``mesh.dim``, the mesh is
not absurdly fine (:data:`MAX_CELLS`), pin and region boxes are not empty, each
``[[obstacle]]`` has the keys of its type, ``[initial]`` and ``[render]`` settings fit
together, solver settings are compatible with the element and material choices, and
contact settings fit the scene's scales (:mod:`fem_anim.scene.contact_limits`).
Every rule raises :class:`SceneError` naming the key path, the constraint and the value.
"""

from __future__ import annotations

import math
from typing import Any

from fem_anim.errors import SceneError, show_value
from fem_anim.scene.contact_limits import check_contact_limits
from fem_anim.scene.joint_rules import check_joint
from fem_anim.scene.shell_rules import check_shell

__all__ = ["check_consistency", "check_render", "HESSIAN_METHODS", "MAX_CELLS", "MIXED_MODELS",
           "MIXED_PRESETS",
           "OBSTACLE_KEYS", "REGION_MATERIAL_KEYS"]

MAX_CELLS = 2.0e7  # ~24 GB of memory for a P1 Newton step; larger is a typo, not a scene
#: Keys each obstacle type needs, and the geometric keys it must not be given.
OBSTACLE_KEYS = {"plane": ("normal",), "sphere": ("center", "radius")}
#: ``solver.method`` values that solve with a Hessian (``solver.hessian``, ``solver.forcing``).
HESSIAN_METHODS = ("newton", "trust_region")
#: Keys of a ``[[region]]`` that override the body's ``[material]``.
REGION_MATERIAL_KEYS = ("model", "youngs_modulus", "poisson_ratio", "density")
#: Models with a volumetric split (fem_anim/forms/incompressible.py), the ones element.formulation =
#: "mixed" takes; mooney_rivlin exists only there.
MIXED_MODELS = ("neohookean", "stable_neohookean", "mooney_rivlin")
#: Presets that solve the symmetric indefinite (saddle-point) Hessian of a mixed step.
MIXED_PRESETS = ("ldlt", "lu", "schur")


def _check_formulation(data: dict[str, Any]) -> None:
    """element.formulation against the material, mass, degree and solver (the mixed
    Taylor-Hood space of :mod:`fem_anim.problem.mixed_space`)."""
    mat, element, solver = data["material"], data["element"], data["solver"]
    mixed = element["formulation"] == "mixed"
    if not mixed and "pressure" in data["output"]["fields"]:
        raise SceneError("output.fields lists \"pressure\", which only element.formulation = "
                         "\"mixed\" has (the displacement formulation has no pressure unknown)")
    if not mixed:
        if mat["poisson_ratio"] == 0.5:
            raise SceneError("material.poisson_ratio must be in (-1.0, 0.5) with element."
                             "formulation = \"displacement\", got 0.5: an exactly "
                             "incompressible solid needs element.formulation = \"mixed\"")
        models = [mat["model"]] + [r["model"] for r in data.get("region", [])]
        if "mooney_rivlin" in models:
            raise SceneError("material.model = \"mooney_rivlin\" exists only with element."
                             "formulation = \"mixed\" (its volumetric part is the pressure's)")
        return
    where = "with element.formulation = \"mixed\""
    if mat["model"] not in MIXED_MODELS:
        raise SceneError(f"material.model = {mat['model']!r} has no volumetric split: element."
                         f"formulation = \"mixed\" takes one of {', '.join(MIXED_MODELS)}")
    if mat["mass"] == "lumped":
        raise SceneError(f"material.mass = \"lumped\" is refused {where} (the pressure has no "
                         "inertia and row-sum lumping of P2 is not positive); use "
                         "\"consistent\"")
    if element["degree"] != 2:
        raise SceneError(f"element.degree = {element['degree']} is refused {where}: it is "
                         "Taylor-Hood P2/P1 (equal-order P1/P1 is unstable without a "
                         "stabilisation, which is not offered); use element.degree = 2")
    if not mat["poisson_ratio"] > 0.0:
        raise SceneError(f"material.poisson_ratio must be in (0, 0.5] {where}, got "
                         f"{mat['poisson_ratio']}")
    if data.get("region") or any(b["region"] for b in data["body"]):
        raise SceneError(f"[region] is not supported {where}")
    for k, body in enumerate(data["body"]):
        if body["material"] != data["body"][0]["material"]:
            raise SceneError(f"body[{k}].material must equal body[0].material {where} (its "
                             "bodies share one incompressible material)")
    if data["time"]["integrator"] == "symplectic_euler":
        raise SceneError(f"time.integrator = \"symplectic_euler\" is refused {where}: the "
                         "constraint must be implicit")
    for key, allowed in (("method", "newton"), ("hessian", "exact"), ("stopping", "norm")):
        if solver[key] != allowed and not (key == "stopping" and solver[key] == "auto"):
            raise SceneError(f"solver.{key} = {solver[key]!r} is refused {where}: the step is "
                             f"a saddle point (use {allowed!r})")


def _estimated_cells(mesh: dict[str, Any]) -> float:
    """A rough count of the simplices gmsh makes (d! per cube of the element size)."""
    d, h = mesh["dim"], mesh["element_size"]
    if mesh["shape"] == "box" and mesh["divisions"] is not None:  # exact: d! per cube
        return math.factorial(d) * math.prod(mesh["divisions"])
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


def _check_mesh(mesh: dict[str, Any], where: str = "mesh") -> None:
    """A ``[mesh]`` table (top level, or a body's) on its own."""
    d = mesh["dim"]
    if mesh["shape"] == "box" and len(mesh["size"]) != d:
        raise SceneError(f"{where}.size must have {d} entries for {where}.dim = {d}, "
                         f"got {mesh['size']}")
    if mesh["origin"] is not None and len(mesh["origin"]) != d:
        raise SceneError(f"{where}.origin must have {d} entries for {where}.dim = {d}, "
                         f"got {mesh['origin']}")
    if mesh["shape"] == "file" and mesh["file"] is None:
        raise SceneError(f"{where}.file is required when {where}.shape = \"file\"")
    if mesh["file"] is not None and mesh["shape"] != "file":
        # an error, not a guess: defaults are filled in before this check, so a scene's
        # explicit shape = "box" and an absent one look alike here
        raise SceneError(f"{where}.file = {mesh['file']!r} is not used with {where}.shape = "
                         f"{mesh['shape']!r}: set {where}.shape = \"file\" to simulate the file")
    if mesh["divisions"] is not None and mesh["shape"] != "box":
        raise SceneError(f"{where}.divisions = {mesh['divisions']} is used with {where}.shape = "
                         f"\"box\" only, not {mesh['shape']!r}")
    if mesh["divisions"] is not None and len(mesh["divisions"]) != d:
        raise SceneError(f"{where}.divisions must have {d} entries for {where}.dim = {d}, "
                         f"got {mesh['divisions']}")
    if mesh["shape"] == "box" and mesh["divisions"] is None and \
            mesh["element_size"] > max(mesh["size"]):
        raise SceneError(f"{where}.element_size must not exceed the box size "
                         f"{max(mesh['size'])}, got {mesh['element_size']}")
    if mesh["shape"] == "torus" and mesh["minor_radius"] >= mesh["radius"]:
        raise SceneError(f"{where}.minor_radius must be < {where}.radius = {mesh['radius']}, "
                         f"got {mesh['minor_radius']}")
    cells = _estimated_cells(mesh)
    if cells > MAX_CELLS:
        key = "divisions" if mesh["divisions"] is not None else "element_size"
        raise SceneError(f"{where}.{key} = {mesh[key]} would make about {cells:.2g} cells for "
                         f"this {mesh['shape']} (at most {MAX_CELLS:.0e}); use fewer, larger "
                         "elements")


def _check_pins(pins: list[dict[str, Any]], d: int, prefix: str = "") -> None:
    """``[[pin]]`` boxes (top level, or a body's ``[[body.pin]]`` with ``prefix`` ``body[k].``)."""
    for i, pin in enumerate(pins):
        lo, hi = pin["min"], pin["max"]
        if len(lo) != d or len(hi) != d:
            raise SceneError(f"{prefix}pin[{i}].min and {prefix}pin[{i}].max must have {d} "
                             f"entries for mesh.dim = {d}, got {lo} and {hi}")
        if any(a > b for a, b in zip(lo, hi)):
            raise SceneError(f"{prefix}pin[{i}] ({pin['name']}) is an empty box: min {lo} "
                             f"exceeds max {hi}")
        for key in ("velocity", "center"):
            if pin[key] is not None and len(pin[key]) != d:
                raise SceneError(f"{prefix}pin[{i}].{key} must have {d} entries for "
                                 f"mesh.dim = {d}, got {pin[key]}")
        if pin["axis"] is not None:
            if d == 2:
                raise SceneError(f"{prefix}pin[{i}].axis is for mesh.dim = 3 (2D rotations are "
                                 "about the z axis)")
            if not any(pin["axis"]):
                raise SceneError(f"{prefix}pin[{i}].axis must not be the zero vector")
        if pin["angular_velocity"] != 0 and d == 3 and pin["axis"] is None:
            raise SceneError(f"{prefix}pin[{i}].axis is required with "
                             f"{prefix}pin[{i}].angular_velocity")


def check_consistency(data: dict[str, Any]) -> None:
    """Cross-key rules: dimensions agree, boxes are not empty, settings are compatible.

    Args:
        data: A scene whose keys each passed their own check (every key present).

    Raises:
        SceneError: for the first rule broken, naming the keys and their values.
    """
    d = data["mesh"]["dim"]
    check_joint(data)
    check_shell(data)
    if data["body"]:
        _check_bodies(data)
    else:
        _check_mesh(data["mesh"])
    if "gravity" in data and len(data["gravity"]["acceleration"]) != d:
        raise SceneError(f"gravity.acceleration must have {d} entries for mesh.dim = {d}, "
                         f"got {data['gravity']['acceleration']}")
    _check_pins(data["pin"], d)
    _check_regions(data)
    _check_initial(data)
    for i, obstacle in enumerate(data["obstacle"]):
        _check_obstacle(i, obstacle, d)
    if data["time"]["min_dt"] is not None and data["time"]["min_dt"] > data["time"]["dt"]:
        raise SceneError(f"time.min_dt must not exceed time.dt = {data['time']['dt']}, got "
                         f"{data['time']['min_dt']}")
    check_render(data["render"])
    _check_formulation(data)
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
    update = solver["hessian_update"]
    if update != "every_iteration":
        if solver["hessian"] not in ("exact", "project", "abs"):
            raise SceneError(f"solver.hessian_update = {update!r} keeps a Hessian over "
                             f"iterations; solver.hessian = {solver['hessian']!r} chooses one "
                             "per iteration (use exact, project or abs)")
        methods = ("newton", "lbfgs") if update in ("rest", "every_step") else ("newton",)
        if solver["method"] not in methods:
            raise SceneError(f"solver.hessian_update = {update!r} needs solver.method in "
                             f"{', '.join(methods)}, got {solver['method']!r}")
        if data["element"].get("formulation") == "mixed":
            raise SceneError(f"solver.hessian_update = {update!r} is refused with element."
                             "formulation = \"mixed\" (a kept saddle-point Hessian gives no "
                             "descent on the merit function)")
    if solver["on_budget"] == "accept" and solver["max_iterations"] is None:
        raise SceneError("solver.on_budget = \"accept\" accepts the iterate after "
                         "solver.max_iterations Newton iterations: set solver.max_iterations")
    check_contact_limits(data)


def _check_bodies(data: dict[str, Any]) -> None:
    """``[[body]]``: unique names, one dimension and one kind of mass, each body's own tables."""
    bodies = data["body"]
    d = bodies[0]["mesh"]["dim"]
    seen: dict[str, int] = {}
    for k, body in enumerate(bodies):
        where = f"body[{k}]"
        if body["name"] in seen:
            raise SceneError(f"{where}.name = {body['name']!r} is already used by "
                             f"body[{seen[body['name']]}]")
        seen[body["name"]] = k
        _check_mesh(body["mesh"], f"{where}.mesh")
        if body["mesh"]["dim"] != d:
            raise SceneError(f"{where}.mesh.dim must equal body[0].mesh.dim = {d} (all bodies "
                             f"share one mesh), got {body['mesh']['dim']}")
        if body["material"]["mass"] != bodies[0]["material"]["mass"]:
            raise SceneError(f"{where}.material.mass must equal body[0].material.mass = "
                             f"{bodies[0]['material']['mass']!r} (one mass matrix), got "
                             f"{body['material']['mass']!r}")
        for key, n in (("offset", d), ("rotation", 3 if d == 3 else 1)):
            if body[key] is not None and len(body[key]) != n:
                raise SceneError(f"{where}.{key} must have {n} entries for mesh.dim = {d}, "
                                 f"got {body[key]}")
        _check_pins(body["pin"], d, f"{where}.")
        if "initial" in body:
            _check_initial({"mesh": {"dim": d}, "initial": body["initial"]}, f"{where}.")
        for i, region in enumerate(body["region"]):
            if region["min"] is None or region["max"] is None:
                raise SceneError(f"{where}.region[{i}] ({region['name']}) needs min and max "
                                 "(a box of the body's cells, in scene coordinates)")
        _check_regions({"mesh": {"dim": d}, "region": body["region"],
                        "material": body["material"], "solver": data["solver"]},
                       f"{where}.")
    models = {b["material"]["model"] for b in bodies} | \
        {r["model"] for b in bodies for r in b["region"] if r["model"]}
    if len(models) > 1 and data["solver"]["hessian"] == "project":
        raise SceneError("solver.hessian = \"project\" takes one material model; the bodies "
                         f"use {', '.join(sorted(models))} (use \"shift\")")


def _check_regions(data: dict[str, Any], prefix: str = "") -> None:
    """``[[region]]``: a box (``min`` and ``max``) or a mesh group name; names unique;
    at least one material key; settings the regions' models allow."""
    d = data["mesh"]["dim"]
    seen: dict[str, int] = {}
    for i, region in enumerate(data["region"]):
        where = f"{prefix}region[{i}] ({region['name']})"
        if region["name"] in seen:
            raise SceneError(f"{where}: the name is already used by "
                             f"{prefix}region[{seen[region['name']]}]")
        seen[region["name"]] = i
        lo, hi = region["min"], region["max"]
        if (lo is None) != (hi is None):
            raise SceneError(f"{where}: give both min and max (a box of cells by centroid), or "
                             "neither (the name is then a physical group of the mesh)")
        if lo is not None:
            if len(lo) != d or len(hi) != d:
                raise SceneError(f"{prefix}region[{i}].min and {prefix}region[{i}].max must "
                                 f"have {d} entries "
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


def _check_initial(data: dict[str, Any], prefix: str = "") -> None:
    """``[initial]``: vectors of the mesh dimension; omega a number in 2D, 3 numbers in 3D."""
    if "initial" not in data:
        return
    d, initial = data["mesh"]["dim"], data["initial"]
    for key in ("velocity", "center"):
        if initial[key] is not None and len(initial[key]) != d:
            raise SceneError(f"{prefix}initial.{key} must have {d} entries for mesh.dim = {d}, "
                             f"got {initial[key]}")
    omega = initial["angular_velocity"]
    if d == 2 and isinstance(omega, list):
        raise SceneError(f"{prefix}initial.angular_velocity must be a number (rad/s about z) "
                         "for "
                         f"mesh.dim = 2, got {show_value(omega)}")
    if d == 3 and omega is not None and not (
            isinstance(omega, list) and len(omega) == 3
            and all(isinstance(c, (int, float)) and not isinstance(c, bool) for c in omega)):
        raise SceneError(f"{prefix}initial.angular_velocity must be a list of 3 numbers (the "
                         "angular "
                         f"velocity vector, rad/s) for mesh.dim = 3, got {show_value(omega)}")
    if all(initial[k] is None for k in ("velocity", "angular_velocity")):
        raise SceneError(f"[{prefix}initial] needs velocity or angular_velocity")


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
    """A camera given by position (``render.camera = "fixed"``): the focal point and up vector
    need it, and differ from it.

    Raises:
        SceneError: naming the ``render`` keys.
    """
    position = render["camera_position"]
    camera = render.get("camera")
    if camera == "fixed" and position is None:
        raise SceneError('render.camera = "fixed" needs render.camera_position')
    if camera not in (None, "fixed") and position is not None:
        raise SceneError(f'render.camera_position needs render.camera = "fixed", got '
                         f'"{camera}"')
    for key in ("focal_point", "view_up"):
        if render[key] is not None and position is None:
            raise SceneError(f"render.{key} needs render.camera_position (or use render.view)")
    if position is not None and render["focal_point"] == position:
        raise SceneError(f"render.focal_point must differ from render.camera_position, got "
                         f"{position}")
