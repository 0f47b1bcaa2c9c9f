"""What fem_anim prints on the terminal besides results: the one-line error, a quiet JIT.

Used by the command line (:mod:`fem_anim.cli`), the benches (:mod:`fem_anim.bench`) and the
Python API (:mod:`fem_anim.runs`), which all sit above this module.
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import sys
from collections.abc import Callable, Iterator
from pathlib import Path

from fem_anim.errors import FemAnimError, describe_os_error

__all__ = ["OneLineParser", "print_error", "exit_status", "quiet_jit_logging", "quiet_jit"]


class OneLineParser(argparse.ArgumentParser):
    """argparse whose own errors are a :class:`~fem_anim.errors.FemAnimError` (``prefix`` +
    message): the caller prints them as one line and exits with code 2, like every other."""

    prefix = ""

    def error(self, message):
        raise FemAnimError(self.prefix + message)


def print_error(message: str) -> None:
    """``fem-anim: error: MESSAGE`` on stderr, once (rank 0), as one line.

    Control characters (a newline inside a scene key, say) are escaped, so a message is
    always exactly one line.
    """
    from mpi4py import MPI

    if MPI.COMM_WORLD.rank == 0:
        line = "".join(c if c.isprintable() else repr(c)[1:-1] for c in message)
        print(f"fem-anim: error: {line}", file=sys.stderr, flush=True)


def exit_status(command: Callable[[], int], target: Callable[[], str | Path | None]) -> int:
    """Run a command's body and turn a user's or the system's error into one line and exit 2.

    Args:
        command: The body; returns the exit status.
        target: The file or folder an OS error is about when the error names none itself
            (called only then; e.g. the ``--out`` folder once the arguments are parsed).

    Returns:
        ``command()``'s status; 2 after :func:`print_error` for a
        :class:`~fem_anim.errors.FemAnimError` or an :class:`OSError`.
    """
    try:
        return command()
    except FemAnimError as err:
        print_error(str(err))
    except OSError as err:
        print_error(describe_os_error(err, target()))
    return 2


def quiet_jit_logging() -> None:
    """Silence the FFCx JIT's build log on the terminal.

    FFCx calls ``logging.basicConfig()``; every JIT compile runs setuptools' distutils,
    which sets the root logger to INFO. Raising the handlers' level keeps warnings only.
    """
    for handler in logging.getLogger().handlers:
        handler.setLevel(logging.WARNING)


class _BuildLogFilter(logging.Filter):
    """Drops the build log of setuptools' distutils (the FFCx JIT's C compiler calls):
    records below WARNING logged by a ``distutils`` module or to a ``distutils`` logger."""

    def filter(self, record: logging.LogRecord) -> bool:
        if record.levelno >= logging.WARNING:
            return True
        parts = Path(record.pathname).parts
        return not ("distutils" in parts or "_distutils" in parts
                    or record.name.split(".")[0] == "distutils")


_FILTER = _BuildLogFilter()


@contextlib.contextmanager
def quiet_jit() -> Iterator[None]:
    """Keep the FFCx JIT's build log (``INFO:root:running build_ext``, the compiler
    command lines) off the terminal while the block runs; for library use.

    FFCx configures the root logger at import (``logging.basicConfig()``) and each compile
    runs setuptools' distutils, which logs every command at INFO. Inside the block a filter
    on the root logger and its handlers drops those records, and only those; the root
    logger's level is restored at the end. A program whose root logger was at INFO or below
    when the block began asked for such lines and sees them.
    """
    root = logging.getLogger()
    level = root.level
    asked = level != logging.NOTSET and level <= logging.INFO
    added = [] if asked else [t for t in (root, *root.handlers) if _FILTER not in t.filters]
    for target in added:  # an enclosing block's filters stay until that block ends
        target.addFilter(_FILTER)
    try:
        yield
    finally:
        if not asked:
            root.setLevel(level)
        for target in added:
            target.removeFilter(_FILTER)
