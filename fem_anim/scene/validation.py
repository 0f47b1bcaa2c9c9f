"""Checking a parsed scene against the key schema, once, at the boundary.

:func:`validate_scene` takes the tables of a scene (parsed TOML, overrides applied, the
solver mode filled in) and returns them complete: unknown tables and keys, wrong types,
NaN/inf, magnitudes over :data:`~fem_anim.scene.constraints.MAX_MAGNITUDE` and values
outside a key's constraint raise :class:`~fem_anim.errors.SceneError` with the dotted key
path, the constraint and the value; absent keys get their defaults (a key given as Python
``None`` counts as absent). The rules between keys then run
(:func:`fem_anim.scene.consistency.check_consistency`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from fem_anim.errors import SceneError
from fem_anim.errors import show_value as _show
from fem_anim.scene.consistency import check_consistency
from fem_anim.scene.contact_integrator import check_integrator, choose_integrator
from fem_anim.scene.constraints import MAX_MAGNITUDE, check_string, key_text
from fem_anim.scene.schema import (ARRAY_SECTIONS, BODY_ARRAYS, BODY_TABLES, NUM,
                                   OPTIONAL_SECTIONS, REQUIRED, SCHEMA, Key)

__all__ = ["validate_scene", "validate_table"]


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
            _check_finite(f"{path}.{key_text(k)}", v)


def validate_table(section: str, table: Any, keys: dict[str, Key], where: str) -> dict:
    """One table: known keys, each of its type, finite, within its constraint.

    Args:
        section: The table's name in :data:`~fem_anim.scene.schema.SCHEMA` (for
            :data:`~fem_anim.scene.schema.REQUIRED`).
        table: The table as parsed.
        keys: The table's schema.
        where: The table's path in messages (``"pin[0]"``, ``"body[1].mesh"``).

    Returns:
        The table with every key, absent ones at their defaults.

    Raises:
        SceneError: for the first bad key, naming its path, the constraint and the value.
    """
    if not isinstance(table, dict):
        raise SceneError(f"{where} must be a table, got {_show(table)}")
    for k in table:
        if k not in keys:
            raise SceneError(f"unknown key {where}.{key_text(k)} (known: {', '.join(keys)})"
                             .replace("unknown key .", "unknown key "))
    out = {}
    for k, key in keys.items():
        path = f"{where}.{k}" if where else k
        if table.get(k) is None:
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
            check_string(path, value)
        if key.length is not None:
            if len(value) not in key.length or not all(
                    isinstance(c, NUM) and not isinstance(c, bool) for c in value):
                raise SceneError(f"{path} must be a list of {' or '.join(map(str, key.length))}"
                                 f" numbers, got {_show(value)}")
        if key.choices is not None and value not in key.choices:
            raise SceneError(f"{path} must be one of {', '.join(map(str, key.choices))}, "
                             f"got {_show(value)}")
        if key.check is not None and (msg := key.check(value)):
            raise SceneError(f"{path} {msg}, got {_show(value)}")
        out[k] = value
    return out


def validate_scene(raw: Mapping[str, Any]) -> dict[str, Any]:
    """A whole scene: every table, then the rules between keys.

    Args:
        raw: The scene's tables as parsed (not modified).

    Returns:
        The complete scene data (every table that applies, every key).

    Raises:
        SceneError: naming the key path, the constraint and the value.
    """
    known = ["name"] + [section for section in SCHEMA if section]
    for name in raw:
        if name not in known:
            raise SceneError(f"unknown section or key {_show(name)} (known: {', '.join(known)})")
    data = validate_table("", {"name": raw["name"]} if "name" in raw else {}, SCHEMA[""], "")
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
            data[section] = [validate_table(section, e, keys, f"{section}[{i}]")
                             for i, e in enumerate(entries)]
        elif section in OPTIONAL_SECTIONS:
            if section in raw:
                data[section] = validate_table(section, raw[section], keys, section)
        else:
            data[section] = validate_table(section, raw.get(section, {}), keys, section)
    if data["body"]:
        data["mesh"] = dict(data["mesh"], dim=data["body"][0]["mesh"]["dim"])
        data["material"] = dict(data["body"][0]["material"])
        if len(data["body"]) > 1 and "contact" not in data:
            data["contact"] = {k: key.default for k, key in SCHEMA["contact"].items()}
    choose_integrator(raw, data)
    check_consistency(data)
    check_integrator(data)
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
                raise SceneError(f"unknown key {where}.{key_text(k)} (known: {known})")
        own = {k: v for k, v in entry.items() if k not in BODY_TABLES + BODY_ARRAYS}
        body = validate_table("body", own, SCHEMA["body"], where)
        for section in BODY_TABLES:
            if section in ("initial", "shell") and section not in entry:
                continue
            body[section] = validate_table(section, entry.get(section, {}), SCHEMA[section],
                                           f"{where}.{section}")
        for section in BODY_ARRAYS:
            items = entry.get(section, [])
            if not isinstance(items, list):
                raise SceneError(f"{where}.{section} must be an array of tables "
                                 f"([[body.{section}]]), got {_show(items)}")
            body[section] = [validate_table(section, e, SCHEMA[section],
                                            f"{where}.{section}[{j}]")
                             for j, e in enumerate(items)]
        bodies.append(body)
    return bodies
