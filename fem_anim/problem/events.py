"""PETSc log events of the step objective's assembly callbacks.

PETSc's own timers: ``-log_view`` lists them as ``FemAnimObjective``, ``FemAnimResidual``,
``FemAnimJacobian``, ``FemAnimFilter`` and ``FemAnimEnergies``, and
:mod:`fem_anim.bench.perf` reads them to split a step's time.
"""

from __future__ import annotations

from petsc4py import PETSc

__all__ = ["EVENTS"]

#: Callback name -> its PETSc log event.
EVENTS = {name: PETSc.Log.Event(f"FemAnim{name.capitalize()}")
          for name in ("objective", "residual", "jacobian", "filter", "energies")}
