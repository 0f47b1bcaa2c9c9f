"""Sphinx directive ``scene-reference``: every scene key's table, generated from the schema.

The page cannot drift from the code: the tables are built at each docs build from
:func:`fem_anim.scene.scene_keys` (type, default, unit, allowed values and meaning of every
key, as the schema itself declares them) and :data:`fem_anim.scene.SECTIONS` (each table's
TOML header and meaning). A key without a meaning is a build warning (an error with -W).
"""

from __future__ import annotations

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

__all__ = ["setup"]

LOGGER = logging.getLogger(__name__)


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
    """``scene-reference``: one section per schema table, one row per key."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        from fem_anim.scene import SECTIONS, scene_keys

        keys = list(scene_keys())
        out: list[nodes.Node] = []
        for section in dict.fromkeys(k.section for k in keys):
            these = [k for k in keys if k.section == section]
            for k in these:
                if not k.doc:
                    LOGGER.warning("scene key %r has no meaning (give its Key a doc)", k.path,
                                   location=self.get_location())
            header, meaning = SECTIONS[section]
            title = header or "top level"
            block = nodes.section(ids=[nodes.make_id(f"scene-{section or 'top'}")])
            block += nodes.title(title, title)
            block += nodes.paragraph(text=meaning[:1].upper() + meaning[1:] + ".")
            block += _table(["key", "type", "default", "allowed", "unit", "meaning"],
                            [[k.path, k.type, _default(k), _allowed(k), k.unit, k.doc]
                             for k in these], {0, 2})
            out.append(block)
        return out


def _default(key) -> str:
    if key.required:
        return "required"
    return "none" if key.default is None else _toml(key.default)


def _allowed(key) -> str:
    return "" if key.choices is None else ", ".join(_toml(v) for v in key.choices)


def setup(app: Sphinx) -> dict:
    """Register the directive."""
    app.add_directive("scene-reference", SceneReference)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
