"""``fem-anim export OUTDIR``: a finished run as USD, or as OBJ/PLY mesh sequences.

Usage::

    fem-anim export OUTDIR [--format usd|obj|ply] [-o PATH] [--start-frame N] [-q]

``--format usd`` (the default) writes ``OUTDIR/<scene>.usdc``
(:mod:`fem_anim.export.usd_stage`), or the ``.usdc``/``.usda``/``.usd`` file ``-o`` names;
``--format obj|ply`` writes one file per body per frame (:mod:`fem_anim.export.mesh_sequence`)
into ``OUTDIR/<format>/``, or into the folder ``-o`` names. Frame numbers (USD time codes,
sequence file numbers) start at ``--start-frame`` (default 1).

Nothing fem_anim did not write is ever replaced (:mod:`fem_anim.output.rundir`): into a
run directory, or a folder ``-o`` names that is new, empty or fem_anim's, the files are
written and listed in the folder's manifest, so a later export replaces them (and removes
the frames of an older, longer sequence); an existing file the manifest does not list is
refused, and a USD file ``-o`` names in another folder is written only if it does not
exist. Files are written under a temporary name and renamed: complete or absent.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from fem_anim.errors import FemAnimError, describe_os_error
from fem_anim.export.mesh_sequence import FORMATS, write_sequence
from fem_anim.export.run_reader import read_run
from fem_anim.export.usd_stage import prim_names, usd_file_name, write_usd
from fem_anim.output.rundir import (MARKER, check_not_in_use, claim, install, read_manifest,
                                    write_manifest)

__all__ = ["add_export_parser", "export_command", "export_run", "USD_SUFFIXES"]

#: The suffixes of a USD file ``-o`` may name (binary crate, text, either).
USD_SUFFIXES = (".usdc", ".usda", ".usd")
#: The staging folder of a sequence export inside the folder it goes to.
EXPORT_STAGING = ".export-partial"


def add_export_parser(sub) -> None:
    """Register ``export`` on the ``fem-anim`` subcommand parsers.

    Args:
        sub: The ``add_subparsers`` object of the ``fem-anim`` parser.
    """
    export = sub.add_parser("export", help="export a finished run as USD (one mesh per body, "
                            "time-sampled) or as OBJ/PLY sequences (one file per body per "
                            "frame)")
    export.add_argument("outdir", help="the output directory of a finished `fem-anim run`")
    export.add_argument("--format", default="usd", choices=("usd", *FORMATS),
                        help="usd (default): OUTDIR/<scene>.usdc; obj, ply: OUTDIR/<format>/")
    export.add_argument("-o", "--output", help="the USD file, or the sequence's folder")
    export.add_argument("--start-frame", type=int, default=1, metavar="N",
                        help="number of the first frame (default 1)")
    export.add_argument("-q", "--quiet", action="store_true", help="print nothing")


def export_command(args) -> int:
    """Run ``fem-anim export`` (rank 0 writes; other ranks wait).

    Args:
        args: The parsed arguments of :func:`add_export_parser`'s parser.

    Returns:
        0.

    Raises:
        FemAnimError: for a run that cannot be read or exported (whatever the reader
            cannot handle is this one line, never a traceback), a target fem_anim does not
            own, or an OS error (naming the file).
    """
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    error, written = None, None
    if comm.rank == 0:
        try:
            written = export_run(Path(args.outdir), args.format, args.output, args.start_frame)
        except FemAnimError as err:
            error = str(err)
        except OSError as err:
            error = describe_os_error(err)
        except (ValueError, KeyError, IndexError, TypeError) as err:  # a run we cannot read
            error = f"the run in {args.outdir} cannot be exported: {type(err).__name__}: {err}"
    error = comm.bcast(error, root=0)
    if error:
        raise FemAnimError(error)
    if comm.rank == 0 and not args.quiet:
        print(f"fem-anim export: {written}")
    return 0


def export_run(outdir: Path, fmt: str, output: str | None = None,
               start_frame: int = 1) -> str:
    """Export a finished run (one process).

    Args:
        outdir: The run directory.
        fmt: ``"usd"``, ``"obj"`` or ``"ply"``.
        output: The USD file or the sequence's folder (default in ``outdir``).
        start_frame: The number of frame 0 (at least 0).

    Returns:
        What was written, one line.

    Raises:
        FemAnimError: as :func:`export_command`.
        OSError: for a file that cannot be written.
    """
    if start_frame < 0:
        raise FemAnimError(f"--start-frame must be at least 0, got {start_frame}")
    outdir = Path(outdir)
    check_not_in_use(outdir)
    run = read_run(outdir)
    if fmt == "usd":
        target = Path(output) if output else outdir / usd_file_name(run.name)
        if target.suffix not in USD_SUFFIXES:
            raise FemAnimError(f"-o {target}: a USD file ends with "
                               f"{', '.join(USD_SUFFIXES)}")
        _write_usd_file(run, target, start_frame)
        return f"{target} ({len(run.body_names)} bodies, {len(run.times)} frames)"
    root, sub = (Path(output), "") if output else (outdir, fmt)
    files = _write_sequence_files(run, root, sub, fmt, start_frame)
    return f"{len(files)} {fmt.upper()} files ({len(run.body_names)} bodies x " \
           f"{len(run.times)} frames) in {root / sub}"


def _refuse(target: Path) -> None:
    raise FemAnimError(f"{target} exists and fem-anim did not write it (it is not in a "
                       f"fem-anim manifest, {MARKER}): choose another -o")


def _write_usd_file(run, target: Path, start_frame: int) -> None:
    """Write the USD file ``target``: listed in its folder's manifest when that folder is
    fem_anim's, else only where no file is."""
    folder = target.parent
    if target.is_dir():
        raise FemAnimError(f"-o {target} is a folder; name the USD file to write")
    owned = (folder / MARKER).is_file()
    if target.exists() and (not owned or target.name not in read_manifest(folder)):
        _refuse(target)
    lock = claim(folder) if owned else None
    tmp = target.with_name(f".{target.stem}.tmp{target.suffix}")
    try:
        write_usd(run, tmp, start_frame)
        os.replace(tmp, target)
        if owned:
            write_manifest(folder, read_manifest(folder) | {target.name})
    except OSError as err:
        raise OSError(err.errno, err.strerror, str(target)) from None
    finally:
        tmp.unlink(missing_ok=True)
        if lock is not None:
            os.close(lock)


def _write_sequence_files(run, root: Path, sub: str, fmt: str, start_frame: int) -> list[str]:
    """Write the sequence into ``root/sub`` through a staging folder and install it,
    replacing the files of an earlier export of the same format there."""
    lock = claim(root)  # refuses a user's non-empty folder; marks a new one
    staging = root / EXPORT_STAGING
    try:
        owned = read_manifest(root)
        stems = prim_names(run.body_names)
        if staging.exists():
            shutil.rmtree(staging)  # an export cut short: fem_anim's files only
        (staging / sub).mkdir(parents=True)
        names = write_sequence(run, staging / sub, fmt, stems, start_frame)
        written = {f"{sub}/{n}" if sub else n for n in names}
        for name in sorted(written):
            if (root / name).exists() and name not in owned:
                _refuse(root / name)
        older = {n for n in owned if n.endswith(f".{fmt}")
                 and (n.startswith(f"{sub}/") if sub else "/" not in n)}
        install(staging, root, replaces=older)
        return sorted(written)
    finally:
        if staging.exists():
            shutil.rmtree(staging)
        os.close(lock)
