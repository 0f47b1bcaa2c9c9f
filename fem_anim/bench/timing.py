"""Where a step's time goes, measured by PETSc's own log events.

A step's wall time is split into phases read from PETSc's event log (``PETSc.Log``):
fem_anim's assembly callbacks (``FemAnimObjective``, ``FemAnimResidual``,
``FemAnimJacobian``, ``FemAnimFilter``, ``FemAnimEnergies``:
:data:`fem_anim.problem.objective.EVENTS`)
and PETSc's ``PCSetUp`` (factorisation, or preconditioner set-up for Krylov presets; its
symbolic part ``MatCholFctrSym``/``MatLUFactorSym`` reported on its own) and ``KSPSolve``
(triangular solves, or Krylov iterations). The phases do not nest, and "other" is the step's
wall time minus their sum: Python, copies, the integrator's update, convergence tests.

Also here: the least-squares growth exponent of cost against problem size, and the peak
resident memory of a process.
"""

from __future__ import annotations

import resource

import numpy as np
from petsc4py import PETSc

__all__ = ["PHASES", "PhaseTimer", "growth_exponent", "peak_memory_mb", "split_step"]

#: Phase name -> PETSc event(s) whose inclusive times are summed (in this order of columns).
PHASES: dict[str, tuple[str, ...]] = {
    "residual": ("FemAnimResidual",),
    "jacobian": ("FemAnimJacobian",),
    "objective": ("FemAnimObjective",),
    "filter": ("FemAnimFilter",),
    "energies": ("FemAnimEnergies",),
    "factor_symbolic": ("MatCholFctrSym", "MatLUFactorSym"),
    "pc_setup": ("PCSetUp",),
    "ksp_solve": ("KSPSolve",),
}


class PhaseTimer:
    """Reads the cumulative times and counts of :data:`PHASES` from PETSc's log.

    Call :meth:`snapshot` before and after the work; :func:`split_step` turns two
    snapshots and the wall time between them into a phase split.
    """

    def __init__(self) -> None:
        PETSc.Log.begin()
        self.events = {name: [PETSc.Log.Event(e) for e in events]
                       for name, events in PHASES.items()}

    def snapshot(self) -> dict[str, tuple[float, int]]:
        """Cumulative (seconds, calls) per phase, this process."""
        out = {}
        for name, events in self.events.items():
            infos = [e.getPerfInfo() for e in events]
            out[name] = (sum(i["time"] for i in infos), sum(int(i["count"]) for i in infos))
        return out


def split_step(before: dict, after: dict, wall: float) -> dict[str, float]:
    """The phases of one step: seconds per phase, ``factor_numeric`` and ``other``.

    ``pc_setup`` contains the symbolic factorisation; it is reported as ``factor_symbolic``
    and ``factor_numeric`` (the rest of ``PCSetUp``). ``other`` = wall minus every phase.
    """
    d = {name: after[name][0] - before[name][0] for name in PHASES}
    calls = {name: after[name][1] - before[name][1] for name in PHASES}
    split = {
        "residual": d["residual"], "jacobian": d["jacobian"], "objective": d["objective"],
        "filter": d["filter"], "energies": d["energies"],
        "factor_symbolic": d["factor_symbolic"],
        "factor_numeric": max(d["pc_setup"] - d["factor_symbolic"], 0.0),
        "solve": d["ksp_solve"],
    }
    split["other"] = wall - sum(split.values())
    split["wall"] = wall
    split["symbolic_calls"] = calls["factor_symbolic"]
    split["factor_calls"] = calls["pc_setup"]
    return split


def growth_exponent(sizes, costs) -> float:
    """Least-squares slope p of log(cost) = a + p log(size)."""
    sizes, costs = np.asarray(sizes, float), np.asarray(costs, float)
    keep = (sizes > 0) & (costs > 0)
    if keep.sum() < 2:
        return float("nan")
    return float(np.polyfit(np.log(sizes[keep]), np.log(costs[keep]), 1)[0])


def peak_memory_mb() -> float:
    """Peak resident set size of this process (Linux reports KiB), in MiB."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
