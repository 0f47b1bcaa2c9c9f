"""The work the handles (moving pins) do on the bodies in one step.

A pinned dof is a Dirichlet condition: the step objective g (seed eq. 4) is minimised over
the free dofs only, and on a pinned dof its gradient is the force the pin must exert to
hold the prescribed motion. Every integrator's g is 1/2 ||x - y||_M^2 + w [E(x) + ...]
with M (x - y) / w the scheme's inertia M a_{n+1} (seed eq. 1b for Newmark), so on the
pinned dofs

    r = grad g(x_{n+1}) / w = M a_{n+1} + grad E(x_{n+1}) (+ damping, barrier, friction)

is the force the pin applies to the body at the step's end, and the work of the step is
W = r . (u_{n+1} - u_n) over the pinned dofs (the step's rectangle rule at its end, as
the implicit step itself takes the forces at its end). Summed over the steps it is what
the handles put in: the stored energy's change plus what damping, friction and the time
step took (:mod:`fem_anim.simulation.energy_report`).
"""

from __future__ import annotations

import numpy as np
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

__all__ = ["handle_work"]


def handle_work(problem, u_n: np.ndarray, x: PETSc.Vec) -> float:
    """The handles' work W (J) in the step from ``u_n`` to the solution ``x`` (collective).

    Args:
        problem: The staged :class:`~fem_anim.problem.objective.EnergyProblem` of the step.
        u_n: Displacement at the step's start (local dofs of V, ghosts included; m).
        x: The step's solution (the unknown's vector: u, or the mixed (u, p~)).

    Returns:
        sum over the owned pinned dofs of r_i (u_{n+1,i} - u_{n,i}), summed over the ranks.
    """
    p = problem
    p.set_state(x)
    b = x.duplicate()
    with b.localForm() as local:
        local.set(0.0)
    fem_petsc.assemble_vector(b, p.residual_form)
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    if p.constant_terms is not None:
        p.constant_terms.add_gradient(b, x)
    if p.ipc is not None:
        p.ipc.add_gradient(b, float(p.weight.value))
    force = p.fields.displacement_part(b) if p.mixed else b
    du = p.u.x.array - u_n
    work = 0.0
    with force.localForm() as local:
        for bc in p.displacement_bcs:
            dofs, first_ghost = bc.dof_indices()
            owned = np.asarray(dofs[:first_ghost])
            work += float(np.dot(local.array_r[owned], du[owned]))
    b.destroy()
    return p.comm.allreduce(work, op=MPI.SUM) / float(p.weight.value)
