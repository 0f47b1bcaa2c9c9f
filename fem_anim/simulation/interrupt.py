"""Signals during a run: stop at the next frame, collectively, keeping everything.

SIGINT (Ctrl-C), SIGTERM and SIGHUP do not kill a run in the middle of a write. The
handler only notes the signal; the time loop asks :meth:`Interrupts.pending` once per
frame, an ``allreduce`` so that every rank stops at the same frame (``mpirun`` forwards
SIGINT and SIGTERM to every rank, not necessarily at the same moment), writes a
checkpoint there, and raises :class:`~fem_anim.errors.Interrupted`. A second signal
does not wait for the frame to end: it raises at once (the last periodic checkpoint
and the frames so far stay on disk either way; nothing is deleted). Inside one long call
of a compiled library (ipctk's CCD, a factorisation) no Python handler runs until the call
returns; there the watcher process of :mod:`fem_anim.simulation.signal_watch`, which sees
every signal through the wakeup descriptor, ends the run a few seconds (its ``GRACE_S``)
after the second signal unless the run has stopped by itself.

A launcher that dies without forwarding a signal (``mpirun`` killed with SIGKILL; OpenMPI 5
also puts every rank in a process group of its own, so a signal to the launcher's group
does not reach them) would leave its ranks running on their own, holding the run's files.
Each rank of a parallel run therefore notes its parent process when the run starts and
counts a change of parent (the launcher gone, the rank adopted) as SIGHUP, the hang-up of
its controlling process: the ranks stop at the same frame, checkpointed and resumable.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

from mpi4py import MPI

from fem_anim.errors import Interrupted
from fem_anim.simulation import signal_watch

__all__ = ["Interrupts", "SIGNALS", "stop_at_once"]

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class _Handlers:
    """Installs ``self._handle`` for :data:`SIGNALS` while in use (main thread only; the
    handlers in force before are put back on exit)."""

    def __init__(self):
        self._previous: dict[int, object] = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for signum in SIGNALS:
                self._previous[signum] = signal.signal(signum, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)
        self._previous.clear()

    def _handle(self, signum: int, frame) -> None:
        raise NotImplementedError


class Interrupts(_Handlers):
    """Context manager: a signal of :data:`SIGNALS` is noted, and every rank stops at the
    end of the same frame (:meth:`pending`); a second one raises at once, or, inside a long
    library call, the watcher process ends the run (module docstring)."""

    def __init__(self, comm: MPI.Comm):
        super().__init__()
        self.comm = comm
        self.received: int | None = None
        self._parent: int | None = None  # a parallel run's launcher (or its daemon)
        self._watcher: subprocess.Popen | None = None

    def __enter__(self) -> Interrupts:
        if self.comm.size > 1:
            self._parent = os.getppid()
        super().__enter__()
        if self._previous:  # handlers installed (main thread): watch inside library calls
            self._watch()
        return self

    def __exit__(self, *exc) -> None:
        super().__exit__(*exc)
        if self._watcher is not None:
            signal.set_wakeup_fd(self._wakeup_before)
            os.close(self._pipe)  # the watcher reads the end of the run and exits
            self._watcher.wait()
            self._watcher = None

    def _watch(self) -> None:
        """Start the watcher process on the reading end of a new wakeup pipe."""
        read, write = os.pipe()
        os.set_blocking(write, False)
        try:  # named "signal-watch", its source on stdin: it is no fem_anim process
            self._watcher = subprocess.Popen(
                ["signal-watch", "-I", "-S", "-", str(read), str(os.getpid()),
                 str(signal_watch.GRACE_S), ",".join(str(int(s)) for s in SIGNALS)],
                executable=sys.executable, pass_fds=(read,), stdin=subprocess.PIPE,
                start_new_session=True)
            with open(signal_watch.__file__, "rb") as source:
                self._watcher.stdin.write(source.read())
            self._watcher.stdin.close()
        except OSError:  # no process to spare: signals still stop the run between calls
            os.close(write)
            return
        finally:
            os.close(read)
        self._pipe = write
        self._wakeup_before = signal.set_wakeup_fd(write, warn_on_full_buffer=False)

    def _handle(self, signum: int, frame) -> None:
        if self.received is not None:  # the second signal: stop now
            raise Interrupted(f"interrupted by {signal.Signals(signum).name} (twice)", signum)
        self.received = signum

    def pending(self) -> int | None:
        """The signal every rank stops for, or None (collective: call once per frame)."""
        if self.received is None and self._parent is not None and \
                os.getppid() != self._parent:
            self.received = signal.SIGHUP  # the launcher is gone
        mine = self.received if self.received is not None else 0
        signum = self.comm.allreduce(mine, op=MPI.MAX)
        return signum or None


class stop_at_once(_Handlers):
    """Context manager: during set-up (meshing, compiling forms) a signal of :data:`SIGNALS`
    raises :class:`~fem_anim.errors.Interrupted` at once.

    There is nothing to keep yet, but a compile killed by SIGTERM, or stopped by SIGINT's
    KeyboardInterrupt (a BaseException FFCx does not clean up after), would leave FFCx's
    lock file in the JIT cache, and every later run would wait for it and fail. FFCx
    releases its lock on an Exception, which :class:`~fem_anim.errors.Interrupted` is (see also
    :func:`fem_anim.compat.jit_locks_released`).
    """

    def _handle(self, signum: int, frame) -> None:
        raise Interrupted(f"interrupted by {signal.Signals(signum).name} while setting up "
                          "(nothing to keep yet)", signum)
