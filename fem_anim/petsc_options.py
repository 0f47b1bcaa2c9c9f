"""PETSc options: command-line splitting, initialisation and precedence of option layers.

Precedence, lowest to highest: library defaults < solver preset < scene
``[solver.petsc]`` < command line. The merged options are put into PETSc's
database under the solver's prefix only while the solver reads them
(``setFromOptions``, and each solve: ``-snes_converged_reason``, ``-ksp_view``, the
factorisation's ``-mat_mumps_*`` and the sub-solvers' ``-sub_*`` are read there, the last
two only when the first solve sets the preconditioner up), then removed, so two solvers
never see each other's options.

Command-line options are held to the scene's standard (:func:`check_cli_options`,
:func:`unused_options`): values finite, viewers' files writable, and an option that no
PETSc object read (``-ksp_tpye cg``) an error naming it, as an unknown scene key is.

PETSc must be initialised from ``argv`` before ``dolfinx`` is imported, so that
global options such as ``-log_view`` take effect; :func:`init_petsc` does that.
"""

from __future__ import annotations

import contextlib
import ctypes
import math
import os
import sys
from collections.abc import Iterable, Iterator, Mapping

from fem_anim.errors import FemAnimError

__all__ = [
    "DEFAULT_PREFIX",
    "GLOBAL_OPTIONS",
    "split_petsc_args",
    "init_petsc",
    "flatten_options",
    "merge_options",
    "options_in_database",
    "check_cli_options",
    "unused_options",
]

DEFAULT_PREFIX = "fem_anim_"

#: Options that belong to PETSc as a whole and are passed to PetscInitialize as they are.
GLOBAL_OPTIONS = frozenset({
    "log_view", "log_view_memory", "options_left", "info", "malloc_debug", "malloc_dump",
    "log_trace", "on_error_abort", "memory_view", "help",
})

#: Families of solver options accepted on the command line (without prefix).
SOLVER_FAMILIES = ("snes_", "ksp_", "pc_", "mat_", "sub_", "mg_", "fem_anim_")


def _is_value(token: str) -> bool:
    if not token.startswith("-"):
        return True
    try:
        float(token)
    except ValueError:
        return False
    return True


def split_petsc_args(argv: list[str]) -> tuple[list[str], dict[str, str], list[str]]:
    """Separate PETSc options from the application's own arguments.

    Args:
        argv: Arguments after the sub-command, e.g. ``["scene.toml", "-snes_monitor"]``.

    Returns:
        ``(app_args, solver_options, global_args)``: the arguments for argparse, the
        solver options (names without leading dash or prefix, values as strings, ``""``
        for flags) and the global PETSc options as an argv list.
    """
    app: list[str] = []
    solver: dict[str, str] = {}
    global_args: list[str] = []
    i = 0
    while i < len(argv):
        tok = argv[i]
        name = tok[1:]
        is_option = tok.startswith("-") and not tok.startswith("--") and len(tok) > 2
        if is_option and (name in GLOBAL_OPTIONS or name.startswith(SOLVER_FAMILIES)):
            value = ""
            if i + 1 < len(argv) and _is_value(argv[i + 1]):
                value = argv[i + 1]
                i += 1
            if name in GLOBAL_OPTIONS:
                global_args += [tok] + ([value] if value else [])
            else:
                if name.startswith(DEFAULT_PREFIX):
                    name = name[len(DEFAULT_PREFIX):]
                solver[name] = value
        else:
            app.append(tok)
        i += 1
    return app, solver, global_args


def init_petsc(global_args: list[str] | None = None) -> None:
    """Initialise petsc4py with the global options, before dolfinx is imported.

    Does nothing if ``petsc4py.PETSc`` is already imported (PETSc is initialised once).

    Args:
        global_args: Global PETSc options as an argv list (``["-log_view"]``).
    """
    import petsc4py

    if "petsc4py.PETSc" not in sys.modules:
        petsc4py.init([sys.argv[0]] + list(global_args or []))


def flatten_options(table: Mapping, parent: str = "") -> dict[str, str]:
    """Flatten a nested options table: ``{"ksp": {"type": "cg"}}`` -> ``{"ksp_type": "cg"}``.

    Booleans become PETSc's ``true``/``false``; ``true`` for a flag may also be written ``""``.

    Args:
        table: The scene's ``[solver.petsc]`` table, nested or flat.
        parent: The name prefix of ``table``'s keys (for the recursion).

    Returns:
        Option name (without prefix) -> value as a string.
    """
    flat: dict[str, str] = {}
    for key, value in table.items():
        name = f"{parent}_{key}" if parent else str(key)
        if isinstance(value, Mapping):
            flat.update(flatten_options(value, name))
        elif isinstance(value, bool):
            flat[name] = "true" if value else "false"
        else:
            flat[name] = str(value)
    return flat


def merge_options(*layers: Mapping[str, str]) -> dict[str, str]:
    """Merge option layers, later layers winning (defaults, preset, scene, command line).

    Returns:
        A new dictionary.
    """
    merged: dict[str, str] = {}
    for layer in layers:
        merged.update(layer)
    return merged


@contextlib.contextmanager
def options_in_database(prefix: str, options: Mapping[str, str]) -> Iterator[None]:
    """Put ``options`` under ``prefix`` in PETSc's database for the duration of the block.

    Args:
        prefix: The solver's options prefix, ending in ``_``.
        options: Option name (without prefix) -> value; removed again on leaving.
    """
    from petsc4py import PETSc

    db = PETSc.Options()
    for name, value in options.items():
        db.setValue(prefix + name, value)
    try:
        yield
    finally:
        for name in options:
            db.delValue(prefix + name)


#: Options fem_anim reads itself (PETSc never reads ``mat_type`` for a matrix the
#: application creates: :class:`fem_anim.solver.minimiser.Minimiser` takes it).
READ_BY_FEM_ANIM = frozenset({"mat_type"})


#: Option names ending so take a number (``-snes_rtol abc`` is refused naming it).
NUMERIC_SUFFIXES = ("_rtol", "_atol", "_stol", "_divtol", "_max_it", "_max_funcs", "_restart",
                    "_levels", "_damping", "_shift_amount", "_omega", "_its", "_lag_jacobian",
                    "_lag_preconditioner", "_maxstep", "_minlambda", "_trtol", "_icntl_13")


def _viewer_file(value: str) -> str | None:
    """The file of a viewer value ``[type]:file[:format[:mode]]``, or None."""
    if ":" not in value:
        return None
    return value.split(":")[1] or None


def check_cli_options(solver: Mapping[str, str], global_args: list[str]) -> None:
    """Command-line PETSc options held to the scene's standard, before anything runs.

    Values must be finite where they are numbers (``-ksp_rtol nan``), and a viewer's file
    (``-log_view :/no/such/dir/f``, ``-ksp_view ascii:out.txt``) must be creatable: its
    folder must exist and be writable.

    Raises:
        FemAnimError: naming the option and its value.
    """
    pairs = [(f"-{name}", value) for name, value in solver.items()]
    i = 0
    while i < len(global_args):
        value = global_args[i + 1] if i + 1 < len(global_args) and \
            not global_args[i + 1].startswith("-") else ""
        pairs.append((global_args[i], value))
        i += 2 if value else 1
    for option, value in pairs:
        try:
            number = float(value)
        except ValueError:
            number = 0.0
        if not math.isfinite(number):
            raise FemAnimError(f"PETSc option {option} must be finite, got {value!r}")
        if option.endswith(NUMERIC_SUFFIXES):
            try:
                float(value)
            except ValueError:
                raise FemAnimError(f"PETSc option {option} must be a number, got {value!r}") \
                    from None
        target = _viewer_file(value)
        if target is not None:
            folder = os.path.dirname(os.path.abspath(target))
            if not os.path.isdir(folder) or not os.access(folder, os.W_OK):
                raise FemAnimError(f"PETSc option {option} {value}: its file {target} cannot "
                                   f"be created (no writable folder {folder})")


def _petsc_library() -> ctypes.CDLL:
    """The PETSc shared library petsc4py loaded (found in this process's memory map)."""
    from petsc4py import PETSc  # noqa: F401  (loads the library)

    with open("/proc/self/maps") as maps:
        for line in maps:
            path = line.split()[-1]
            if os.path.basename(path).startswith("libpetsc") and ".so" in path:
                return ctypes.CDLL(path)
    raise OSError("the PETSc library is not loaded")


def unused_options(prefix: str, names: Iterable[str]) -> list[str]:
    """Which of ``names`` (without prefix) in PETSc's database no object has read yet.

    petsc4py has no binding of ``PetscOptionsUsed`` (the query behind ``-options_left``);
    it is called through ctypes on the global database. Call it while the options are in
    the database (:func:`options_in_database`).

    Args:
        prefix: The solver's options prefix.
        names: Option names without prefix (those fem_anim reads itself are skipped).

    Returns:
        The names no PETSc object has read.

    Raises:
        OSError: if the PETSc library is not loaded or ``PetscOptionsUsed`` fails.
    """
    lib = _petsc_library()
    lib.PetscOptionsUsed.argtypes = [ctypes.c_void_p, ctypes.c_char_p,
                                     ctypes.POINTER(ctypes.c_int)]
    unused = []
    for name in names:
        if name in READ_BY_FEM_ANIM:
            continue
        used = ctypes.c_int(0)
        if lib.PetscOptionsUsed(None, f"{prefix}{name}".encode(), ctypes.byref(used)) != 0:
            raise OSError(f"PetscOptionsUsed failed for -{prefix}{name}")
        if not used.value:
            unused.append(name)
    return unused
