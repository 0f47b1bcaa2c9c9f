"""The scene keys: every table and key a scene file may hold, with its type, default, unit,
one-line meaning and constraint.

A scene is TOML data, never code. Tables that describe the body and the run (``mesh``,
``element``, ``material``, ``time``, ``solver``, ``output``, ``render``) fall back key by
key to their defaults (:data:`DEFAULTS`); physical terms (``[gravity]``, ``[damping]``,
``[initial]``, ``[contact]``, ``[[pin]]``, ``[[region]]``, ``[[obstacle]]``) exist only
when a scene declares them. ``[[body]]`` tables describe several bodies, each with its own
``mesh``, ``material``, ``initial``, ``[[body.pin]]`` and ``[[body.region]]``, whose keys are
those of the top-level tables. :func:`scene_keys` lists every key as a :class:`KeyInfo`;
:mod:`fem_anim.scene.validation` checks a scene against :data:`SCHEMA`.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

from fem_anim.scene import constraints as c
from fem_anim.scene.modes import SOLVER_MODES
from fem_anim.scene.shell_rules import shell_bending_value
from fem_anim.solver.hessian_modification import MODES as HESSIAN_MODES

__all__ = ["Key", "KeyInfo", "SCHEMA", "DEFAULTS", "SECTIONS", "OPTIONAL_SECTIONS",
           "ARRAY_SECTIONS", "BODY_TABLES", "BODY_ARRAYS", "REQUIRED", "NUM", "scene_keys",
           "type_text", "MATERIAL_MODELS", "FORMULATIONS", "INTEGRATORS", "MESH_SHAPES",
           "HESSIAN_UPDATES", "NONLINEAR_METHODS", "OBSTACLE_TYPES", "COLOR_FIELDS", "VIEWS",
           "CAMERA_MODES", "RENDER_OUTPUTS", "TRAJECTORY_FIELDS", "SURFACE_FILLS",
           "LENGTH_UNITS"]

MATERIAL_MODELS = ("linear", "stvk", "corotated", "neohookean", "stable_neohookean",
                   "corotated_lagged", "mooney_rivlin")
FORMULATIONS = ("displacement", "mixed")
INTEGRATORS = ("newmark", "implicit_euler", "bdf2", "symplectic_euler")
MESH_SHAPES = ("box", "sphere", "cylinder", "torus", "capsule", "file", "sheet")
#: ``solver.hessian_update``: how often Newton's Hessian is rebuilt
#: (:mod:`fem_anim.solver.hessian_reuse`).
HESSIAN_UPDATES = ("every_iteration", "every_step", "lagged", "rest")
NONLINEAR_METHODS = ("newton", "trust_region", "lbfgs", "ncg", "gradient_descent")
OBSTACLE_TYPES = ("plane", "sphere")
#: ``mesh.fill``: how a surface file becomes tetrahedra (:mod:`fem_anim.mesh.surface_repair`).
SURFACE_FILLS = ("auto", "gmsh", "tetwild")
#: ``mesh.units``: metres per unit of a mesh file's coordinates.
LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "km": 1000.0, "in": 0.0254, "ft": 0.3048}
#: What ``render.color_by`` may name: vertex |displacement|, the cells' mean psi, or one
#: colour per body (the mesh's connected parts: the ``[[body]]`` tables in order).
COLOR_FIELDS = ("displacement", "energy_density", "body")
#: Named camera views (``auto``: ``side`` in 3D, ``xy`` in 2D; :mod:`fem_anim.render.frames`).
VIEWS = ("auto", "side", "iso", "xy", "xz", "yz")
#: What ``render.camera`` may name (:mod:`fem_anim.render.camera`).
CAMERA_MODES = ("fit_bodies", "follow", "fixed")
#: What ``output.fields`` may list (:mod:`fem_anim.output.trajectory`).
TRAJECTORY_FIELDS = ("displacement", "energy_density", "velocity", "pressure")
#: What ``render.outputs`` may list: PNG frames, an animated GIF, an MP4 video.
RENDER_OUTPUTS = ("frames", "gif", "mp4")

NUM = (int, float)


@dataclass(frozen=True)
class Key:
    """One scene key: its type, default, constraint, unit and meaning.

    Attributes:
        kind: The Python type(s) of the TOML value (``NUM``: an integer or a float).
        default: The value when the key is not given; ``None``: required, absent or derived.
        check: The constraint beyond the type (:mod:`fem_anim.scene.constraints`).
        length: The allowed list lengths (a list of numbers), or ``None``.
        choices: The allowed values, or ``None``.
        unit: The SI unit of the value (``""``: a pure number or not a quantity).
        doc: What the key means, one line.
    """

    kind: type | tuple[type, ...]
    default: Any = None
    check: c.Check | None = None
    length: tuple[int, ...] | None = None
    choices: tuple | None = None
    unit: str = ""
    doc: str = ""


V = (2, 3)  # a vector of the mesh dimension
SCHEMA: dict[str, dict[str, Key]] = {
    "": {"name": Key(str, "scene", c.scene_name,
                     doc="the scene's name; names the default output directory out/<name>")},
    "mesh": {
        "shape": Key(str, "box", choices=MESH_SHAPES,
                     doc="a gmsh shape (2D: rectangle, disk, annulus, stadium) or a mesh file"),
        "dim": Key(int, 3, choices=(2, 3), doc="3: tetrahedra; 2: triangles, plane strain"),
        "size": Key(list, [1.0, 0.2, 0.2], c.all_positive, V, unit="m",
                    doc="box edge lengths (dim entries)"),
        "origin": Key(list, None, None, V, unit="m", doc="box: lower corner; sphere, torus: "
                      "centre; cylinder, capsule: centre of the x-min end (default 0)"),
        "radius": Key(NUM, 0.1, c.positive, unit="m", doc="sphere, cylinder, capsule radius; "
                      "torus major radius"),
        "length": Key(NUM, 0.5, c.positive, unit="m", doc="cylinder and capsule length (x)"),
        "minor_radius": Key(NUM, 0.03, c.positive, unit="m",
                            doc="torus tube radius (< radius)"),
        "element_size": Key(NUM, 0.05, c.positive, unit="m", doc="gmsh target edge length"),
        "file": Key(str, None, unit="", doc="shape = \"file\": a volume mesh meshio reads or "
                    "a closed STL/OBJ/PLY surface, relative to the scene file"),
        "fill": Key(str, "auto", choices=SURFACE_FILLS, doc="a surface file's tetrahedra: "
                    "\"auto\" (gmsh if closed and clean, else repaired by fTetWild), "
                    "\"gmsh\", \"tetwild\""),
        "units": Key(str, "m", choices=tuple(LENGTH_UNITS), doc="the length unit of a mesh "
                     "file's coordinates (converted to metres)"),
        "scale": Key(NUM, 1.0, c.positive, doc="a mesh file's coordinates are multiplied by "
                     "scale (after units), about the origin"),
        "divisions": Key(list, None, c.divisions, V, doc="box only: a structured grid of "
                         "cells per axis, cut into simplices (instead of gmsh)"),
        "triangulation": Key(str, "right", choices=("right", "left", "alternate"),
                             doc="sheet: how each square is cut into triangles "
                             "(fem_anim.meshes.sheet)"),
    },
    "element": {
        "degree": Key(int, 1, choices=(1, 2), doc="Lagrange degree of the displacement"),
        "quadrature_degree": Key(int, None, c.in_closed(0, 12, "must be in 0..12"),
                                 doc="quadrature of the elastic energy (default: the degree)"),
        "formulation": Key(str, "displacement", choices=FORMULATIONS,
                           doc="\"mixed\": Taylor-Hood (u, p) for (nearly) incompressible "
                           "solids, poisson_ratio up to 0.5"),
    },
    "material": {
        "model": Key(str, "neohookean", choices=MATERIAL_MODELS,
                     doc="hyperelastic energy density psi(F) (mooney_rivlin: mixed only)"),
        "youngs_modulus": Key(NUM, 1.0e5, c.positive, unit="Pa", doc="Young's modulus E"),
        # 0.5 passes here; the consistency rules admit it with element.formulation = "mixed"
        "poisson_ratio": Key(NUM, 0.3, lambda v: None if v == 0.5 else
                             c.in_open(-1.0, 0.5)(v),
                             doc="Poisson's ratio nu in (-1, 0.5); 0.5 with the mixed form"),
        "density": Key(NUM, 1000.0, c.positive, unit="kg/m^3", doc="mass density rho"),
        "mass": Key(str, "consistent", choices=("consistent", "lumped"),
                    doc="mass matrix: consistent, or lumped row sums (P1 only)"),
        "mooney_ratio": Key(NUM, 0.3, c.in_closed(0, 1, "must be in [0, 1]"),
                            doc="mooney_rivlin: the Mooney ratio r, the share of the shear "
                            "modulus in the I2 term (c01 = r mu / 2)"),
    },
    "time": {
        "integrator": Key(str, "newmark", choices=INTEGRATORS, doc="time integrator"),
        "dt": Key(NUM, 1.0 / 60.0, c.positive, unit="s",
                  doc="the time step; with output.fps, the largest one: each frame interval "
                  "1/output.fps is split into the fewest equal steps no longer than dt"),
        "steps": Key(int, 60, c.steps, doc="the run lasts steps * dt (one frame per step; with "
                     "output.fps, up to the next whole frame)"),
        "adaptive": Key(bool, True, doc="retry a failed step with dt halved, then grow dt "
                        "back"),
        "min_dt": Key(NUM, None, c.positive, unit="s",
                      doc="floor of adaptive halving (default dt/256)"),
    },
    "gravity": {"acceleration": Key(list, None, None, V, unit="m/s^2",
                                    doc="gravitational acceleration g (dim entries)")},
    "damping": {
        "alpha": Key(NUM, 0.0, c.non_negative, unit="1/s",
                     doc="mass-proportional Rayleigh damping: C = alpha M + beta K_0"),
        "beta": Key(NUM, 0.0, c.non_negative, unit="s",
                    doc="stiffness-proportional Rayleigh damping: C = alpha M + beta K_0"),
    },
    "pin": {
        "name": Key(str, "pin", doc="the pin's name in messages"),
        "min": Key(list, None, None, V, unit="m", doc="lower corner of the box of held "
                   "vertices"),
        "max": Key(list, None, None, V, unit="m", doc="upper corner of the box of held "
                   "vertices"),
        "velocity": Key(list, None, None, V, unit="m/s",
                        doc="the held vertices translate at this velocity (a handle)"),
        "angular_velocity": Key(NUM, 0.0, unit="rad/s",
                                doc="the held vertices turn about axis through center"),
        "axis": Key(list, None, None, (3,), doc="rotation axis (3D; required with a "
                    "rotation)"),
        "center": Key(list, None, None, V, unit="m", doc="centre of rotation (default: the "
                      "box centre)"),
        "until": Key(NUM, None, c.non_negative, unit="s",
                     doc="the handle stops moving at this time (default: never)"),
    },
    "region": {
        "name": Key(str, None, doc="a physical group of the mesh, or with min and max a new "
                    "name for a box of cells"),
        "min": Key(list, None, None, V, unit="m", doc="lower corner of the box of cells (by "
                   "centroid)"),
        "max": Key(list, None, None, V, unit="m", doc="upper corner of the box of cells (by "
                   "centroid)"),
        "model": Key(str, None, choices=MATERIAL_MODELS, doc="material.model on the "
                     "region's cells"),
        "youngs_modulus": Key(NUM, None, c.positive, unit="Pa",
                              doc="material.youngs_modulus on the region's cells"),
        "poisson_ratio": Key(NUM, None, c.in_open(-1.0, 0.5),
                             doc="material.poisson_ratio on the region's cells"),
        "density": Key(NUM, None, c.positive, unit="kg/m^3",
                       doc="material.density on the region's cells"),
    },
    "initial": {
        "velocity": Key(list, None, None, V, unit="m/s", doc="initial rigid velocity"),
        "angular_velocity": Key((int, float, list), None, unit="rad/s",
                                doc="initial angular velocity: a number (2D, about z) or a "
                                "vector (3D)"),
        "center": Key(list, None, None, V, unit="m",
                      doc="centre of the rotation (default: the centre of mass)"),
    },
    "obstacle": {  # static obstacles, contact as a barrier energy (forms/obstacle_contact.py)
        "name": Key(str, "obstacle", doc="the obstacle's name in messages"),
        "type": Key(str, None, choices=OBSTACLE_TYPES, doc="a half space or a ball"),
        "point": Key(list, None, None, V, unit="m", doc="plane: a point of the plane "
                     "(default 0)"),
        "normal": Key(list, None, None, V, doc="plane: the normal pointing into the free "
                      "side"),
        "center": Key(list, None, None, V, unit="m", doc="sphere: its centre"),
        "radius": Key(NUM, None, c.positive, unit="m", doc="sphere: its radius"),
        "dhat": Key(NUM, 1.0e-3, c.positive, unit="m", doc="barrier activation distance"),
        "stiffness": Key(NUM, None, c.positive, unit="Pa",
                         doc="barrier stiffness kappa (default: youngs_modulus)"),
        "friction": Key(NUM, 0.0, c.non_negative, doc="Coulomb friction coefficient mu"),
        "epsv": Key(NUM, 1.0e-3, c.positive, unit="m/s",
                    doc="sliding speed below which friction is a stiff viscous stick"),
    },
    "body": {  # one of several bodies (fem_anim/mesh/bodies.py); sub-tables as at the top level
        "name": Key(str, None, c.body_name, doc="the body's name (unique)"),
        "offset": Key(list, None, None, V, unit="m", doc="translation of the body's mesh"),
        "rotation": Key(list, None, None, (1, 3), unit="degrees",
                        doc="rotation of the body's mesh about x, then y, then z (2D: one "
                        "angle)"),
    },
    "shell": {  # a thin shell body: its mid-surface (fem_anim/problem/shell_terms.py)
        "thickness": Key(NUM, None, c.positive, unit="m",
                         doc="shell thickness t: energy t psi per area, area density rho t"),
        "bending": Key((int, float, str), "derived", shell_bending_value, unit="J",
                       doc="hinge stiffness k, 0 for a membrane, or \"derived\": from E, nu "
                       "and the thickness (k = D / 6, D = E t^3 / (12 (1 - nu^2))); with "
                       "bending_model = \"kirchhoff_love\" the rigidity D itself"),
        "bending_model": Key(str, "hinge", choices=("hinge", "kirchhoff_love"),
                             doc="\"hinge\": P1 discrete-shell hinges; \"kirchhoff_love\": "
                             "P2 C0 interior-penalty Kirchhoff-Love (needs element.degree = 2)"),
    },
    "wind": {  # aerodynamic drag on a shell (fem_anim/forms/aerodynamic_drag.py)
        "velocity": Key(list, [0.0, 0.0, 0.0], None, (3,), unit="m/s",
                        doc="the wind's velocity w (zero: still air, drag only)"),
        "drag_coefficient": Key(NUM, 1.2, c.non_negative, doc="C_d of the normal pressure "
                                "drag f = -C_d rho_a |s| s n / 2 per area, s = (v - w) . n"),
        "air_density": Key(NUM, 1.2, c.positive, unit="kg/m^3", doc="rho_a of the drag law"),
    },
    "contact": {  # contact between bodies and of a body with itself (fem_anim/contact/ipc.py)
        "self": Key(bool, True, doc="each body also repels itself"),
        "dhat": Key(NUM, 1.0e-3, c.positive, unit="m", doc="barrier activation distance"),
        "stiffness": Key((int, float, str), "adaptive", c.stiffness, unit="Pa",
                         doc="barrier stiffness kappa, or \"adaptive\" (IPC's schedule)"),
        "friction": Key(NUM, 0.0, c.non_negative, doc="Coulomb friction coefficient mu"),
        "epsv": Key(NUM, 1.0e-3, c.positive, unit="m/s",
                    doc="sliding speed below which friction is a stiff viscous stick"),
    },
    "solver": {
        "mode": Key(str, "exact", choices=tuple(SOLVER_MODES),
                    doc="\"exact\": Newton to convergence; \"preview\": one Newton step per "
                    "frame"),
        "preset": Key(str, "cholesky", doc="linear solver preset (fem-anim solvers lists "
                      "them)"),
        "method": Key(str, "newton", choices=NONLINEAR_METHODS, doc="the minimiser"),
        "stopping": Key(str, "auto", choices=("auto", "norm", "decrement", "step"),
                        doc="residual-norm tests, the Newton decrement, or IPC's step test "
                        "(\"auto\": \"step\" with contact, else \"norm\")"),
        "step_tol": Key(NUM, 1.0e-3, c.positive, unit="1/s",
                        doc="stopping = \"step\": ||Newton step||_inf / dt at most this "
                        "fraction of the scene's bounding-box diagonal per second"),
        "decrement_tol": Key(NUM, 1e-14, c.positive,
                             doc="stopping = \"decrement\": lambda^2/2 at most this, in the "
                             "units of the step objective g"),
        "hessian": Key(str, "exact", choices=HESSIAN_MODES,
                       doc="Newton's Hessian, or a filtered one (when not given, solver.mode "
                       "fills \"auto\" where it applies)"),
        "forcing": Key(str, "tight", choices=("tight", "adaptive"),
                       doc="Krylov tolerance per Newton iteration: fixed, or Eisenstat-Walker"),
        "inversion_filter": Key(bool, None, doc="halve Newton steps that invert an element "
                                "(default: on for neo-Hookean)"),
        "max_iterations": Key(int, None, c.at_least_one,
                              doc="a budget of Newton iterations per step"),
        "on_budget": Key(str, "fail", choices=("fail", "accept"),
                         doc="a step past the budget fails, or is kept if it lowered g"),
        "hessian_update": Key(str, "every_iteration", choices=HESSIAN_UPDATES,
                              doc="how often the Hessian is rebuilt"),
        "hessian_lag": Key(int, 2, c.at_least_one, doc="iterations a \"lagged\" Hessian "
                           "serves"),
        "petsc": Key(dict, {}, c.check_petsc, doc="PETSc options without prefix (nested "
                     "tables flattened)"),
    },
    "output": {
        "directory": Key(str, None, c.output_directory,
                         doc="output directory, relative (default out/<name>; -o wins)"),
        "fps": Key(NUM, None, c.positive, unit="frames/s",
                   doc="frame rate: frame k is the converged state at t = k/fps, whatever "
                   "time.dt is (24: film, Blender, USD); not given: one frame per step"),
        "start_frame": Key(int, 1, c.non_negative, doc="the number of frame 0 (the initial "
                           "state) in USD time codes and file names"),
        "every": Key(int, 1, c.at_least_one, unit="frames", doc="write every n-th frame"),
        "fields": Key(list, ["displacement", "energy_density"],
                      c.distinct_names(TRAJECTORY_FIELDS),
                      doc="the trajectory's fields per frame: displacement and energy_density "
                      "always (a P2 body's displacement at every dof), velocity and a mixed "
                      "run's pressure at every dof when listed"),
        "checkpoint_every": Key(int, None, c.at_least_one, unit="frames",
                                doc="frames between checkpoints (default steps/10)"),
        "render": Key(bool, True, doc="render the run's pictures when it ends"),
        "usd": Key(bool, False, doc="also write <name>.usdc (one time-sampled mesh per body, "
                   "fem_anim.export) when the run ends"),
    },
    "render": {
        "color_by": Key(str, None, choices=COLOR_FIELDS,
                        doc="colour by |u|, by the cells' energy density, or one colour per "
                        "body (default: body with several bodies, else displacement)"),
        "colormap": Key(str, "viridis", c.colormap, doc="a matplotlib colormap name"),
        "view": Key(str, "auto", choices=VIEWS, doc="camera direction, fitted to the run"),
        "camera": Key(str, None, choices=CAMERA_MODES,
                      doc="fit_bodies: one camera framing the bodies over the run; follow: "
                      "tracks them at a fixed distance; fixed: camera_position (default: "
                      "fixed with a camera_position, follow for bodies travelling over twice "
                      "their size, else fit_bodies)"),
        "fov": Key(NUM, 30.0, c.in_open(0.0, 180.0), unit="deg",
                   doc="the camera's vertical view angle"),
        "camera_position": Key(list, None, None, (3,), unit="m", doc="an explicit camera "
                               "position"),
        "focal_point": Key(list, None, None, (3,), unit="m",
                           doc="where the camera looks (default: the run's centre)"),
        "view_up": Key(list, None, c.nonzero_vector, (3,), doc="the camera's up direction "
                       "(default z)"),
        "background": Key(str, "white", c.color, doc="a matplotlib colour or \"#rrggbb\""),
        "window_size": Key(list, [800, 600], c.window_size, (2,), unit="px",
                           doc="picture width and height"),
        "fps": Key(NUM, None, c.fps, unit="frames/s",
                   doc="GIF and MP4 frame rate (default: real time, within 1..60)"),
        "outputs": Key(list, list(RENDER_OUTPUTS), c.distinct_names(RENDER_OUTPUTS),
                       doc="which animations to write ([]: final.png and plots only)"),
        "show_edges": Key(bool, None, doc="draw the surface's cell edges (default: with "
                          "pins, else not)"),
        "ghost": Key(bool, None, doc="draw the rest shape as a grey wireframe (default: with "
                     "pins, where the rest shape is the reference of the deflection)"),
        "obstacles": Key(bool, True, doc="draw the obstacles (planes as tiles under the "
                         "bodies; never one between camera and bodies)"),
        "shadows": Key(bool, False, doc="cast shadows from the key light (VTK shadow maps: "
                       "about twice the time per frame)"),
        "workers": Key(int, None, c.at_least_one, doc="processes rendering frames side by "
                       "side (default 1: the render process alone)"),
    },
}
#: How each table is written in TOML, and what it is, one line.
SECTIONS: dict[str, tuple[str, str]] = {
    "": ("", "top-level keys"),
    "mesh": ("[mesh]", "the body's mesh: a gmsh shape or a file"),
    "element": ("[element]", "the finite element"),
    "material": ("[material]", "the body's hyperelastic material"),
    "time": ("[time]", "time stepping"),
    "gravity": ("[gravity]", "gravity (absent: none)"),
    "damping": ("[damping]", "Rayleigh damping (absent: none)"),
    "pin": ("[[pin]]", "boxes of held vertices, possibly moving (handles)"),
    "region": ("[[region]]", "parts of the mesh with their own material keys"),
    "initial": ("[initial]", "a rigid initial velocity (absent: at rest)"),
    "obstacle": ("[[obstacle]]", "static obstacles with barrier contact"),
    "body": ("[[body]]", "one of several bodies, with its own [body.mesh], [body.material], "
             "[body.initial], [[body.pin]] and [[body.region]] (keys as at the top level); "
             "[body.shell] makes it a thin shell beside solid bodies"),
    "shell": ("[shell]", "a thin shell: the body is a triangle surface in 3D (mesh.shape = "
              "\"sheet\" or a surface file), its membrane and bending energies"),
    "wind": ("[wind]", "wind and aerodynamic drag on a [shell] (absent: none)"),
    "contact": ("[contact]", "IPC contact between surfaces (on by default with several "
                "bodies)"),
    "solver": ("[solver]", "the minimiser of each step and its linear solver"),
    "output": ("[output]", "what is written"),
    "render": ("[render]", "the pictures and animations"),
}
#: Sections that exist only when a scene declares them (physical terms).
OPTIONAL_SECTIONS = ("gravity", "damping", "initial", "contact", "shell", "wind")
#: Sections that are arrays of tables (``[[pin]]``, ``[[region]]``, ``[[obstacle]]``).
ARRAY_SECTIONS = ("pin", "region", "obstacle")
#: Sub-tables of a ``[[body]]``: the top-level sections that describe one body.
BODY_TABLES = ("mesh", "material", "initial", "shell")
BODY_ARRAYS = ("pin", "region")
#: Keys without a default that a declared optional section must give.
REQUIRED = {"gravity": ("acceleration",), "pin": ("min", "max"), "region": ("name",),
            "obstacle": ("type",), "body": ("name",), "shell": ("thickness",)}

DEFAULTS: dict[str, dict[str, Any]] = {
    section: {k: key.default for k, key in keys.items()}
    for section, keys in SCHEMA.items()
    if section not in OPTIONAL_SECTIONS + ARRAY_SECTIONS + ("body",)
}


@dataclass(frozen=True)
class KeyInfo:
    """One scene key as a reader sees it (a row of the scene reference).

    Attributes:
        section: The table's name in :data:`SCHEMA` (``""``: top level).
        table: The table as written in TOML (``"[mesh]"``, ``"[[pin]]"``, ``""``).
        name: The key.
        path: The dotted path of messages and ``--set`` (``"pin[i].min"`` for arrays).
        type: The type in words (``"list of 2 or 3 numbers"``).
        default: The default value; ``None``: none (see ``required``).
        required: Whether a declared table must give it.
        unit: The SI unit (``""``: a pure number or not a quantity).
        choices: The allowed values, or ``None``.
        doc: The meaning, one line.
    """

    section: str
    table: str
    name: str
    path: str
    type: str
    default: Any
    required: bool
    unit: str
    choices: tuple | None
    doc: str


def type_text(key: Key) -> str:
    """A key's type in words: ``"number"``, ``"list of 2 or 3 numbers"``, ..."""
    if key.kind is list and key.length is not None:
        return f"list of {' or '.join(map(str, key.length))} numbers"
    names = {int: "integer", float: "number", str: "string", list: "list", dict: "table",
             bool: "boolean"}
    if isinstance(key.kind, tuple):
        return " or ".join(dict.fromkeys(names[k] for k in key.kind)).replace(
            "integer or number", "number")
    return names[key.kind]


def scene_keys() -> Iterator[KeyInfo]:
    """Every key of a scene file, table by table, in :data:`SCHEMA`'s order.

    The keys of ``[[body]]``'s sub-tables are those of the top-level tables (listed once).

    Yields:
        One :class:`KeyInfo` per key.

    Examples:
        >>> from fem_anim.scene import scene_keys
        >>> key = next(k for k in scene_keys() if k.path == "material.youngs_modulus")
        >>> key.type, key.default, key.unit
        ('number', 100000.0, 'Pa')
    """
    for section, keys in SCHEMA.items():
        table = SECTIONS[section][0]
        for name, key in keys.items():
            prefix = f"{section}[i]." if section in ARRAY_SECTIONS + ("body",) else \
                (f"{section}." if section else "")
            yield KeyInfo(section, table, name, prefix + name, type_text(key), key.default,
                          name in REQUIRED.get(section, ()), key.unit, key.choices, key.doc)
