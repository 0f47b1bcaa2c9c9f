"""The terms of g assembled once (:mod:`fem_anim.problem.constant_terms`) against g as one form.

The callbacks SNES calls assemble w E(x) per call and add the inertia, Rayleigh damping and
gravity terms from matrices and a vector assembled once. Here they are compared with the
whole step objective assembled as the single UFL form it is (``EnergyProblem.ufl_objective``:
value, ``ufl.derivative`` gradient lifted by the pins like DOLFINx's nonlinear problems, and
Hessian with the pins' identity rows), on a bar with every such term: consistent mass,
gravity, mass- and stiffness-proportional damping, a moving pin whose dofs are off their
prescribed values (the lifting is not zero) or on them (it is skipped), in both matrix types
the solvers use, and again after the damping coefficient changes (adaptive dt). The iterate
handed to the callbacks has stale ghost entries, as SNES's do. Run as a script under
``mpirun -n 3`` by the last test (the pin straddles the ranks' boundaries; on 3 ranks a
vertex on the pin box's face was pinned on one rank and free on its owner until the owner's
choice was made the rule: ``EnergyProblem._owners_choice``).
"""

from __future__ import annotations

import sys

import numpy as np
import pytest
import ufl
from conftest import run_file_under_mpirun
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.problem.form_compiler import compile_forms
from fem_anim.scene import load_scene
from fem_anim.simulation.loop import Simulation

PIN_VELOCITY = np.array([0.0, 0.3, 0.1])  # m/s
SCENE = ["mesh.size=[1.0,0.1,0.1]", "mesh.element_size=0.1", "damping.alpha=0.7",
         "damping.beta=0.002", 'material.model="neohookean"', "output.render=false",
         # a moving pin across the middle, where two ranks' partition boundary lies (its
         # dofs are then ghosts of a rank: the lifting must read the state's ghost values)
         'pin=[{name="middle",min=[0.4,-1,-1],max=[0.6,1,1],velocity=[0.0,0.3,0.1]}]']
RTOL = 1e-12


def check(comm: MPI.Comm) -> list[str]:
    """Differences between the callbacks and the single form; one line per failure."""
    sim = Simulation(load_scene(None, SCENE), comm)
    p = sim.problem
    assert p.constant_terms is not None and len(p.constant_terms.terms) == 2
    V = p.V
    du, dv = ufl.TrialFunction(V), ufl.TestFunction(V)
    residual = ufl.derivative(p.ufl_objective, p.u, dv)
    whole = compile_forms({"objective": p.ufl_objective, "residual": residual,
                           "jacobian": ufl.derivative(residual, p.u, du)})
    rng = np.random.default_rng(comm.rank)
    n = p.u.x.array.size
    p.set_pinned_displacement(0.25)  # the pin has moved: u_bc != 0
    p.weight.value = 1.0 / 240.0
    failures = []
    for coefficient in (0.3, 0.05):  # the damping Hessian reassembled for the new c
        p.damping_coefficient.value = coefficient
        for name, f in (("u_pred", p.u_pred), ("u_anchor", p.u_anchor)):
            f.x.array[:] = 0.01 * rng.standard_normal(n)
            f.x.scatter_forward()
        for on_target in (False, True):
            # the pin's translation everywhere plus noise: det F > 0 on or off target
            p.u.x.array[:] = np.tile(0.25 * PIN_VELOCITY, n // 3) + \
                0.002 * rng.standard_normal(n)
            p.u.x.scatter_forward()
            x = compat.petsc_vec(p.u).copy()
            if on_target:
                fem_petsc.set_bc(x, p.bcs)
            label = f"c = {coefficient}, pins {'on' if on_target else 'off'} target"
            # the single form, as a nonlinear problem of DOLFINx assembles it (at the state
            # with its ghosts updated)
            p.set_state(x)
            g = p.assemble_scalar(whole["objective"])
            b_ref = fem_petsc.assemble_vector(whole["residual"])
            fem_petsc.apply_lifting(b_ref, [whole["jacobian"]], [p.bcs],
                                    [compat.petsc_vec(p.u)], -1.0)
            b_ref.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
            fem_petsc.set_bc(b_ref, p.bcs, x, -1.0)
            A_ref = fem_petsc.assemble_matrix(whole["jacobian"], p.bcs)
            A_ref.assemble()
            # the callbacks, given x with stale ghost entries as SNES leaves them (it never
            # updates them; under MPI a callback must not read them)
            with x.localForm() as local:
                local.array[x.getLocalSize():] = 1.0e3
            value = p.objective(None, x)
            b = p.create_vector()
            p.residual(None, x, b)
            for kind in ("aij", "baij"):
                A = p.create_matrix(kind)
                p.jacobian(None, x, A, A)
                probe, Az = A.createVecs()
                Az_ref = Az.duplicate()
                probe.setArray(rng.standard_normal(probe.getLocalSize()))
                A.mult(probe, Az)
                A_ref.mult(probe, Az_ref)
                diff = (Az - Az_ref).norm() / Az_ref.norm()
                if not diff <= RTOL:
                    failures.append(f"{label}: {kind} Jacobian action differs by {diff:.2e}")
            diff = abs(value - g) / abs(g)
            if not diff <= RTOL:
                failures.append(f"{label}: objective differs by {diff:.2e}")
            diff = (b - b_ref).norm() / b_ref.norm()
            if not diff <= RTOL:
                failures.append(f"{label}: residual differs by {diff:.2e}")
    return failures


def test_constant_terms_equal_the_single_form():
    assert check(MPI.COMM_WORLD) == []


@pytest.mark.mpi
def test_constant_terms_under_mpi(tmp_path):
    """The same on three ranks: ghosts, the pins' owners, the collective dot products."""
    run_file_under_mpirun(__file__, 3, tmp_path)


if __name__ == "__main__":
    failures = check(MPI.COMM_WORLD)
    if MPI.COMM_WORLD.rank == 0:
        print("\n".join(failures) or "constant terms: all equal")
    sys.exit(1 if failures else 0)
