"""Scene files for the tests: base scenes as Python data, written as TOML and loaded.

The tests need many small variations of a few bodies. Instead of a TOML template per test
module, a scene is a dictionary (top-level keys, ``{section: {key: value}}`` tables and
``{array: [{key: value}, ...]}`` arrays of tables, exactly the layout of a scene file),
built from a base (:func:`beam`, :func:`bar`) with :func:`merge`, and written and validated
by :func:`make_scene` through :func:`fem_anim.scene.loading.load_scene` like any scene file.
A key whose value is ``None`` is left out (the scene default applies).

The bases:

* :func:`beam`, the reference beam of the numpy-oracle tests: a box of :data:`LENGTHS`
  (:data:`DIVISIONS` cells in the oracle's mesh, which replaces gmsh's) of a soft material
  (:data:`YOUNGS_MODULUS`, :data:`POISSON_RATIO`, :data:`DENSITY`);
* :func:`bar`, the 1 x 0.1 x 0.1 m bar on gmsh's mesh (element size 0.1), its end face
  x = 0 pinned (:func:`wall_pin`).
"""

from __future__ import annotations

import datetime
import math
from pathlib import Path
from typing import Any

from fem_anim.scene import Scene, load_scene

__all__ = ["DENSITY", "DIVISIONS", "LENGTHS", "POISSON_RATIO", "YOUNGS_MODULUS", "bar", "beam",
           "make_scene", "merge", "scene_toml", "to_toml", "toml_list", "wall_pin"]

#: The reference beam (metres) and its cells per direction in the oracle's box mesh.
LENGTHS = {2: (1.0, 0.25), 3: (1.0, 0.25, 0.25)}
DIVISIONS = {2: (4, 2), 3: (4, 2, 2)}
YOUNGS_MODULUS = 1.0e4  # Pa: soft, the pinned beam sags by ~0.6 m within 20 steps of 1/60 s
POISSON_RATIO = 0.3
DENSITY = 1000.0  # kg/m^3


def _toml_string(s: str) -> str:
    out = []
    for c in s:
        out.append(f"\\u{ord(c):04x}" if ord(c) < 32 or c in '"\\\x7f' else c)
    return '"' + "".join(out) + '"'


def to_toml(value: Any) -> str:
    """Inline TOML of a value (top level: ``key = value`` lines); floats keep nan/inf/-0.0."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else str(value)
    if isinstance(value, str):
        return _toml_string(value)
    if isinstance(value, (datetime.datetime, datetime.date, datetime.time)):
        return value.isoformat()
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(to_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_toml_string(k)} = {to_toml(v)}" for k, v in value.items()) + "}"
    raise TypeError(type(value))


def toml_list(values) -> str:
    """A TOML list of floats (``[1.0, 0.25]``)."""
    return to_toml([float(v) for v in values])


def _table(header: str, table: dict) -> list[str]:
    return [header] + [f"{k} = {to_toml(v)}" for k, v in table.items() if v is not None]


def scene_toml(scene: dict) -> str:
    """The TOML text of a scene dictionary: top-level keys, ``[tables]``, ``[[arrays]]``."""
    lines = [f"{k} = {to_toml(v)}" for k, v in scene.items()
             if v is not None and not isinstance(v, (dict, list))]
    for k, v in scene.items():
        if isinstance(v, dict):
            lines += _table(f"[{k}]", v)
        elif isinstance(v, list):
            for entry in v:
                lines += _table(f"[[{k}]]", entry)
    return "\n".join(lines) + "\n"


def merge(base: dict, **overrides: Any) -> dict:
    """``base`` with tables updated key by key; other values (arrays, top level) replaced."""
    out = dict(base)
    for k, v in overrides.items():
        out[k] = out[k] | v if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def make_scene(directory: Path, scene: dict, tail: str = "") -> Scene:
    """Write ``<directory>/<name>.toml`` (``tail``: raw TOML appended) and load it."""
    path = Path(directory) / f"{scene['name']}.toml"
    path.write_text(scene_toml(scene) + tail)
    return load_scene(path)


def beam(name: str, d: int, **overrides: Any) -> dict:
    """The reference beam (its ``[mesh]`` is validated; the tests build the oracle's mesh)."""
    base = {
        "name": name,
        "mesh": {"dim": d, "size": [float(v) for v in LENGTHS[d]], "element_size": 0.25},
        "material": {"youngs_modulus": YOUNGS_MODULUS, "poisson_ratio": POISSON_RATIO,
                     "density": DENSITY},
    }
    return merge(base, **overrides)


def wall_pin(d: int = 3) -> dict:
    """A ``[[pin]]`` fixing the face x = 0."""
    return {"name": "wall", "min": [-1e-6] + [-1.0] * (d - 1), "max": [1e-6] + [1.0] * (d - 1)}


def bar(name: str, **overrides: Any) -> dict:
    """The 1 x 0.1 x 0.1 m bar, pinned at x = 0 (gmsh mesh, element size 0.1)."""
    base = {"name": name, "mesh": {"size": [1.0, 0.1, 0.1], "element_size": 0.1},
            "pin": [wall_pin()]}
    return merge(base, **overrides)
