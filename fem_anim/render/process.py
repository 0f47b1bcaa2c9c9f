"""Rendering in its own process: a run's pictures, or one file's.

:func:`render_run` (frames, GIF, MP4, final.png and plots of a run directory:
:func:`fem_anim.render.animation.render_directory`) and :func:`render_file` (one ``.vtu`` to
a PNG: :func:`fem_anim.render.frames.render_vtu`) start ``python -m fem_anim.render.process``:
the VTK wheel's C++ runtime clashes with libraries DOLFINx loads (std::regex in VTK's scalar
bar aborts in a process that has imported dolfinx), and a separate process also lets a
saved run be re-rendered without simulating again (``fem-anim render OUTDIR``).

The process reports every error a user or the system can cause (a folder holding files
fem_anim did not write, a read-only or full file system) as one ``fem-anim: error:`` line
and exit code 2, an interrupt with exit code 130; its caller raises them again as
:class:`~fem_anim.errors.FemAnimError` and :class:`~fem_anim.errors.Interrupted`. An
interrupted rendering installs nothing (:mod:`fem_anim.output.products`), unless the signal
came while or after its finished pictures were installed: then both processes say that the
new pictures are complete.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

from fem_anim.errors import FemAnimError, Interrupted, describe_os_error
from fem_anim.output.products import installed_by_this_process
from fem_anim.render.animation import render_directory
from fem_anim.render.frames import render_vtu

__all__ = ["render_file", "render_run", "STOP_SIGNALS"]

#: Signals that stop a rendering: it removes its staged files and installs nothing.
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: What the renderer says when a signal came while or after its finished pictures were
#: installed (and its caller, when the renderer had finished).
INSTALLED_THEN_STOPPED = ("rendering interrupted after its new pictures were installed; "
                          "they are complete")


def _interrupted(stderr: str, signum: int, returncode: int | None = None) -> Interrupted:
    """The parent's account of an interrupted renderer, true to what the renderer did: it
    had finished (``returncode`` 0), or said that its pictures were installed, or not."""
    if returncode == 0 or INSTALLED_THEN_STOPPED in stderr:
        return Interrupted(INSTALLED_THEN_STOPPED, signum)
    return Interrupted(f"rendering interrupted by signal {signum}; nothing was installed, "
                       "the previous pictures are as they were", signum)


def _run_renderer(args: list[str]) -> subprocess.CompletedProcess:
    """Run ``python -m fem_anim.render.process ARGS`` outside the MPI job.

    Raises:
        FemAnimError: the renderer's one-line message, if it rejected its input (exit 2).
        Interrupted: if a signal stopped the renderer or this process while it rendered
            (the renderer is given SIGINT and the time to remove its staged files).
        RuntimeError: with the renderer's error output if it failed otherwise.
    """
    env = dict(os.environ)
    for key in [k for k in env if k.startswith(("OMPI_", "PMIX_", "PMI_"))]:
        del env[key]  # the renderer is not part of the MPI job
    child = subprocess.Popen([sys.executable, "-m", "fem_anim.render.process", *args],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                             env=env)
    try:
        stdout, stderr = child.communicate()
    except KeyboardInterrupt:
        child.send_signal(signal.SIGINT)  # let it clean up (it may have had one already)
        try:
            _, stderr = child.communicate(timeout=60)
        except subprocess.TimeoutExpired:
            child.kill()
            child.wait()
            stderr = ""
        raise _interrupted(stderr or "", signal.SIGINT, child.returncode) from None
    proc = subprocess.CompletedProcess(child.args, child.returncode, stdout, stderr)
    message = proc.stderr.strip()
    last = message.splitlines()[-1] if message else ""  # after ffmpeg's own complaints
    if proc.returncode == 2 and last.startswith("fem-anim: error: "):
        raise FemAnimError(last.removeprefix("fem-anim: error: "))
    if proc.returncode < 0 or proc.returncode - 128 in STOP_SIGNALS:
        signum = -proc.returncode if proc.returncode < 0 else proc.returncode - 128
        raise _interrupted(message, signum)
    if proc.returncode != 0:
        last = message.splitlines()[-1] if message else f"exit code {proc.returncode}"
        raise RuntimeError(f"rendering failed: {last}")
    return proc


def render_file(vtu: Path, png: Path, title: str = "", settings: dict | None = None) -> None:
    """Render a ``.vtu`` file to a PNG in a fresh Python process.

    Args:
        vtu: A mesh file with point data ``displacement``.
        png: The PNG file to write.
        title: Text drawn in the top-left corner.
        settings: The scene's ``[render]`` table (default: its defaults).

    Raises:
        FemAnimError: the renderer's one-line message, if it rejected its input.
        RuntimeError: if rendering failed otherwise or wrote no file.
    """
    _run_renderer([str(vtu), str(png), "--title", title,
                   "--settings", json.dumps(settings or {})])
    if not Path(png).is_file():
        raise RuntimeError(f"rendering {vtu} wrote no {png}")


def render_run(path: Path, settings: dict, quiet: bool = True) -> None:
    """Make the pictures of a run (frames, GIF, MP4, final.png, plots) in a fresh process.

    See :func:`fem_anim.render.animation.render_directory`.

    Args:
        path: The finished run directory.
        settings: The scene's ``[render]`` table.
        quiet: Do not print the renderer's summary line.

    Raises:
        FemAnimError: naming what is missing or wrong in ``path``, a file there that
            fem_anim did not write, or an OS error (read-only or full file system).
        Interrupted: if a signal stopped the rendering (nothing was installed).
        RuntimeError: if rendering failed otherwise.
    """
    proc = _run_renderer(["--run", str(path), "--settings", json.dumps(settings)])
    if not quiet and proc.stdout:
        print(proc.stdout, end="", flush=True)


def main(argv: list[str] | None = None) -> int:
    """The render process: ``VTU PNG`` (one file) or ``--run OUTDIR`` (a run directory).

    Args:
        argv: The command line after the program name (default: ``sys.argv[1:]``).

    Returns:
        The exit status: 0; 2 with a one-line ``fem-anim: error:`` message on stderr for
        bad input or an OS error; 130 if interrupted (nothing installed, unless it says
        that its new pictures were installed: a signal during or after the install).
    """
    parser = argparse.ArgumentParser(prog="python -m fem_anim.render.process")
    parser.add_argument("files", nargs="*", metavar="VTU PNG")
    parser.add_argument("--run", metavar="OUTDIR", help="render a run directory")
    parser.add_argument("--title", default="")
    parser.add_argument("--settings", default="{}", help="the [render] table as JSON")
    args = parser.parse_args(argv)
    settings = json.loads(args.settings)
    stopped: dict[str, int] = {}

    def stop(signum, frame):  # SIGTERM and SIGHUP clean up like Ctrl-C
        for sig in STOP_SIGNALS:  # a second signal must not cut the clean-up short
            signal.signal(sig, signal.SIG_IGN)
        stopped["signum"] = signum
        raise KeyboardInterrupt

    for sig in STOP_SIGNALS:
        signal.signal(sig, stop)
    try:
        if args.run:
            render_directory(Path(args.run), settings)
        elif len(args.files) == 2:
            render_vtu(Path(args.files[0]), Path(args.files[1]), args.title, settings)
        else:
            parser.error("give VTU PNG, or --run OUTDIR")
        for sig in STOP_SIGNALS:  # done: a signal now changes nothing (exit code 0)
            signal.signal(sig, signal.SIG_IGN)
    except FemAnimError as err:
        print(f"fem-anim: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # read-only or full file system: the file and why
        target = args.run or args.files[-1]
        print(f"fem-anim: error: cannot write the pictures of {target}: "
              f"{describe_os_error(err, target)}; nothing was replaced", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        if args.run and Path(args.run) in installed_by_this_process():
            print(f"fem-anim: error: {INSTALLED_THEN_STOPPED}", file=sys.stderr)
        else:
            print("fem-anim: error: rendering interrupted; nothing was installed",
                  file=sys.stderr)
        return 128 + stopped.get("signum", signal.SIGINT)
    return 0


if __name__ == "__main__":
    sys.exit(main())
