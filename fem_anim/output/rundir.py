"""What makes a folder a run directory: its marker, its lock, and the files fem_anim owns.

fem_anim deletes or overwrites only what it wrote. A run directory carries a marker
file :data:`MARKER`, written before anything else, which lists (JSON) every file the
runs and renderings made there (its *manifest*). Then:

* ``-o DIR`` onto a folder that is neither missing, empty nor marked is refused
  (:func:`claim`), naming the folder: a user's folder is never written into;
* a new run or rendering replaces the files of the old one (:func:`install`): each
  new file is renamed into place (atomic), and an old file of the manifest that the new
  results do not replace is removed; a file the manifest does not list (a user's notes
  in ``frames/``) is never touched;
* one run per directory: :func:`claim` takes an exclusive ``flock`` on :data:`LOCK`
  for the life of the process (and ``fem-anim render`` refuses a held directory,
  :func:`check_not_in_use`). The kernel drops the lock when its process dies,
  however it dies, so a stale lock never blocks a new run; the file keeps the holder's
  pid, which the refusal names.

Rank 0 calls these; :class:`fem_anim.output.files.RunDirectory` makes the decisions
collective.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
from pathlib import Path

from fem_anim.errors import ConvergenceError, FemAnimError, Interrupted, describe_os_error

__all__ = ["MARKER", "LOCK", "STAGING", "claim", "check_not_in_use", "install",
           "read_manifest", "write_manifest", "write_atomically", "foreign_files",
           "RENDER_PRODUCTS", "stopped_run_error"]

MARKER = ".fem_anim-run"
LOCK = ".fem_anim-lock"
STAGING = ".partial"
#: Files :mod:`fem_anim.render.animation` and :mod:`fem_anim.render.plots` make from a run:
#: a new run into the same directory removes the old ones (those of the manifest), so no
#: picture outlives its data.
RENDER_PRODUCTS = ("final.png", "frames", "animation.gif", "animation.mp4", "energies.png",
                   "newton.png")


def write_atomically(path: Path, data: bytes) -> None:
    """Write a file so that it is either complete or absent: temp file, fsync, rename.

    Args:
        path: The file to write.
        data: Its whole content.

    Raises:
        OSError: naming ``path`` (a full disk reports no file name by itself); the
            temporary file is removed, the old ``path`` is left as it was.
    """
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise OSError(err.errno, err.strerror or str(err), str(path)) from None


def read_manifest(path: Path) -> set[str]:
    """The files fem_anim wrote in a run directory.

    Args:
        path: The run directory.

    Returns:
        Relative POSIX paths; empty if the marker is missing or unreadable.
    """
    try:
        return set(json.loads((Path(path) / MARKER).read_text()).get("files", []))
    except (OSError, ValueError, AttributeError):
        return set()


def foreign_files(path: Path, names) -> list[str]:
    """The files among ``names`` that exist in ``path`` but fem_anim did not write there.

    Args:
        path: A folder (missing: nothing is foreign).
        names: Relative POSIX paths.

    Returns:
        Those of ``names`` present in ``path`` (as a file, folder or link) and absent
        from its manifest, sorted.
    """
    path = Path(path)
    if not path.is_dir():
        return []
    owned = read_manifest(path)
    return [name for name in sorted(set(names)) if name not in owned
            and ((path / name).exists() or (path / name).is_symlink())]


def write_manifest(path: Path, files: set[str]) -> None:
    """Rewrite a run directory's marker with its manifest (temp file and rename).

    Args:
        path: The run directory.
        files: Relative POSIX paths of the files fem_anim owns there.
    """
    text = json.dumps({"fem_anim": "run directory", "files": sorted(files)}, indent=1) + "\n"
    write_atomically(Path(path) / MARKER, text.encode())


def claim(path: Path) -> int:
    """Make ``path`` a run directory of this process: create or check it, mark it, lock it.

    Args:
        path: The output directory.

    Returns:
        The file descriptor holding the lock (close it to release the directory).

    Raises:
        FemAnimError: if ``path`` is a non-empty folder without :data:`MARKER`, if
            another live run holds the lock, or for an OS error (naming the file).
    """
    path = Path(path)
    try:
        if path.is_dir() and not (path / MARKER).is_file() and any(path.iterdir()):
            raise FemAnimError(f"output directory {path} is not empty and is not a fem-anim "
                               f"run directory (no {MARKER} in it): fem-anim writes only into "
                               "a new or empty folder or one of its own runs; choose another -o")
        path.mkdir(parents=True, exist_ok=True)
        if not (path / MARKER).is_file():
            write_manifest(path, set())
        fd = os.open(path / LOCK, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as err:
        raise FemAnimError(f"output directory {path} cannot be written: "
                           f"{describe_os_error(err, path)}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
        os.close(fd)
        raise FemAnimError(f"output directory {path} is in use by another fem-anim run "
                           f"(pid {holder}); wait for it to end or choose another -o") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return fd


def check_not_in_use(path: Path) -> None:
    """Refuse a directory a live run holds (``fem-anim render`` while it is written).

    Args:
        path: The run directory.

    Raises:
        FemAnimError: naming the holder's pid.
    """
    try:
        fd = os.open(Path(path) / LOCK, os.O_RDONLY)
    except OSError:
        return  # no lock file: no run was ever started here by a locking fem_anim
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        holder = os.pread(fd, 32, 0).decode(errors="replace").strip() or "unknown"
        raise FemAnimError(f"{path} is in use by a running fem-anim run (pid {holder}); "
                           "render it when the run has ended") from None
    finally:
        os.close(fd)


def _files_below(root: Path) -> set[str]:
    if root.is_dir() and not root.is_symlink():
        return {p.relative_to(root.parent).as_posix() for p in root.rglob("*") if not p.is_dir()}
    return {root.name}


def install(staging: Path, path: Path, replaces: set[str] | None = None) -> None:
    """Move everything in ``staging`` into the run directory ``path``; remove ``staging``.

    Files are renamed one by one (each rename atomic), directories merged file by file.
    Then every manifest file in ``replaces`` that was not just written is removed (a
    frame of an older, longer run), and the manifest becomes what fem_anim now owns.

    Args:
        staging: A folder inside ``path`` holding the new files.
        path: The run directory.
        replaces: Manifest entries the new files supersede (default: none).

    Raises:
        FileExistsError: before anything is moved, naming a file of ``path`` that one of
            the new files would replace but that the manifest does not list (a user's).
    """
    owned = read_manifest(path)
    new: set[str] = set()
    for item in sorted(staging.iterdir()):
        new |= _files_below(item)
    foreign = foreign_files(path, new)
    if foreign:  # checked before anything moves: nothing is replaced, nothing is lost
        raise FileExistsError(errno.EEXIST, "exists and was not written by fem-anim (it is "
                              f"not in {MARKER}); nothing was replaced",
                              str(path / foreign[0]))
    for name in sorted(new):
        target = path / name
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / name, target)
    for name in sorted((replaces or set()) & owned - new):
        (path / name).unlink(missing_ok=True)
        parent = (path / name).parent
        if parent != path:
            try:
                parent.rmdir()  # only if empty: a user's file in it keeps it
            except OSError:
                pass
    for item in sorted(staging.rglob("*"), reverse=True):
        item.rmdir()
    staging.rmdir()
    write_manifest(path, (owned - (replaces or set())) | new)


def stopped_run_error(err: ConvergenceError | Interrupted, path: Path, continue_with: str,
                      other_options: str = " (e.g. with other solver options)"
                      ) -> ConvergenceError | Interrupted:
    """``err`` again, saying what the run stopped in ``path`` keeps and how to continue it.

    A stopped run leaves its frames so far in ``path/.partial`` (:data:`STAGING`) and, once
    one was written, the checkpoint ``--resume`` continues from (docs/resume.md).

    Args:
        err: Why the run stopped (a step that did not converge, or a signal).
        path: The run directory.
        continue_with: How the user continues it, e.g. ``fem-anim run ... --resume OUT``.
        other_options: Said after ``continue_with`` for a step that did not converge.

    Returns:
        An error of ``err``'s type (an :class:`Interrupted` keeps its signal number) whose
        message ends with what is kept, and ``continue_with`` when there is a checkpoint.
    """
    if not (Path(path) / STAGING / "checkpoint.npz").is_file():
        kept = f"the frames so far are kept in {path}/{STAGING} (no checkpoint yet: " \
               "nothing to resume; a new run replaces them)"
    else:
        other = other_options if isinstance(err, ConvergenceError) else ""
        kept = f"the frames so far and the last checkpoint are kept in {path}/{STAGING}: " \
               f"continue with `{continue_with}`{other}"
    if isinstance(err, Interrupted):
        return Interrupted(f"{err}; {kept}", err.signum)
    return ConvergenceError(f"{err}; {kept}")
