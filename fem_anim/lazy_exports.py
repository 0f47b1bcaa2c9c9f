"""Public names of a concept folder, imported only when first used (PEP 562).

A folder's ``__init__`` lists which of its modules defines each public name; the name is
imported from that module on first access (``fem_anim.problem.EnergyProblem``). Nothing is
imported with the folder itself, so a light process (the render process, which must not load
DOLFINx) can import one light module of a folder whose other modules need DOLFINx, and no
folder's import can start a cycle through another's.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping

__all__ = ["lazy_exports"]


def lazy_exports(package: str, exports: Mapping[str, str]
                 ) -> tuple[list[str], Callable[[str], object], Callable[[], list[str]]]:
    """``__all__``, ``__getattr__`` and ``__dir__`` for a package's ``__init__``.

    Args:
        package: The package's ``__name__``.
        exports: Public name -> the module of the package (its last dotted part) defining it.

    Returns:
        The sorted public names, and the module-level ``__getattr__`` and ``__dir__`` that
        import a name's module on first access.

    Raises:
        AttributeError: (from ``__getattr__``) for a name the table does not list.
    """
    names = sorted(exports)

    def __getattr__(name: str) -> object:
        try:
            module = exports[name]
        except KeyError:
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None
        return getattr(importlib.import_module(f"{package}.{module}"), name)

    def __dir__() -> list[str]:
        return names

    return names, __getattr__, __dir__
