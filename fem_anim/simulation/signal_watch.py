"""The watcher that makes a second signal stop a run inside a long library call.

Python runs a signal handler only between two bytecodes of the main thread: while the main
thread is inside one long call of a compiled library (the IPC Toolkit's CCD, a PETSc
factorisation), neither the handler of the first signal nor the one of the second runs. What
does run at once is CPython's C-level handler, which writes the signal's number as one byte
to the wakeup file descriptor (:func:`signal.set_wakeup_fd`).

:class:`~fem_anim.simulation.interrupt.Interrupts` starts this file as a small process of its
own (standard library only, no MPI, no fem_anim package import) holding the reading end of
that descriptor. Counting the watched signals' bytes, at the second one it gives the run
:data:`GRACE_S` seconds to stop by itself (its Python handler raises and the command line
prints its message); if the run is still alive then, it prints one line and ends the run
with SIGKILL. Nothing is written or deleted then: the frames on disk and the last
checkpoint (written atomically) stay, and ``--resume`` continues from it; the run
directory's lock is a ``flock``, released by the kernel. The watcher ends when the run
closes its end of the pipe (the run ended, whatever the way), and ignores SIGINT, SIGTERM
and SIGHUP itself (a Ctrl-C at the terminal reaches every process of the foreground group).

Usage: ``python signal_watch.py FD PID GRACE_S SIGNUMS`` (``SIGNUMS`` comma-separated);
:class:`~fem_anim.simulation.interrupt.Interrupts` runs it as ``signal-watch -I -S - ...``
with this file on stdin, so that the process list shows it apart from the run's own.
"""

from __future__ import annotations

import os
import select
import signal
import sys
import time

__all__ = ["GRACE_S", "watch", "main"]

#: Seconds a run has, after its second signal, to stop by itself before it is killed.
GRACE_S = 3.0


def watch(fd: int, pid: int, grace: float, watched: set[int]) -> bool:
    """Read signal numbers from ``fd``; kill ``pid`` if it outlives its second signal.

    Args:
        fd: The reading end of the run's wakeup pipe (one byte per signal received).
        pid: The run's process.
        grace: Seconds the run has to stop by itself after the second watched signal.
        watched: The signal numbers counted.

    Returns:
        True if the run was killed; False if it closed the pipe first (it ended).
    """
    seen: list[int] = []
    while len(seen) < 2:
        data = os.read(fd, 64)
        if not data:
            return False
        seen += [b for b in data if b in watched]
    end = time.monotonic() + grace
    while (left := end - time.monotonic()) > 0:
        if select.select([fd], [], [], left)[0] and not os.read(fd, 64):
            return False
    name = signal.Signals(seen[1]).name
    message = (f"fem-anim: error: interrupted by {name} (twice) inside a library call "
               f"(pid {pid}), stopped now: the frames written so far and the last checkpoint "
               "stay in the run's .partial directory (continue with `fem-anim run ... "
               "--resume OUTDIR`)\n")
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        return False
    os.write(2, message.encode())
    return True


def main(argv: list[str]) -> int:
    """Entry point (see the module docstring for the arguments)."""
    for signum in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        signal.signal(signum, signal.SIG_IGN)
    fd, pid, grace = int(argv[0]), int(argv[1]), float(argv[2])
    watch(fd, pid, grace, {int(s) for s in argv[3].split(",")})
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
