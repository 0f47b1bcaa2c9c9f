"""The mixed formulation's quadrature integrates its weak constraint exactly, for every q.

The contract (:mod:`fem_anim.problem.discretisation`): with ``element.formulation =
"mixed"`` and no ``element.quadrature_degree``, the elastic rule has degree 1 + d (k - 1),
so that int q (J - 1) dX is integrated exactly for every pressure test function q of
P_{k-1}, not only for q = 1 (the total volume): J = det(I + grad u) is a polynomial of degree
d (k - 1) on each cell of a P_k displacement. Checked for each basis function q_i of the
P1 pressure space, at an arbitrary P2 displacement (random dof values, J far from 1),
against a rule of degree 4 higher; a rule one degree too low keeps q = 1 (degree d) exact
and misses here.
"""

from __future__ import annotations

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from test_mixed import _mixed_scene

from fem_anim.forms.kinematics import deformation_gradient
from fem_anim.simulation.loop import Simulation


def assembled(form) -> np.ndarray:
    """The owned entries of an assembled vector (ghost contributions summed)."""
    from petsc4py import PETSc

    b = fem_petsc.assemble_vector(fem.form(form))
    b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
    out = b.array.copy()
    b.destroy()
    return out


@pytest.mark.parametrize("d", [2, 3])
def test_constraint_of_every_pressure_test_function_is_exact(tmp_path, d):
    sim = Simulation(_mixed_scene(tmp_path, d=d))
    p = sim.problem
    rng = np.random.default_rng(7 + d)
    p.u.x.array[:] = 0.08 * rng.standard_normal(p.u.x.array.size)
    J = ufl.det(deformation_gradient(p.u))
    q = ufl.TestFunction(p.fields.Q)
    high = ufl.Measure("dx", domain=sim.domain.mesh,
                       metadata={"quadrature_degree": p.quadrature_degree + 4})
    with_rule = assembled(q * (J - 1.0) * p.dx_elastic)
    reference = assembled(q * (J - 1.0) * high)
    scale = MPI.COMM_WORLD.allreduce(float(np.abs(reference).max()), op=MPI.MAX)
    error = MPI.COMM_WORLD.allreduce(float(np.abs(with_rule - reference).max()), op=MPI.MAX)
    assert scale > 1e-3  # J is far from 1: the check has something to integrate
    assert error <= 1e-12 * scale, error / scale
    sim.minimiser.destroy()
