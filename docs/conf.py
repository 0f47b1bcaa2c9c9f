"""Sphinx configuration of the fem_anim documentation.

Build (warnings are errors; a broken cross-reference is a warning)::

    .venv/bin/sphinx-build -W --keep-going -b html docs /tmp/fem_anim-docs

At build time this file writes three things into the source folder (all git-ignored):
``api/index.rst`` (the autosummary over the package's folders, found by walking the
package), ``api/generated/`` (autosummary's stubs) and ``demos/`` (the literate demos
``demos/*.py`` and their pictures, read by myst-nb through jupytext and never executed).
The repository is the folder above this one, or ``$FEM_ANIM_ROOT``.
"""

from __future__ import annotations

import os
import re
import shutil
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = Path(os.environ.get("FEM_ANIM_ROOT", HERE.parent)).resolve()
sys.path.insert(0, str(HERE / "_ext"))

from api_index import write_api_index  # noqa: E402  (docs/_ext)

project = "fem_anim"
author = "fem_anim contributors"
copyright = "fem_anim contributors"
release = version = "0.1.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "myst_nb",  # Markdown pages (it loads myst-parser) and the percent-format demos
    "scene_reference",  # docs/_ext: the scene keys' tables, generated from the schema
]

# --- sources -------------------------------------------------------------------------------
root_doc = "index"
exclude_patterns = ["_build", "jupyter_execute", "_ext", "conf.py", "README.md",
                    ".gitignore", "**/.ipynb_checkpoints"]
source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".py": "myst-nb"}
myst_enable_extensions = ["dollarmath", "colon_fence"]
myst_heading_anchors = 3
# The demos are percent-format scripts (`# %% [markdown]` cells): read them as notebooks
# through jupytext and show them with their committed pictures; never run them here.
nb_custom_formats = {".py": ["jupytext.reads", {"fmt": "py:percent"}]}
nb_execution_mode = "off"

# --- cross-references ----------------------------------------------------------------------
# Every :doc:, :ref: and Markdown link must resolve (a miss is a warning, and -W makes it an
# error). Python objects named in type hints (numpy, PETSc, DOLFINx, UFL ...) are not in
# these docs, so misses in the Python domain are not reported.
nitpicky = True
nitpick_ignore_regex = [(r"py:.*", r"(?s).*")]
# "more than one target found" for a bare class name in a type hint (two classes share a
# name in different modules): Python-domain references are not checked, as above.
suppress_warnings = ["ref.python"]

# --- API reference -------------------------------------------------------------------------
autosummary_generate = True
autosummary_imported_members = False
autodoc_member_order = "bysource"
autodoc_typehints = "description"
templates_path = ["_templates"]  # autosummary/module.rst: packages list modules, modules members
napoleon_google_docstring = True
napoleon_numpy_docstring = False

# --- HTML ----------------------------------------------------------------------------------
html_theme = "furo"
html_title = "fem_anim"
html_static_path: list[str] = []


def escape_bars(app, what, name, obj, options, lines: list[str]) -> None:
    """Docstrings write norms and absolute values as ``|x|``: show the bars literally.

    reStructuredText reads ``|x|`` as a substitution; outside double-backquoted literals,
    each ``|`` becomes ``\\|``.
    """
    for i, line in enumerate(lines):
        if "|" in line:
            parts = re.split(r"(``.*?``)", line)
            lines[i] = "".join(p if p.startswith("``") else p.replace("|", r"\|")
                               for p in parts)


def setup(app) -> None:
    """Connect :func:`escape_bars` to autodoc."""
    app.connect("autodoc-process-docstring", escape_bars)


def copy_demos(srcdir: Path = HERE, root: Path = ROOT) -> list[str]:
    """Copy ``demos/*.py``, their pictures and scenes into ``docs/demos/``; return the demo names.

    The pictures (``demos/*.png``, ``demos/hanging_beam.gif``) and scenes (``demos/*.toml``)
    are copied too; a demo page shows its committed picture ``demos/<name>.png`` after its
    title cell, when there is one.
    """
    target = srcdir / "demos"
    if target.exists():
        shutil.rmtree(target)
    target.mkdir()
    names = []
    for other in ("*.png", "*.gif", "*.toml", "results/**/*.png"):
        for path in sorted((root / "demos").glob(other)):
            copy = target / path.relative_to(root / "demos")
            copy.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, copy)
    for script in sorted((root / "demos").glob("*.py")):
        text = JUPYTEXT_HEADER + script.read_text()
        if (target / f"{script.stem}.png").exists():
            text = _with_picture(text, f"{script.stem}.png")
        (target / script.name).write_text(text)
        names.append(script.stem)
    return names


#: Tells jupytext (so myst-nb) the cells are Python, for highlighting.
JUPYTEXT_HEADER = """# ---
# jupyter:
#   kernelspec:
#     display_name: Python 3
#     language: python
#     name: python3
# ---

"""


def _with_picture(text: str, picture: str) -> str:
    """The script with a Markdown cell showing ``picture`` after its first (title) cell."""
    cell = f"# %% [markdown]\n# ![The demo's picture]({picture})\n\n"
    second = text.find("\n# %%", text.find("# %%") + 1)
    if second < 0:
        return text + "\n" + cell
    return text[:second + 1] + cell + text[second + 1:]


DEMOS = copy_demos()
write_api_index(HERE / "api", ROOT)
