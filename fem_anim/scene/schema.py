"""Scene files: schema, defaults, validation and ``--set`` overrides (STYLE rule 8).

A scene is TOML data, never code. :func:`load_scene` parses it, applies
``--set KEY=VALUE`` overrides and validates everything before anything is built:
unknown keys, wrong types and nonphysical values raise :class:`SceneError` with the
dotted key path, the constraint and the value.

Sections describing the body and the run (``mesh``, ``element``, ``material``,
``time``, ``solver``, ``output``) fall back key by key to :data:`DEFAULTS`; physical
terms (``gravity``, ``pin``, ``obstacle``) exist only when the scene declares them.
``[[region]]`` entries override the body's ``[material]`` on parts of the mesh
(:mod:`fem_anim.mesh.regions`); ``[initial]`` gives the body a rigid initial velocity
(:mod:`fem_anim.simulation.initial_state`). ``[[body]]`` tables describe several bodies, each with its
own ``mesh``, ``material``, ``initial``, ``[[body.pin]]`` and ``[[body.region]]``
(:mod:`fem_anim.mesh.bodies`); ``[contact]`` makes surfaces repel each other
(:mod:`fem_anim.contact.ipc`). Rules between keys (lengths match ``mesh.dim``, boxes are not
empty, settings are compatible) are checked after each key's own, in
:mod:`fem_anim.scene.consistency`.
"""

from __future__ import annotations

import errno
import math
import os
import re
import stat
import tomllib
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

from fem_anim.errors import SceneError
from fem_anim.errors import show_value as _show
from fem_anim.solver.hessian_modification import MODES as HESSIAN_MODES
from fem_anim.scene.consistency import check_consistency, check_render
from fem_anim.scene.modes import SOLVER_MODES, apply_solver_mode

__all__ = ["Scene", "load_scene", "parse_override", "validate_render", "DEFAULTS", "SCHEMA",
           "default_scene_text"]

MATERIAL_MODELS = ("linear", "stvk", "corotated", "neohookean", "stable_neohookean",
                   "corotated_lagged", "mooney_rivlin")
FORMULATIONS = ("displacement", "mixed")
INTEGRATORS = ("newmark", "implicit_euler", "bdf2", "symplectic_euler")
MESH_SHAPES = ("box", "sphere", "cylinder", "torus", "capsule", "file")
#: ``solver.hessian_update``: how often Newton's Hessian is rebuilt (fem_anim/solver/hessian_reuse.py).
HESSIAN_UPDATES = ("every_iteration", "every_step", "lagged", "rest")
NONLINEAR_METHODS = ("newton", "trust_region", "lbfgs", "ncg", "gradient_descent")
OBSTACLE_TYPES = ("plane", "sphere")
MAX_MAGNITUDE = 1.0e150  # larger values are taken as a typo or an attack, not physics
MAX_STEPS = 10**9  # frames; more is a typo (at 60 frames/s, 190 days of animation)
MAX_FILE_BYTES = 1 << 20  # a scene is a page of TOML; refuse to slurp anything bigger
MAX_STRING = 1024  # characters in any string value (paths included)
#: ``name`` becomes the directory ``out/<name>``: one file-name-safe token, no separators.
NAME_PATTERN = re.compile(r"\w[\w.-]{0,99}")
#: PETSc option names (the parts joined by ``_`` when ``[solver.petsc]`` is flattened).
PETSC_KEY = re.compile(r"[A-Za-z0-9_]+")
#: PETSc viewers that write files or open connections: a scene may not name them
#: (``ksp_view_mat = "binary:/elsewhere"``); the command line may.
PETSC_WRITING_VIEWERS = ("binary", "hdf5", "vtk", "vtu", "matlab", "socket", "saws", "adios",
                         "exodusii", "glvis", "mathematica", "pythonviewer")


@dataclass(frozen=True)
class Key:
    """One scene key: its type, default (``None``: required or derived) and constraint."""

    kind: type | tuple[type, ...]
    default: Any = None
    check: Callable[[Any], str | None] | None = None
    length: tuple[int, ...] | None = None  # allowed list lengths


def _positive(v) -> str | None:
    return None if v > 0 else "must be > 0"


def _non_negative(v) -> str | None:
    return None if v >= 0 else "must be >= 0"


def _one_of(options) -> Callable[[Any], str | None]:
    return lambda v: None if v in options else f"must be one of {', '.join(map(str, options))}"


def _in_open(lo, hi) -> Callable[[Any], str | None]:
    return lambda v: None if lo < v < hi else f"must be in ({lo}, {hi})"


def _all_positive(v) -> str | None:
    return None if all(c > 0 for c in v) else "must have all entries > 0"


def _divisions(v) -> str | None:
    ok = all(isinstance(c, int) and not isinstance(c, bool) and c >= 1 for c in v)
    return None if ok else "must have all entries whole numbers >= 1"


def _steps(v) -> str | None:
    if v < 1:
        return "must be >= 1"
    return None if v <= MAX_STEPS else f"must be at most {MAX_STEPS}"


def _stiffness(v) -> str | None:
    if isinstance(v, str):
        return None if v == "adaptive" else "must be a number of Pa or \"adaptive\""
    return _positive(v)


def _scene_name(v) -> str | None:
    return None if NAME_PATTERN.fullmatch(v) else (
        "must be a simple file name (letters, digits, '_', '-', '.'; not starting with '.' "
        "or '-'; at most 100 characters), since it names the output directory out/<name>")


def symlink_loops(path: Path) -> bool:
    """Whether ``path`` or one of its parents is a symbolic link that never resolves.

    ``Path.resolve()`` raised on a loop up to Python 3.12 and returns the path as it stands
    from 3.13 on, so the loop is found by asking the OS: ``stat`` of a link in a loop fails
    with ELOOP on every Python.
    """
    for prefix in (path, *path.parents):
        if prefix.is_symlink():
            try:
                os.stat(prefix)
            except OSError as err:
                if err.errno == errno.ELOOP:
                    return True
    return False


def _output_directory(v) -> str | None:
    """A scene may only write below the working directory (``-o`` may write anywhere)."""
    if not v or os.path.isabs(v) or v.startswith("~"):
        return "must be a relative path inside the working directory"
    parts = os.path.normpath(v).split(os.sep)
    if parts[0] == ".." or ".." in parts:
        return "must not leave the working directory (a scene cannot make the program " \
               "write outside its output directory; use -o)"
    cwd = Path.cwd().resolve()
    if symlink_loops(cwd / v):
        return "must be a path that resolves (a symbolic link loops)"
    try:
        inside = (cwd / v).resolve().is_relative_to(cwd)
    except (OSError, RuntimeError):  # a loop, on Pythons before 3.13 (3.13 does not raise)
        return "must be a path that resolves (a symbolic link loops)"
    if not inside:  # through a symbolic link
        return "must not leave the working directory (it resolves outside it through a " \
               "symbolic link; use -o)"
    return None


def _check_petsc(table: dict, path: str = "solver.petsc") -> None:
    """PETSc options: identifier names; string, finite number or boolean values.

    A viewer that writes files (``ksp_view_mat = "binary:/elsewhere"``, ``"ascii:log.txt"``)
    is refused: a scene cannot make the program write outside its output directory.
    """
    for k, value in table.items():
        where = f"{path}.{_key(k)}"
        if not PETSC_KEY.fullmatch(k):
            raise SceneError(f"{where}: PETSc option names are letters, digits and '_'")
        if isinstance(value, dict):
            _check_petsc(value, where)
        elif not isinstance(value, (str, int, float)):  # bool is an int
            raise SceneError(f"{where} must be a string, a number or true/false, "
                             f"got {_show(value)}")
        elif isinstance(value, str):
            _check_string(where, value)
            try:
                number = float(value)
            except ValueError:
                number = 0.0
            if not math.isfinite(number):
                raise SceneError(f"{where} must be finite, got {_show(value)}")
            viewer, _, rest = value.partition(":")
            if viewer.strip().lower() in PETSC_WRITING_VIEWERS or rest.partition(":")[0]:
                raise SceneError(f"{where} must not name a PETSc viewer that writes files "
                                 "(give it on the command line), got " + _show(value))


def _key(k: str) -> str:
    """A key as written in a dotted path; odd keys (spaces, newlines, ...) are quoted."""
    return k if re.fullmatch(r"[\w-]{1,64}", k) else _show(k)


def _check_string(path: str, value: str) -> None:
    if len(value) > MAX_STRING:
        raise SceneError(f"{path} must be at most {MAX_STRING} characters, got {_show(value)}")
    if any(ord(c) < 32 or ord(c) == 127 for c in value):
        raise SceneError(f"{path} must not contain control characters, got {_show(value)}")


#: What ``render.color_by`` may name: vertex |displacement|, the cells' mean psi, or one
#: colour per body (the mesh's connected parts: the ``[[body]]`` tables in order).
COLOR_FIELDS = ("displacement", "energy_density", "body")
#: Named camera views (``auto``: ``side`` in 3D, ``xy`` in 2D; see fem_anim/render/process.py).
VIEWS = ("auto", "side", "iso", "xy", "xz", "yz")
#: What ``render.outputs`` may list: PNG frames, an animated GIF, an MP4 video.
RENDER_OUTPUTS = ("frames", "gif", "mp4")


def _colormap(v) -> str | None:
    import matplotlib  # only when a scene names a colormap: the default costs no import

    if v in matplotlib.colormaps:
        return None
    close = [name for name in matplotlib.colormaps if name.lower() == v.lower()]
    hint = f" (did you mean {close[0]!r}?)" if close else " (see matplotlib's colormap list)"
    return "must be a matplotlib colormap name" + hint


def _color(v) -> str | None:
    import matplotlib.colors

    return None if matplotlib.colors.is_color_like(v) else \
        "must be a colour name or '#rrggbb' (matplotlib's colour names)"


def _window_size(v) -> str | None:
    ok = all(isinstance(c, int) and 16 <= c <= 4096 for c in v)
    return None if ok else "must be two whole numbers of pixels in 16..4096"


def _fps(v) -> str | None:
    return None if 0 < v <= 240 else "must be in (0, 240] frames per second"


def _outputs(v) -> str | None:
    ok = all(isinstance(c, str) for c in v) and set(v) <= set(RENDER_OUTPUTS) and \
        len(set(v)) == len(v)
    return None if ok else f"must be a list of distinct names from {', '.join(RENDER_OUTPUTS)}"


NUM = (int, float)
SCHEMA: dict[str, dict[str, Key]] = {
    "": {"name": Key(str, "scene", _scene_name)},
    "mesh": {
        "shape": Key(str, "box", _one_of(MESH_SHAPES)),
        "dim": Key(int, 3, _one_of((2, 3))),
        "size": Key(list, [1.0, 0.2, 0.2], _all_positive, (2, 3)),
        "origin": Key(list, None, None, (2, 3)),
        "radius": Key(NUM, 0.1, _positive),
        "length": Key(NUM, 0.5, _positive),
        "minor_radius": Key(NUM, 0.03, _positive),
        "element_size": Key(NUM, 0.05, _positive),
        "file": Key(str, None),
        "divisions": Key(list, None, _divisions, (2, 3)),
    },
    "element": {
        "degree": Key(int, 1, _one_of((1, 2))),
        "quadrature_degree": Key(int, None, lambda v: None if 0 <= v <= 12 else
                                 "must be in 0..12"),
        "formulation": Key(str, "displacement", _one_of(FORMULATIONS)),
    },
    "material": {
        "model": Key(str, "neohookean", _one_of(MATERIAL_MODELS)),
        "youngs_modulus": Key(NUM, 1.0e5, _positive),
        # 0.5 passes here; scene_consistency admits it with element.formulation = "mixed" only
        "poisson_ratio": Key(NUM, 0.3, lambda v: None if v == 0.5 else
                             _in_open(-1.0, 0.5)(v)),
        "density": Key(NUM, 1000.0, _positive),
        "mass": Key(str, "consistent", _one_of(("consistent", "lumped"))),
        "mooney_ratio": Key(NUM, 0.3, lambda v: None if 0 <= v <= 1 else "must be in [0, 1]"),
    },
    "time": {
        "integrator": Key(str, "newmark", _one_of(INTEGRATORS)),
        "dt": Key(NUM, 1.0 / 60.0, _positive),
        "steps": Key(int, 60, _steps),
        "adaptive": Key(bool, True),
        "min_dt": Key(NUM, None, _positive),
    },
    "gravity": {"acceleration": Key(list, None, None, (2, 3))},
    "damping": {
        "alpha": Key(NUM, 0.0, _non_negative),
        "beta": Key(NUM, 0.0, _non_negative),
    },
    "pin": {
        "name": Key(str, "pin"),
        "min": Key(list, None, None, (2, 3)),
        "max": Key(list, None, None, (2, 3)),
        "velocity": Key(list, None, None, (2, 3)),
        "angular_velocity": Key(NUM, 0.0),
        "axis": Key(list, None, None, (3,)),
        "center": Key(list, None, None, (2, 3)),
        "until": Key(NUM, None, _non_negative),
    },
    "region": {
        "name": Key(str, None),
        "min": Key(list, None, None, (2, 3)),
        "max": Key(list, None, None, (2, 3)),
        "model": Key(str, None, _one_of(MATERIAL_MODELS)),
        "youngs_modulus": Key(NUM, None, _positive),
        "poisson_ratio": Key(NUM, None, _in_open(-1.0, 0.5)),
        "density": Key(NUM, None, _positive),
    },
    "initial": {
        "velocity": Key(list, None, None, (2, 3)),
        "angular_velocity": Key((int, float, list), None),
        "center": Key(list, None, None, (2, 3)),
    },
    "obstacle": {  # static obstacles, contact as a barrier energy (forms/obstacle_contact.py)
        "name": Key(str, "obstacle"),
        "type": Key(str, None, _one_of(OBSTACLE_TYPES)),
        "point": Key(list, None, None, (2, 3)),
        "normal": Key(list, None, None, (2, 3)),
        "center": Key(list, None, None, (2, 3)),
        "radius": Key(NUM, None, _positive),
        "dhat": Key(NUM, 1.0e-3, _positive),
        "stiffness": Key(NUM, None, _positive),
        "friction": Key(NUM, 0.0, _non_negative),
        "epsv": Key(NUM, 1.0e-3, _positive),
    },
    "body": {  # one of several bodies (fem_anim/mesh/bodies.py); sub-tables as at the top level
        "name": Key(str, None, lambda v: None if NAME_PATTERN.fullmatch(v) else
                    "must be a simple name (letters, digits, '_', '-', '.'; at most 100 "
                    "characters)"),
        "offset": Key(list, None, None, (2, 3)),
        "rotation": Key(list, None, None, (1, 3)),
    },
    "contact": {  # contact between bodies and of a body with itself (fem_anim/contact/ipc.py)
        "self": Key(bool, True),
        "dhat": Key(NUM, 1.0e-3, _positive),
        "stiffness": Key((int, float, str), "adaptive", _stiffness),
        "friction": Key(NUM, 0.0, _non_negative),
        "epsv": Key(NUM, 1.0e-3, _positive),
    },
    "solver": {
        "mode": Key(str, "exact", _one_of(SOLVER_MODES)),
        "preset": Key(str, "cholesky"),
        "method": Key(str, "newton", _one_of(NONLINEAR_METHODS)),
        "stopping": Key(str, "norm", _one_of(("norm", "decrement"))),
        "decrement_tol": Key(NUM, 1e-14, _positive),
        "hessian": Key(str, "exact", _one_of(HESSIAN_MODES)),
        "forcing": Key(str, "tight", _one_of(("tight", "adaptive"))),
        "inversion_filter": Key(bool, None),
        "max_iterations": Key(int, None, lambda v: None if v >= 1 else "must be >= 1"),
        "on_budget": Key(str, "fail", _one_of(("fail", "accept"))),
        "hessian_update": Key(str, "every_iteration", _one_of(HESSIAN_UPDATES)),
        "hessian_lag": Key(int, 2, lambda v: None if v >= 1 else "must be >= 1"),
        "petsc": Key(dict, {}, _check_petsc),
    },
    "output": {
        "directory": Key(str, None, _output_directory),
        "every": Key(int, 1, lambda v: None if v >= 1 else "must be >= 1"),
        "checkpoint_every": Key(int, None, lambda v: None if v >= 1 else "must be >= 1"),
        "render": Key(bool, True),
    },
    "render": {
        "color_by": Key(str, "displacement", _one_of(COLOR_FIELDS)),
        "colormap": Key(str, "viridis", _colormap),
        "view": Key(str, "auto", _one_of(VIEWS)),
        "camera_position": Key(list, None, None, (3,)),
        "focal_point": Key(list, None, None, (3,)),
        "view_up": Key(list, None, lambda v: None if any(v) else "must not be the zero vector",
                       (3,)),
        "background": Key(str, "white", _color),
        "window_size": Key(list, [800, 600], _window_size, (2,)),
        "fps": Key(NUM, None, _fps),
        "outputs": Key(list, list(RENDER_OUTPUTS), _outputs),
        "show_edges": Key(bool, True),
    },
}
#: Sections that exist only when a scene declares them (physical terms).
OPTIONAL_SECTIONS = ("gravity", "damping", "initial", "contact")
#: Sections that are arrays of tables (``[[pin]]``, ``[[region]]``, ``[[obstacle]]``).
ARRAY_SECTIONS = ("pin", "region", "obstacle")
#: Sub-tables of a ``[[body]]``: the top-level sections that describe one body.
BODY_TABLES = ("mesh", "material", "initial")
BODY_ARRAYS = ("pin", "region")
#: Keys without a default that a declared optional section must give.
REQUIRED = {"gravity": ("acceleration",), "pin": ("min", "max"), "region": ("name",),
            "obstacle": ("type",), "body": ("name",)}

DEFAULTS: dict[str, dict[str, Any]] = {
    section: {k: key.default for k, key in keys.items()}
    for section, keys in SCHEMA.items()
    if section not in OPTIONAL_SECTIONS + ARRAY_SECTIONS + ("body",)
}


@dataclass
class Scene:
    """A validated scene: plain nested dictionaries plus where it came from."""

    data: dict[str, Any]
    source: str = "<default scene>"
    base_dir: Path = field(default_factory=Path.cwd)

    def __getitem__(self, section: str) -> Any:
        return self.data[section]

    def get(self, section: str, default: Any = None) -> Any:
        return self.data.get(section, default)

    @property
    def name(self) -> str:
        return self.data["name"]

    @property
    def dim(self) -> int:
        return self.data["mesh"]["dim"]

    @property
    def damped(self) -> bool:
        """A ``[damping]`` section with a positive coefficient (alpha = beta = 0: no term)."""
        damping = self.data.get("damping")
        return damping is not None and (damping["alpha"] > 0 or damping["beta"] > 0)


def default_scene_text() -> str:
    """The TOML text of the embedded default scene (the hanging beam)."""
    return resources.files("fem_anim").joinpath("default_scene.toml").read_text()


def parse_override(text: str) -> tuple[list[str], Any]:
    """Parse one ``--set KEY=VALUE``; the value is TOML, a bare word is taken as a string."""
    if "=" not in text:
        raise SceneError(f"--set expects KEY=VALUE, got {text!r}")
    key, raw = text.split("=", 1)
    path = key.strip().split(".")
    if not all(re.fullmatch(r"[\w-]+", part) for part in path):
        raise SceneError(f"--set key {key!r} is not a dotted key path")
    try:
        value = _parse_toml(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        if raw.strip().replace("_", "").replace("-", "").isalnum():
            value = raw.strip()
        else:
            raise SceneError(f"--set {key}: value {raw!r} is not valid TOML") from None
    return path, value


def _apply_override(data: dict, path: list[str], value: Any) -> None:
    node = data
    for i, part in enumerate(path[:-1]):
        if isinstance(node, list):
            if not part.isdecimal():
                raise SceneError(f"--set {'.'.join(path)}: {'.'.join(path[:i])} is a list; "
                                 f"give an entry number, e.g. {'.'.join(path[:i])}.0")
            idx = int(part)
            if idx >= len(node):
                raise SceneError(f"--set {'.'.join(path)}: there is no entry {idx} in "
                                 f"{'.'.join(path[:i])}")
            node = node[idx]
            if not isinstance(node, (dict, list)):
                raise SceneError(f"--set {'.'.join(path)}: {'.'.join(path[:i + 1])} is not a "
                                 "table")
            continue
        nxt = node.setdefault(part, {})
        if not isinstance(nxt, (dict, list)):
            raise SceneError(f"--set {'.'.join(path)}: {'.'.join(path[:i + 1])} is not a table")
        node = nxt
    if not isinstance(node, dict):
        raise SceneError(f"--set {'.'.join(path)}: cannot set a key inside a list")
    node[path[-1]] = value


def _type_name(kind) -> str:
    names = {int: "an integer", float: "a number", str: "a string", list: "a list",
             dict: "a table", bool: "true or false"}
    if isinstance(kind, tuple):
        return "a number"
    return names.get(kind, kind.__name__)


def _check_finite(path: str, value: Any) -> None:
    if isinstance(value, bool):
        return
    if isinstance(value, (int, float)):
        if isinstance(value, float) and not math.isfinite(value):
            raise SceneError(f"{path} must be finite, got {value}")
        if abs(value) > MAX_MAGNITUDE:
            shown = f"{value:g}" if isinstance(value, float) else _show(value)
            raise SceneError(f"{path} must be at most {MAX_MAGNITUDE:g} in magnitude, "
                             f"got {shown}")
        if value and abs(value) < 1.0 / MAX_MAGNITUDE:  # dt / 256 would underflow to 0
            raise SceneError(f"{path} must be 0 or at least {1.0 / MAX_MAGNITUDE:g} in "
                             f"magnitude, got {value:g}")
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_finite(f"{path}[{i}]", v)
    elif isinstance(value, dict):
        for k, v in value.items():
            _check_finite(f"{path}.{_key(k)}", v)


def _validate_table(section: str, table: Any, keys: dict[str, Key], where: str) -> dict:
    if not isinstance(table, dict):
        raise SceneError(f"{where} must be a table, got {_show(table)}")
    for k in table:
        if k not in keys:
            raise SceneError(f"unknown key {where}.{_key(k)} (known: {', '.join(keys)})".replace(
                "unknown key .", "unknown key "))
    out = {}
    for k, key in keys.items():
        path = f"{where}.{k}" if where else k
        if k not in table:
            if section in REQUIRED and k in REQUIRED[section]:
                raise SceneError(f"{path} is required")
            out[k] = key.default
            continue
        value = table[k]
        ok = isinstance(value, key.kind) and not (isinstance(value, bool) and key.kind is not bool)
        if key.kind is NUM and isinstance(value, bool):
            ok = False
        if not ok:
            raise SceneError(f"{path} must be {_type_name(key.kind)}, got {_show(value)}")
        _check_finite(path, value)
        if isinstance(value, str):
            _check_string(path, value)
        if key.length is not None:
            if len(value) not in key.length or not all(
                    isinstance(c, NUM) and not isinstance(c, bool) for c in value):
                raise SceneError(f"{path} must be a list of {' or '.join(map(str, key.length))}"
                                 f" numbers, got {_show(value)}")
        if key.check is not None and (msg := key.check(value)):
            raise SceneError(f"{path} {msg}, got {_show(value)}")
        out[k] = value
    return out


def _validate(raw: Mapping[str, Any]) -> dict[str, Any]:
    known = ["name"] + [section for section in SCHEMA if section]
    for name in raw:
        if name not in known:
            raise SceneError(f"unknown section or key {_show(name)} (known: {', '.join(known)})")
    data = _validate_table("", {"name": raw["name"]} if "name" in raw else {}, SCHEMA[""], "")
    for section, keys in SCHEMA.items():
        if not section:
            continue
        if section == "body":
            data["body"] = _validate_bodies(raw)
        elif section in ARRAY_SECTIONS:
            entries = raw.get(section, [])
            if not isinstance(entries, list):
                raise SceneError(f"{section} must be an array of tables ([[{section}]]), "
                                 f"got {_show(entries)}")
            data[section] = [_validate_table(section, e, keys, f"{section}[{i}]")
                             for i, e in enumerate(entries)]
        elif section in OPTIONAL_SECTIONS:
            if section in raw:
                data[section] = _validate_table(section, raw[section], keys, section)
        else:
            data[section] = _validate_table(section, raw.get(section, {}), keys, section)
    if data["body"]:
        data["mesh"] = dict(data["mesh"], dim=data["body"][0]["mesh"]["dim"])
        data["material"] = dict(data["body"][0]["material"])
        if len(data["body"]) > 1 and "contact" not in data:
            data["contact"] = {k: key.default for k, key in SCHEMA["contact"].items()}
    check_consistency(data)
    return data


def _validate_bodies(raw: Mapping[str, Any]) -> list[dict[str, Any]]:
    """``[[body]]`` tables: their own keys, then each sub-table with its top-level schema.

    With bodies the top-level tables that describe one body may not be given (their
    meaning would be ambiguous): each body carries its own.
    """
    entries = raw.get("body", [])
    if not isinstance(entries, list):
        raise SceneError(f"body must be an array of tables ([[body]]), got {_show(entries)}")
    if entries:
        for section in BODY_TABLES + BODY_ARRAYS:
            if section in raw:
                raise SceneError(f"{section} must not be given at the top level with [[body]] "
                                 f"tables: give it in each body (body[i].{section})")
    bodies = []
    for i, entry in enumerate(entries):
        where = f"body[{i}]"
        if not isinstance(entry, dict):
            raise SceneError(f"{where} must be a table, got {_show(entry)}")
        for k in entry:
            if k not in SCHEMA["body"] and k not in BODY_TABLES + BODY_ARRAYS:
                known = ", ".join([*SCHEMA["body"], *BODY_TABLES, *BODY_ARRAYS])
                raise SceneError(f"unknown key {where}.{_key(k)} (known: {known})")
        own = {k: v for k, v in entry.items() if k not in BODY_TABLES + BODY_ARRAYS}
        body = _validate_table("body", own, SCHEMA["body"], where)
        for section in BODY_TABLES:
            if section == "initial" and section not in entry:
                continue
            body[section] = _validate_table(section, entry.get(section, {}), SCHEMA[section],
                                            f"{where}.{section}")
        for section in BODY_ARRAYS:
            items = entry.get(section, [])
            if not isinstance(items, list):
                raise SceneError(f"{where}.{section} must be an array of tables "
                                 f"([[body.{section}]]), got {_show(items)}")
            body[section] = [_validate_table(section, e, SCHEMA[section], f"{where}.{section}[{j}]")
                             for j, e in enumerate(items)]
        bodies.append(body)
    return bodies


def _parse_toml(text: str) -> dict[str, Any]:
    """``tomllib.loads``, with its non-TOML failures turned into ``TOMLDecodeError``."""
    try:
        return tomllib.loads(text)
    except RecursionError:
        raise tomllib.TOMLDecodeError("arrays or tables nested too deeply") from None
    except ValueError as err:  # an integer longer than Python converts (4300 digits)
        if isinstance(err, tomllib.TOMLDecodeError):
            raise
        raise tomllib.TOMLDecodeError(f"a number has too many digits ({err})".split(
            "; use sys.set_int_max_str_digits")[0]) from None


def _read_scene_file(p: Path) -> str:
    """The text of a scene file: a regular UTF-8 file of at most ``MAX_FILE_BYTES``."""
    try:
        mode = p.stat().st_mode
    except FileNotFoundError:
        raise SceneError(f"scene file {p} does not exist") from None
    except OSError as err:
        raise SceneError(f"scene file {p} cannot be read: {err.strerror}") from None
    if stat.S_ISDIR(mode):
        raise SceneError(f"scene file {p} is a directory")
    if not stat.S_ISREG(mode):  # a FIFO or device would block or never end
        raise SceneError(f"scene file {p} is not a regular file")
    try:
        with open(p, "rb") as f:
            data = f.read(MAX_FILE_BYTES + 1)
    except OSError as err:
        raise SceneError(f"scene file {p} cannot be read: {err.strerror}") from None
    if len(data) > MAX_FILE_BYTES:
        raise SceneError(f"scene file {p} is larger than {MAX_FILE_BYTES} bytes: not a scene")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise SceneError(f"scene file {p} is not UTF-8 text (byte {err.start}: "
                         f"{data[err.start:err.start + 1]!r})") from None
    return text


def load_scene(path: str | Path | None = None, overrides: list[str] = ()) -> Scene:
    """Read, override and validate a scene; ``path=None`` gives the default scene.

    Raises:
        SceneError: naming the file, key path, constraint and value.
    """
    if path is None:
        text, source, base = default_scene_text(), "<default scene>", Path.cwd()
    else:
        p = Path(path)
        text = _read_scene_file(p)
        source, base = str(p), p.resolve().parent
    try:
        raw = _parse_toml(text)
    except tomllib.TOMLDecodeError as err:
        raise SceneError(f"scene file {source} is not valid TOML: {err}") from None
    if not raw and path is not None:  # an empty file is a mistake, not the defaults
        raise SceneError(f"scene file {source} is empty (no keys)")
    for item in overrides:
        key_path, value = parse_override(item)
        _apply_override(raw, key_path, value)
    apply_solver_mode(raw)  # solver.mode fills the solver keys the scene left out
    try:
        data = _validate(raw)
    except SceneError as err:
        raise SceneError(f"{source}: {err}") from None
    return Scene(data=data, source=source, base_dir=base)


def validate_render(saved: Mapping[str, Any] | None, overrides: list[str] = ()) -> dict[str, Any]:
    """The ``[render]`` settings of a saved run, with ``--set render.KEY=VALUE`` applied.

    ``fem-anim render OUTDIR`` re-renders a run with the settings it was run with
    (``scene.json``), changed only by ``render.*`` overrides: the simulation is not redone,
    so other keys cannot change.

    Raises:
        SceneError: for an override outside ``render``, or a bad value (naming the key).
    """
    table = {"render": {k: v for k, v in (saved or {}).items() if v is not None}}
    for item in overrides:
        path, value = parse_override(item)
        if path[0] != "render" or len(path) != 2:
            raise SceneError(f"--set {'.'.join(path)}: only render.* keys can change when a "
                             "saved run is rendered again (run the scene to change others)")
        _apply_override(table, path, value)
    render = _validate_table("render", table["render"], SCHEMA["render"], "render")
    check_render(render)
    return render
