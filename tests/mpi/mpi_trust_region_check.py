"""Run by ``tests/test_hessian_modes.py::test_trust_region_under_mpi`` under ``mpirun -n 2``:
the crushed StVK cube (h = 0.1, cg-icc, auto) takes its Newton-CG steps in a trust region on
2 ranks (KSPSTCG with block-Jacobi ICC of the AIJ copy), each step converges, every rank uses
the same radius at every trust-region iteration, and the energies per step are printed from
rank 0 for the test to compare with a serial run; then the abs-filtered Hessian is assembled
as an ascent direction's replacement would."""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

from mpi4py import MPI

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from test_solver_menu import squash  # noqa: E402

comm = MPI.COMM_WORLD


def _abort(*exc_info) -> None:
    """An error on one rank ends every rank (the others would wait in a collective)."""
    sys.__excepthook__(*exc_info)
    comm.Abort(1)


sys.excepthook = _abort
folder = comm.bcast(tempfile.mkdtemp() if comm.rank == 0 else None, root=0)
sim = squash(Path(folder), "stvk", hessian="auto", element_size=0.1,
             solver='preset = "cg-icc"')
choice = sim.minimiser.hessian
radii = []  # the radius of every trust-region iteration, on this rank
enter = choice._trust_region


def spy(rho, A):
    enter(rho, A)
    radii.append(choice._radius)


choice._trust_region = spy
state, energies, reasons = sim.initial_state(), [], []
for _ in range(4):
    state, stats = sim.step(state, 0.05)
    reasons.append(stats.reason)
    energies.append(sim.problem.energies())
press = sim.problem.moving_pins[0]
u = state.u.reshape(-1, 3)
local = [float(v) for v in u[press.dofs, 2]]
heights = comm.gather(local, root=0)
used = comm.allreduce(sim.minimiser.hessian.trust_region_its, op=MPI.MIN)
every = comm.gather(radii, root=0)
# the abs-filtered Hessian of an ascent direction's replacement assembles into a matrix of
# its own: into the MatConvert target (converted many times above) it fails on 2 ranks
abs_matrix = sim.minimiser.hessian._assemble_abs(sim.minimiser.snes, sim.problem.x_work)
abs_norm = abs_matrix.norm()
if comm.rank == 0:
    print(json.dumps({"ranks": comm.size, "reasons": reasons, "energies": energies,
                      "press": [v for part in heights for v in part],
                      "trust_region_its": used, "abs_norm": abs_norm,
                      "radii_agree": all(r == every[0] for r in every),
                      "radii": len(every[0])}))
