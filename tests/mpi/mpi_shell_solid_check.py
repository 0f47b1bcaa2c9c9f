"""A cloth falling on a soft cube, the two stepped as one (issue 30), on any number of ranks.

Usage (``tests/test_shell_solid.py`` runs it on 1 and 2 ranks and compares)::

    mpirun -n 2 python tests/mpi/mpi_shell_solid_check.py OUT.npz [--steps N (5)]

The scenes of ``tests/test_shell_solid.py`` (a neo-Hookean cube pinned at its base, a StVK
sheet 3 mm above it, IPC between and within them with friction 0.3, implicit Euler). Rank 0
writes each step's total energy, Newton iterations and pair count, and each body's final
displacement in the order of its dof coordinates (gathered from every rank), so runs on
different rank counts compare entry by entry.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from mpi4py import MPI

from fem_anim.petsc_options import init_petsc

init_petsc([])

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_shell_solid import DHAT, _shell, _simulation, _solid  # noqa: E402

COMM = MPI.COMM_WORLD


def ordered(part, u: np.ndarray) -> np.ndarray | None:
    """The owned displacement blocks of every rank, on rank 0, in dof-coordinate order."""
    n = part.V.dofmap.index_map.size_local
    X = part.V.tabulate_dof_coordinates()[:n]
    pieces = COMM.gather((X, u.reshape(-1, 3)[:n]), root=0)
    if COMM.rank != 0:
        return None
    X = np.concatenate([p[0] for p in pieces])
    U = np.concatenate([p[1] for p in pieces])
    order = np.lexsort(np.round(X, 9).T[::-1])
    return U[order]


def main() -> None:
    out = Path(sys.argv[1])
    steps = int(sys.argv[sys.argv.index("--steps") + 1]) if "--steps" in sys.argv else 5
    sim = _simulation(_solid(), _shell(contact={"dhat": DHAT, "friction": 0.3}))
    states = sim.initial_state()
    energy, its, pairs = [], [], []
    for _ in range(steps):
        states, stats = sim.step(states, 0.01)
        energy.append(sim.energies(states)["total_energy"])
        its.append(stats.newton_its)
        pairs.append(sim.problem.ipc.num_pairs)
    finals = [ordered(part, s.u) for part, s in zip(sim.parts, states)]
    if COMM.rank == 0:
        np.savez(out, energy=energy, newton_its=its, pairs=pairs, solid=finals[0],
                 shell=finals[1])


if __name__ == "__main__":
    main()
