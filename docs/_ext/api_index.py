"""Write ``docs/api/index.rst``: an autosummary over the package, found by walking it.

The module list is not written by hand (modules move): every sub-package and module of
``fem_anim`` found on disk is listed, except the ones in :data:`SKIP`; sub-packages are
documented recursively by autosummary (``:recursive:``).
"""

from __future__ import annotations

import pkgutil
from pathlib import Path

__all__ = ["api_modules", "write_api_index"]

#: Not API: the ``python -m fem_anim`` entry point (it runs the CLI on import), the
#: benchmark tools (documented by the pages that give their figures) and the peers' worker.
SKIP = ("fem_anim.__main__", "fem_anim.bench")
#: Folders installed under ``fem_anim`` from elsewhere in the repository (pyproject.toml's
#: ``package-dir``).
MAPPED = {"fem_anim.forms": "forms", "fem_anim.meshes": "meshes"}


def api_modules(root: Path) -> list[str]:
    """Dotted names of ``fem_anim``'s direct sub-packages and modules, concept folders first.

    Args:
        root: The repository (holding ``fem_anim/``, ``forms/`` and ``meshes/``).

    Returns:
        Sub-packages (sorted), then the root modules (sorted), minus :data:`SKIP`.
    """
    found = {f"fem_anim.{m.name}": m.ispkg for m in pkgutil.iter_modules([str(root / "fem_anim")])}
    for name, folder in MAPPED.items():
        if (root / folder / "__init__.py").exists():
            found[name] = True
    keep = {n: pkg for n, pkg in found.items() if n not in SKIP}
    return sorted(n for n, pkg in keep.items() if pkg) + sorted(n for n, pkg in keep.items()
                                                                  if not pkg)


def write_api_index(folder: Path, root: Path) -> None:
    """Write ``folder/index.rst`` listing :func:`api_modules` in one recursive autosummary."""
    folder.mkdir(exist_ok=True)
    lines = ["API reference", "=============", "",
             "Generated from the docstrings (Google style). The folders follow the algorithm:",
             "scene -> mesh -> problem (the energy) -> contact -> solver -> simulation ->",
             "output -> render; see :doc:`../architecture`.", "",
             ".. autosummary::", "   :toctree: generated", "   :recursive:", ""]
    lines += [f"   {name}" for name in api_modules(root)]
    text = "\n".join(lines) + "\n"
    index = folder / "index.rst"
    if not index.exists() or index.read_text() != text:
        index.write_text(text)
