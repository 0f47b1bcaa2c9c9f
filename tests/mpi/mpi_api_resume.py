"""``fem_anim.run`` of a small scene under ``mpirun``, stopped by SIGINT and resumed from Python.

Usage (``tests/test_python_api.py`` runs it under ``mpirun -n 2``)::

    mpirun -n 2 python tests/mpi/mpi_api_resume.py OUT

Every rank runs the scene once whole (a temporary run directory), then into ``OUT`` with
each rank sending itself SIGINT while frame 3 is written (the run stops at that frame's end
with a checkpoint), then ``fem_anim.run(scene, OUT, resume=True)``. Rank 0 prints one line
``STOP <message>`` and one ``RESUMED <steps taken> <frames> <largest difference>`` against
the whole run's final displacement; exit 0.
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

import fem_anim
from fem_anim.simulation.loop import Simulation

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_python_api import TINY  # noqa: E402

scene = fem_anim.Scene.from_dict(TINY, ["time.steps=8", "output.checkpoint_every=1"])
rank = MPI.COMM_WORLD.rank
with fem_anim.run(scene) as whole:
    expected = whole.displacement(-1) if rank == 0 else None
fields, written, steps = Simulation.frame_fields, [], []


def _frame_fields(self, state):
    written.append(state.time)
    if len(written) == 4:  # frames 0..3
        os.kill(os.getpid(), signal.SIGINT)
    return fields(self, state)


Simulation.frame_fields = _frame_fields
try:
    fem_anim.run(scene, sys.argv[1])
    raise SystemExit("the run was not stopped")
except fem_anim.Interrupted as stop:
    if rank == 0:
        print("STOP", stop, flush=True)
Simulation.frame_fields = fields
step = Simulation.timed_step
Simulation.timed_step = lambda self, *a: steps.append(1) or step(self, *a)
resumed = fem_anim.run(scene, sys.argv[1], resume=True)
if rank == 0:
    gap = np.abs(resumed.displacement(-1) - expected).max()
    print("RESUMED", len(steps), len(resumed.times), gap, flush=True)
