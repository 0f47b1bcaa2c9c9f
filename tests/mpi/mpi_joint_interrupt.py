"""``fem-anim ARGS`` of a scene with a shell body, each rank sending itself SIGINT after step K.

Usage (``tests/test_joint_resume.py`` runs it under ``mpirun -n 2``)::

    mpirun -n 2 python tests/mpi/mpi_joint_interrupt.py K run SCENE -o OUT

Every rank notes the signal after the same step; the run stops at the end of that frame
with a checkpoint (:mod:`fem_anim.simulation.interrupt`) and exits with 130, as a run whose
launcher forwarded a Ctrl-C would.
"""

from __future__ import annotations

import os
import signal
import sys

from fem_anim.cli import main
from fem_anim.simulation.joint_loop import JointSimulation

STOP = int(sys.argv[1])
_take = JointSimulation.timed_step


def _timed_step(self, state, dt):
    new, row = _take(self, state, dt)
    if new.step == STOP:
        os.kill(os.getpid(), signal.SIGINT)
    return new, row


JointSimulation.timed_step = _timed_step
sys.exit(main(sys.argv[2:]))
