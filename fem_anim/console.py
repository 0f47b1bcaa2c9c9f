"""What fem_anim prints on the terminal besides results: the one-line error, a quiet JIT.

Used by the command line (:mod:`fem_anim.cli`) and by the benches (:mod:`fem_anim.bench`),
which both sit above this module (STYLE rule 15).
"""

from __future__ import annotations

import argparse
import logging
import sys

from fem_anim.errors import FemAnimError

__all__ = ["OneLineParser", "print_error", "quiet_jit_logging"]


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


def quiet_jit_logging() -> None:
    """Silence the FFCx JIT's build log on the terminal.

    FFCx calls ``logging.basicConfig()``; every JIT compile runs setuptools' distutils,
    which sets the root logger to INFO. Raising the handlers' level keeps warnings only.
    """
    for handler in logging.getLogger().handlers:
        handler.setLevel(logging.WARNING)
