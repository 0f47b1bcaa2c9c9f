"""Sphinx directive ``scene-reference``: every scene key's table, generated from the schema.

The page cannot drift from the code: the tables are built at each docs build from
``fem_anim.scene.schema`` (see :func:`read_schema`, the only function that knows the
schema's shape). For each key it shows the type (from ``Key.kind`` and ``Key.length``), the
default (``Key.default``; a default of ``None`` is "declared only" for the optional
sections and arrays, "derived or none" elsewhere), the constraint (read off ``Key.check``:
the options of a ``one of`` check, or the name of a named check), and the unit and
meaning (``Key.unit`` / ``Key.doc`` when the schema has them, else ``scene_key_notes``).
A key without a meaning, or a note naming no key, is a build warning (an error with -W).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

from scene_key_notes import NOTES

__all__ = ["KeyRow", "read_schema", "setup"]

LOGGER = logging.getLogger(__name__)

#: What named checks of the schema mean (the check functions of ``fem_anim.scene.schema``).
CHECKS = {"_positive": "> 0", "_non_negative": ">= 0", "_all_positive": "entries > 0",
          "_divisions": "entries whole numbers >= 1", "_steps": "1 .. 1e9",
          "_stiffness": "> 0 or \"adaptive\"", "_scene_name": "a file-name token",
          "_output_directory": "relative, inside the working directory",
          "_check_petsc": "PETSc option names; scalar values", "_colormap": "a matplotlib colormap",
          "_color": "a matplotlib colour", "_window_size": "two integers in 16..4096",
          "_fps": "in (0, 240]", "_outputs": "distinct names of frames, gif, mp4"}


@dataclass(frozen=True)
class KeyRow:
    """One row of the reference: a key as the schema describes it."""

    section: str  # "" for top-level keys
    array: bool  # an array of tables ([[pin]])
    key: str
    kind: str
    default: str
    constraint: str
    unit: str
    meaning: str

    @property
    def path(self) -> str:
        """The dotted path of the key (``pin.min``; ``name`` at the top level)."""
        return f"{self.section}.{self.key}" if self.section else self.key


def read_schema(module: str = "fem_anim.scene.schema") -> list[KeyRow]:
    """Rows for every key of the schema, in the schema's order.

    Reads ``SCHEMA`` (section -> key -> ``Key(kind, default, check, length)``),
    ``OPTIONAL_SECTIONS``, ``ARRAY_SECTIONS`` and ``REQUIRED`` from ``module``, and a key's
    ``unit`` and ``doc`` attributes when it has them.
    """
    schema = importlib.import_module(module)
    optional = set(schema.OPTIONAL_SECTIONS) | set(schema.ARRAY_SECTIONS) | {"body"}
    rows = []
    for section, keys in schema.SCHEMA.items():
        required = schema.REQUIRED.get(section, ())
        for name, key in keys.items():
            path = f"{section}.{name}" if section else name
            unit, meaning = NOTES.get(path, ("", ""))
            if name in required:
                default = "required"
            elif key.default is None:
                default = "declared only" if section in optional else "derived / none"
            else:
                default = _toml(key.default)
            rows.append(KeyRow(section, section in schema.ARRAY_SECTIONS + ("body",), name,
                               _kind(key.kind, key.length), default, _constraint(key.check),
                               getattr(key, "unit", None) or unit,
                               getattr(key, "doc", None) or meaning))
    return rows


def _kind(kind, length) -> str:
    names = {str: "string", int: "integer", float: "number", bool: "boolean", list: "list",
             dict: "table"}
    kinds = kind if isinstance(kind, tuple) else (kind,)
    text = "number" if set(kinds) == {int, float} else " or ".join(names.get(k, k.__name__)
                                                                  for k in kinds)
    if length:
        text += f" of {' or '.join(map(str, length))}"
    return text


def _toml(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, list):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{}" if not value else str(value)
    return str(value)


def _constraint(check) -> str:
    if check is None:
        return ""
    name = getattr(check, "__name__", "")
    if name in CHECKS:
        return CHECKS[name]
    for cell in check.__closure__ or ():  # _one_of(options), _in_open(lo, hi)
        value = cell.cell_contents
        if isinstance(value, tuple) and value and all(isinstance(v, (str, int)) for v in value):
            return "one of " + ", ".join(_toml(v) for v in value)
    return "checked (see the schema)"


def _table(headers: list[str], rows: list[list[str]], literal_columns: set[int]) -> nodes.table:
    table = nodes.table(classes=["scene-keys"])
    group = nodes.tgroup(cols=len(headers))
    table += group
    for _ in headers:
        group += nodes.colspec(colwidth=1)
    head = nodes.thead()
    group += head
    head += _row(headers, set())
    body = nodes.tbody()
    group += body
    for row in rows:
        body += _row(row, literal_columns)
    return table


def _row(cells: list[str], literal_columns: set[int]) -> nodes.row:
    row = nodes.row()
    for i, text in enumerate(cells):
        entry = nodes.entry()
        para = nodes.paragraph()
        if text:
            para += nodes.literal(text, text) if i in literal_columns else nodes.Text(text)
        entry += para
        row += entry
    return row


class SceneReference(SphinxDirective):
    """``scene-reference``: one section per schema section, one table row per key."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        rows = read_schema()
        known = {row.path for row in rows}
        for path in sorted(set(NOTES) - known):
            LOGGER.warning("docs/_ext/scene_key_notes.py names %r, which the schema does not "
                           "have", path, location=self.get_location())
        out: list[nodes.Node] = []
        sections = list(dict.fromkeys(row.section for row in rows))
        for section in sections:
            these = [row for row in rows if row.section == section]
            for row in these:
                if not row.meaning:
                    LOGGER.warning("scene key %r has no meaning (give Key a doc, or add it to "
                                   "docs/_ext/scene_key_notes.py)", row.path,
                                   location=self.get_location())
            title = ("top level" if not section else
                     f"[[{section}]]" if these[0].array else f"[{section}]")
            anchor = nodes.make_id(f"scene-{section or 'top'}")
            block = nodes.section(ids=[anchor])
            block += nodes.title(title, title)
            block += _table(["key", "type", "default", "constraint", "unit", "meaning"],
                            [[r.key, r.kind, r.default, r.constraint, r.unit, r.meaning]
                             for r in these], {0, 2})
            out.append(block)
        return out


def setup(app: Sphinx) -> dict:
    """Register the directive."""
    app.add_directive("scene-reference", SceneReference)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
