"""May a command write a file into a folder? Every command's answer, and its staged writes.

fem_anim replaces only files it wrote. ``run`` keeps that promise with a run directory
(:mod:`fem_anim.output.rundir`); every other command that writes into a folder the user
names (``render``, ``bench -o``, the benchmarks' ``--out``, and any later command such as
an exporter) uses this module:

* :func:`check_may_write`: a file of a name the command would write may already be in the
  folder only if the folder's manifest (:data:`fem_anim.output.rundir.MARKER`) lists it,
  i.e. fem_anim wrote it; anything else there (the user's ``trade_study.md``, their own
  ``animation.gif``) is refused with one error naming the file, before any work is done;
* :func:`staged_products`: the command writes its files into a fresh hidden folder inside
  the target (a name no user file can have: :func:`tempfile.mkdtemp`), and only when all
  of them are complete are they renamed into place, each rename atomic, and added to the
  manifest (:func:`fem_anim.output.rundir.install`, which checks ownership once more),
  with SIGINT, SIGTERM and SIGHUP held meanwhile so that all are installed or none. An
  error or an interrupt removes the staging folder: no half-written file ever sits under
  a product's name, and the previous products stay as they were. A signal that arrives
  while the files are being installed is delivered once they all are. A command stopped
  by a signal asks :func:`installed_by_this_process` whether its install had completed
  (the signal came during it, or after it), so that it says its new files are complete
  rather than "nothing was installed";
* :func:`write_product`: one file (``-o FILE.md``) the same way.

A file of the manifest that the command may write but did not write this time (a plot of
an older study that now has nothing to plot) is removed, so no product outlives its data.
Rank 0 calls these; the callers make the decisions collective.
"""

from __future__ import annotations

import contextlib
import shutil
import signal
import tempfile
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

from fem_anim.errors import FemAnimError
from fem_anim.output.rundir import MARKER, foreign_files, install, read_manifest

__all__ = ["check_may_write", "staged_products", "write_product", "installed_by_this_process",
           "STAGING_PREFIX"]

#: Prefix of the staging folders (hidden, unique per command; removed when it ends).
STAGING_PREFIX = ".fem_anim-staging-"
#: The stop signals held while a product set is installed.
HELD_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)

_installed: list[Path] = []


def installed_by_this_process() -> list[Path]:
    """The folders into which this process has installed a complete product set: a stop
    signal that arrives during the install (it is delivered right after it) or later no
    longer undoes anything there."""
    return list(_installed)


def check_may_write(folder: Path, names: Iterable[str], comm=None) -> None:
    """Refuse a folder that holds a file of one of ``names`` which fem_anim did not write.

    A missing folder, or one without any of these files, may be written; so may a file
    that the folder's manifest lists.

    Args:
        folder: The folder the command writes into.
        names: Relative POSIX paths of the files the command would write there.
        comm: An MPI communicator: decided on its rank 0 and raised on every rank
            (default: decided here).

    Raises:
        FemAnimError: naming the first such file (or ``folder``, if it is a file).
    """
    if comm is not None:
        error = None
        if comm.rank == 0:
            try:
                check_may_write(folder, names)
            except FemAnimError as err:
                error = str(err)
        if (error := comm.bcast(error, root=0)):
            raise FemAnimError(error)
        return
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise FemAnimError(f"{folder} exists and is not a folder")
    foreign = foreign_files(folder, names)
    if foreign:
        raise FemAnimError(f"{folder / foreign[0]} was not written by fem-anim (it is not in "
                           f"{folder / MARKER}): fem-anim never replaces a file it did not "
                           "write; move it away or choose another output folder")


@contextlib.contextmanager
def staged_products(folder: Path, names: Iterable[str],
                    replaces: Iterable[str] | None = None) -> Iterator[Path]:
    """A staging folder for a command's files, installed into ``folder`` when all are made.

    Args:
        folder: The target folder (created if missing).
        names: Every file (relative POSIX path) the command may write; it writes a subset
            of them into the staging folder under the same relative paths.
        replaces: The manifest's files the new ones supersede, removed if not written
            again (default: those of ``names`` the manifest lists).

    Yields:
        The staging folder (inside ``folder``).

    Raises:
        FemAnimError: from :func:`check_may_write`, or if the command staged a file not
            among ``names``.
        OSError: if the folder cannot be written (the staging folder is removed).
    """
    folder, names = Path(folder), set(names)
    check_may_write(folder, names)
    folder.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=STAGING_PREFIX, dir=folder))
    try:
        yield staging
        made = {p.relative_to(staging).as_posix() for p in staging.rglob("*") if p.is_file()}
        if made - names:
            raise FemAnimError(f"internal error: {sorted(made - names)} written into {folder} "
                               f"but not declared (declared: {sorted(names)})")
        old = names & read_manifest(folder) if replaces is None else set(replaces)
        with _signals_held(folder):  # all files renamed and listed, or none
            install(staging, folder, replaces=old)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@contextlib.contextmanager
def _signals_held(folder: Path) -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP until the block ends (main thread only).

    Two layers: the main thread's signal mask, and Python handlers that only note the
    signal, because another thread of the process (VTK's, a BLAS pool's) may take the
    signal, and Python then runs the handler in the main thread at once, inside the block.
    When the block ends, the folder is listed by :func:`installed_by_this_process` if the
    block completed, the handlers and the mask are restored, and the first signal noted (or
    left pending by the mask) is raised again, so the command's own handler sees it after
    the block, and can tell that the install was whole.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    handlers = {sig: signal.getsignal(sig) for sig in HELD_SIGNALS}
    for sig in HELD_SIGNALS:
        signal.signal(sig, lambda signum, frame: arrived.append(signum))
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, HELD_SIGNALS)
    completed = False
    try:
        yield
        completed = True
        _installed.append(Path(folder))
    finally:
        for sig in sorted(signal.sigpending() & set(HELD_SIGNALS)):
            arrived.append(signal.sigwait({sig}))  # taken while still blocked
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        for sig, handler in handlers.items():  # None: a handler not set from Python
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)
        if arrived:
            signal.raise_signal(arrived[0])


def write_product(path: Path, data: bytes) -> None:
    """Write one file the way :func:`staged_products` writes several.

    Args:
        path: The file (its folder is created if missing, and its manifest records it).
        data: Its whole content.

    Raises:
        FemAnimError: if ``path`` exists and fem_anim did not write it.
        OSError: if it cannot be written (an old ``path`` is left as it was).
    """
    path = Path(path)
    with staged_products(path.parent, [path.name]) as staging:
        (staging / path.name).write_bytes(data)
