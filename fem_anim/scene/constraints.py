"""What one scene key's value may be, besides its type: ranges, names, paths, limits.

Each check takes a value already of the key's type and returns ``None`` when it is allowed,
else the constraint as a phrase (``"must be > 0"``) that :mod:`fem_anim.scene.validation`
puts into a :class:`~fem_anim.errors.SceneError` with the key path and the value. The limits
(:data:`MAX_MAGNITUDE`, :data:`MAX_STRING`, ...) keep a typo or a hostile file from becoming
a computation: a scene is a page of TOML, never code.
"""

from __future__ import annotations

import errno
import math
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fem_anim.errors import SceneError
from fem_anim.errors import show_value as _show

__all__ = ["MAX_MAGNITUDE", "MAX_STEPS", "MAX_FILE_BYTES", "MAX_STRING", "NAME_PATTERN",
           "PETSC_KEY", "PETSC_WRITING_VIEWERS", "Check", "positive", "non_negative",
           "in_open", "in_closed", "at_least_one", "all_positive", "divisions", "steps",
           "stiffness", "scene_name", "body_name", "symlink_loops", "output_directory",
           "check_petsc", "check_string", "key_text", "colormap", "color", "window_size",
           "fps", "distinct_names", "nonzero_vector"]

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

#: A check: the value (of the key's type) -> ``None`` if allowed, else the constraint.
Check = Callable[[Any], "str | None"]


def positive(v) -> str | None:
    return None if v > 0 else "must be > 0"


def non_negative(v) -> str | None:
    return None if v >= 0 else "must be >= 0"


def at_least_one(v) -> str | None:
    return None if v >= 1 else "must be >= 1"


def in_open(lo, hi) -> Check:
    """``lo < v < hi``."""
    return lambda v: None if lo < v < hi else f"must be in ({lo}, {hi})"


def in_closed(lo, hi, text: str) -> Check:
    """``lo <= v <= hi``, the constraint phrased as ``text``."""
    return lambda v: None if lo <= v <= hi else text


def all_positive(v) -> str | None:
    return None if all(c > 0 for c in v) else "must have all entries > 0"


def divisions(v) -> str | None:
    ok = all(isinstance(c, int) and not isinstance(c, bool) and c >= 1 for c in v)
    return None if ok else "must have all entries whole numbers >= 1"


def steps(v) -> str | None:
    if v < 1:
        return "must be >= 1"
    return None if v <= MAX_STEPS else f"must be at most {MAX_STEPS}"


def stiffness(v) -> str | None:
    if isinstance(v, str):
        return None if v == "adaptive" else "must be a number of Pa or \"adaptive\""
    return positive(v)


def scene_name(v) -> str | None:
    return None if NAME_PATTERN.fullmatch(v) else (
        "must be a simple file name (letters, digits, '_', '-', '.'; not starting with '.' "
        "or '-'; at most 100 characters), since it names the output directory out/<name>")


def body_name(v) -> str | None:
    return None if NAME_PATTERN.fullmatch(v) else \
        "must be a simple name (letters, digits, '_', '-', '.'; at most 100 characters)"


def nonzero_vector(v) -> str | None:
    return None if any(v) else "must not be the zero vector"


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


def output_directory(v) -> str | None:
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


def check_petsc(table: dict, path: str = "solver.petsc") -> None:
    """PETSc options: identifier names; string, finite number or boolean values.

    A viewer that writes files (``ksp_view_mat = "binary:/elsewhere"``, ``"ascii:log.txt"``)
    is refused: a scene cannot make the program write outside its output directory.

    Raises:
        SceneError: naming the option's key path and value.
    """
    for k, value in table.items():
        where = f"{path}.{key_text(k)}"
        if not PETSC_KEY.fullmatch(k):
            raise SceneError(f"{where}: PETSc option names are letters, digits and '_'")
        if isinstance(value, dict):
            check_petsc(value, where)
        elif not isinstance(value, (str, int, float)):  # bool is an int
            raise SceneError(f"{where} must be a string, a number or true/false, "
                             f"got {_show(value)}")
        elif isinstance(value, str):
            check_string(where, value)
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


def key_text(k: str) -> str:
    """A key as written in a dotted path; odd keys (spaces, newlines, ...) are quoted."""
    return k if re.fullmatch(r"[\w-]{1,64}", k) else _show(k)


def check_string(path: str, value: str) -> None:
    """At most :data:`MAX_STRING` characters, no control characters.

    Raises:
        SceneError: naming ``path`` and the value.
    """
    if len(value) > MAX_STRING:
        raise SceneError(f"{path} must be at most {MAX_STRING} characters, got {_show(value)}")
    if any(ord(c) < 32 or ord(c) == 127 for c in value):
        raise SceneError(f"{path} must not contain control characters, got {_show(value)}")


def colormap(v) -> str | None:
    import matplotlib  # only when a scene names a colormap: the default costs no import

    if v in matplotlib.colormaps:
        return None
    close = [name for name in matplotlib.colormaps if name.lower() == v.lower()]
    hint = f" (did you mean {close[0]!r}?)" if close else " (see matplotlib's colormap list)"
    return "must be a matplotlib colormap name" + hint


def color(v) -> str | None:
    import matplotlib.colors

    return None if matplotlib.colors.is_color_like(v) else \
        "must be a colour name or '#rrggbb' (matplotlib's colour names)"


def window_size(v) -> str | None:
    ok = all(isinstance(c, int) and 16 <= c <= 4096 for c in v)
    return None if ok else "must be two whole numbers of pixels in 16..4096"


def fps(v) -> str | None:
    return None if 0 < v <= 240 else "must be in (0, 240] frames per second"


def distinct_names(options) -> Check:
    """A list of distinct strings, each one of ``options``."""
    def check(v) -> str | None:
        ok = all(isinstance(c, str) for c in v) and set(v) <= set(options) and \
            len(set(v)) == len(v)
        return None if ok else f"must be a list of distinct names from {', '.join(options)}"
    return check
