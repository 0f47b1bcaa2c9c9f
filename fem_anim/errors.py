"""Typed errors of fem_anim, and the helpers that word their messages.

Library code raises these; only the command line turns them into a message and
exit code 2. Every message names the offending key, file or value. Under MPI an error is
decided on one rank and raised on all of them by the caller.
"""

import os

__all__ = ["FemAnimError", "SceneError", "MeshError", "ConvergenceError", "Interrupted",
           "show_value", "describe_os_error", "describe_library_error"]


class FemAnimError(Exception):
    """Base class of every error fem_anim reports to a user."""


class SceneError(FemAnimError):
    """A scene file or override is malformed, of the wrong type or nonphysical."""


class MeshError(FemAnimError):
    """A mesh cannot be built or read, or is unusable (inverted, empty, ...)."""


class ConvergenceError(FemAnimError):
    """A time step's minimisation did not converge."""


class Interrupted(FemAnimError):
    """A signal (SIGINT, SIGTERM, SIGHUP) stopped the run.

    Args:
        message: The one-line message (which step, how to resume).
        signum: The signal's number.
    """

    def __init__(self, message: str, signum: int):
        super().__init__(message)
        self.signum = signum


def describe_os_error(err: OSError, path: object = None) -> str:
    """``FILE: reason`` for an OS error: the file the error names, else ``path``.

    h5py and some writers raise ``OSError`` without a file name or ``strerror``; the
    caller's ``path`` (the file being written) names it then.

    Args:
        err: The error.
        path: The file being read or written, named if ``err`` names none.

    Returns:
        ``FILE: reason``, or the reason alone if no file is known.
    """
    name = err.filename if err.filename is not None else path
    reason = err.strerror or (os.strerror(err.errno) if err.errno else str(err) or "OS error")
    return f"{name}: {reason}" if name is not None else reason


def show_value(value: object, limit: int = 200) -> str:
    """``repr`` of a value for a message, cut short (a scene value may be megabytes).

    Args:
        value: Any value.
        limit: The most characters of its ``repr`` to keep.

    Returns:
        The ``repr``, or its first ``limit`` characters and the full length.
    """
    text = repr(value)
    return text if len(text) <= limit else f"{text[:limit]}... ({len(text)} characters)"


def describe_library_error(err: BaseException) -> str:
    """One line for an error a compiled library raised (ipctk, PETSc, DOLFINx).

    A ``MemoryError`` from the IPC Toolkit means its candidate set outgrew the memory (a
    ``dhat`` near the size of the bodies, every surface pair a candidate); other errors are
    named with the library's own first line.

    Args:
        err: The library's exception (``MemoryError``, ``RuntimeError``, ...).

    Returns:
        The message, without a traceback: what failed and what to change.
    """
    first = (str(err).strip().splitlines() or [""])[0][:300]
    if isinstance(err, MemoryError):
        return ("out of memory in a library call (for contact: the IPC Toolkit's candidate "
                "pairs; reduce contact.dhat or the number of surface elements)"
                + (f": {first}" if first else ""))
    return f"a library call failed ({type(err).__name__}): {first or 'no message'}"
