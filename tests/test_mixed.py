"""The mixed (u, p) formulation for nearly and exactly incompressible solids.

Taylor-Hood P2/P1 with the perturbed Lagrangian of ``fem_anim/forms/incompressible.py``:

* Cook's membrane (plane strain, nu = 0.499975) converges to the published mid-edge
  displacement 16.4326 (``fem_anim/bench/mixed_verification.py``);
* a manufactured solution gives the L2 orders 3 (u) and 2 (p) of Taylor-Hood;
* an exactly incompressible body (nu = 0.5) keeps what the weak constraint guarantees:
  int q g(J) dX = 0 for every P1 q, so with g = J - 1 (stable neo-Hookean, Mooney-Rivlin)
  its total volume to solver tolerance at every step, and with g = ln J (neo-Hookean)
  int ln J dX = 0; the cell means of J stay within a measured bound of 1;
* the ``schur`` fieldsplit preset gives the ``ldlt`` steps, serial and under mpirun -n 2.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.sparse as sp
import ufl
from conftest import mpirun_command
from fem_anim.forms.kinematics import deformation_gradient
from fem_anim.forms.incompressible import MIXED_MATERIALS
from mpi4py import MPI
from scenes import beam, make_scene, wall_pin

from fem_anim import compat
from fem_anim.bench.mixed_verification import COOK_REFERENCE, cook_membrane, manufactured_errors
from fem_anim.simulation.loop import Simulation


def test_cook_membrane_converges_to_the_published_value():
    """Mid-edge u_y of n x n meshes: -5.51 %, -1.91 %, -0.77 % (n = 4, 8, 16), measured;
    n = 32 gives -0.28 % (``python -m fem_anim.bench.mixed_verification --full``). The
    re-entrant corner limits the rate: successive differences shrink by 3.1 then 2.4."""
    values = [cook_membrane(n) for n in (4, 8, 16)]
    errors = [v / COOK_REFERENCE - 1.0 for v in values]
    assert errors[0] < errors[1] < errors[2] < 0.0
    assert abs(errors[2]) < 0.01
    assert (values[1] - values[0]) / (values[2] - values[1]) > 2.5


def test_cook_membrane_in_3d():
    """The plane-strain membrane as a one-layer slab of tetrahedra with u_z = 0: measured
    15.613, 16.142, 16.317 (-4.99 %, -1.77 %, -0.71 %) for n = 4, 8, 16 (16 is the bench's)."""
    values = [cook_membrane(n, dim=3) for n in (4, 8)]
    errors = [v / COOK_REFERENCE - 1.0 for v in values]
    assert errors[0] < errors[1] < 0.0 and abs(errors[1]) < 0.025
    assert values[1] == pytest.approx(cook_membrane(8), rel=0.01)  # the 2D value


@pytest.mark.parametrize("model", ["neohookean",
                                   pytest.param("stable_neohookean", marks=pytest.mark.slow),
                                   pytest.param("mooney_rivlin", marks=pytest.mark.slow)])
def test_manufactured_solution_orders(model):
    """Fitted L2 orders of u (3) and p (2): measured (neo-Hookean) 2.97, 2.99 for u and
    3.09, 2.75 for p (p is pre-asymptotic at these sizes: 2.35 at n = 32)."""
    errors = np.array([manufactured_errors(n, model=model) for n in (4, 8, 16)])
    orders = np.log2(errors[:-1] / errors[1:])
    assert np.all(orders[:, 0] > 2.85), orders
    assert np.all(orders[:, 1] > 1.9), orders


def _mixed_scene(tmp_path, d=2, **sections):
    keys = {"element": {"degree": 2, "formulation": "mixed"},
            "material": {"poisson_ratio": 0.5, "model": "stable_neohookean",
                         "youngs_modulus": 1e4},
            "solver": {"preset": "ldlt"}, "time": {"steps": 6, "dt": 1.0 / 30.0},
            "gravity": {"acceleration": [0.0, -9.81, 0.0][:d]}, "pin": [wall_pin(d)]}
    for k, v in sections.items():
        keys[k] = keys.get(k, {}) | v
    return make_scene(tmp_path, beam("mixed", d, **keys))


class VolumeProbe:
    """int J dX, int g(J) dX and the cell means of J of a simulation's displacement."""

    def __init__(self, sim: Simulation, model: str):
        p = sim.problem
        self.p = p
        J = ufl.det(deformation_gradient(p.u))
        dx = ufl.Measure("dx", domain=sim.domain.mesh, metadata={"quadrature_degree": 4})
        q = ufl.TestFunction(p.W0)
        # the constraint as the problem integrates it (exactly, for polynomial g)
        constraint = MIXED_MATERIALS[model].constraint(J) * p.dx_elastic
        forms = {"volume": J * dx, "constraint": constraint,
                 "rest": 1.0 * dx, "l2": (J - 1.0) ** 2 * dx, "cells": (J - 1.0) * q * dx,
                 "cell_volume": q * dx}
        self.forms = compat.compile_forms_together(forms, {})
        from dolfinx.fem import petsc as fem_petsc

        self._vector = fem_petsc.assemble_vector
        self.rest = p.assemble_scalar(self.forms["rest"])

    def measure(self, u: np.ndarray) -> tuple[float, float, float, float]:
        """(int J / |Omega| - 1, int g(J) / |Omega|, max over owned cells |mean J - 1|,
        the root mean square of J - 1)."""
        self.p.u.x.array[:] = u
        rms = math.sqrt(self.p.assemble_scalar(self.forms["l2"]) / self.rest)
        volume = self.p.assemble_scalar(self.forms["volume"]) / self.rest - 1.0
        constraint = self.p.assemble_scalar(self.forms["constraint"]) / self.rest
        mean = self._vector(self.forms["cells"]).array / \
            self._vector(self.forms["cell_volume"]).array
        worst = self.p.comm.allreduce(float(np.abs(mean).max()), op=MPI.MAX)
        return volume, constraint, worst, rms


@pytest.mark.parametrize("model,exact_volume", [("stable_neohookean", True),
                                                 ("mooney_rivlin", True),
                                                 ("neohookean", False)])
def test_exactly_incompressible_body_keeps_its_volume(tmp_path, model, exact_volume):
    """nu = 0.5 (1/kappa = 0): a beam sagging under gravity for 6 steps of 1/30 s.

    The weak constraint with q = 1 is int g(J) dX = 0: to solver tolerance at every step
    (sqrt(N_p) ||r|| / (w mu), from the residual norm where Newton stopped). For g = J - 1
    that is the total volume; for neo-Hookean's g = ln J the volume changes at second order. J is not kept cell by cell: with a tip sag of 0.2 m
    (stable neo-Hookean) the root mean square of J - 1 is 4.8 %, 3.5 %, 2.4 % and the worst
    cell mean 6.9 %, 8.3 %, 13.7 % at element sizes 0.25, 0.125, 0.0625 m (measured): the
    mean square error falls, the worst cell is at the clamped corners, where the pressure is
    singular and gets worse as cells shrink there. Bounds here: the 0.25 m mesh.
    """
    sim = Simulation(_mixed_scene(tmp_path, material={"model": model}))
    probe = VolumeProbe(sim, model)
    state = sim.initial_state()
    worst_cell = worst_rms = 0.0
    for _ in range(6):
        state, stats = sim.step(state, 1.0 / 30.0)
        assert stats.reason > 0
        volume, constraint, cell, rms = probe.measure(state.u)
        # the pressure rows of the residual are w mu int q_i g(J) and sum_i q_i = 1
        p = sim.problem
        n_p = p.fields.Q.dofmap.index_map.size_global
        tolerance = math.sqrt(n_p) * stats.residual_norm / (p.weight.value * p.mu.value) / \
            probe.rest + 1e-14
        assert abs(constraint) <= tolerance, (constraint, tolerance)
        if exact_volume:
            assert abs(volume) <= tolerance, (volume, tolerance)
        else:
            assert 1e-8 < abs(volume) < 1e-3, volume
        worst_cell, worst_rms = max(worst_cell, cell), max(worst_rms, rms)
    sag = -state.u.reshape(-1, 2)[:, 1].min()
    assert 0.15 < sag < 0.25, sag
    assert worst_cell < 0.1 and worst_rms < 0.06, (worst_cell, worst_rms)
    assert math.isnan(stats.newton_decrement)  # no decrement for a saddle point


def test_schur_preset_gives_the_ldlt_steps(tmp_path):
    """nu = 0.4999, 3 steps: fieldsplit Schur (BoomerAMG on u, pressure mass for S) against
    MUMPS LDL^T: the same displacements to 1e-8 relative, more linear iterations."""
    runs = {}
    for preset in ("ldlt", "schur"):
        sim = Simulation(_mixed_scene(tmp_path, material={"poisson_ratio": 0.4999},
                                      solver={"preset": preset}))
        state = sim.initial_state()
        linear = 0
        for _ in range(3):
            state, stats = sim.step(state, 1.0 / 30.0)
            linear += stats.linear_its
        runs[preset] = state.u, linear
        if preset == "schur":
            pc = sim.minimiser.snes.getKSP().getPC()
            assert pc.getType() == "fieldsplit"
            sub = pc.getFieldSplitSubKSP()
            assert [k.getPC().getType() for k in sub] == ["hypre", "jacobi"]
    (u_ldlt, n_ldlt), (u_schur, n_schur) = runs["ldlt"], runs["schur"]
    assert np.linalg.norm(u_schur - u_ldlt) <= 1e-8 * np.linalg.norm(u_ldlt)
    assert n_schur > n_ldlt


@pytest.mark.mpi
@pytest.mark.parametrize("preset", ["ldlt", pytest.param("schur", marks=pytest.mark.slow)])
def test_mixed_run_under_mpi_equals_serial(tmp_path, preset):
    """The default 3D bar at nu = 0.5 (stable neo-Hookean), 3 steps, mpirun -n 2 against
    serial (the schur variant, BoomerAMG and fieldsplit index sets across ranks: slow)."""
    from test_mpi_runs import assert_same_run, run

    if mpirun_command(2) is None:
        pytest.skip("mpirun not available")
    args = ["run", "-q", "--set", "time.steps=3", "--set", "output.render=false",
            "--set", "mesh.element_size=0.1", "--set", "element.degree=2",
            "--set", 'element.formulation="mixed"', "--set", "material.poisson_ratio=0.5",
            "--set", 'material.model="stable_neohookean"', "--set", "damping.beta=0",
            "--solver", preset]
    outs = {}
    for ranks in (1, 2):
        outs[ranks] = tmp_path / f"n{ranks}"
        r = run([*args, "-o", str(outs[ranks])], tmp_path, ranks)
        assert r.returncode == 0, r.stderr
    assert_same_run(outs[1], outs[2])


# -- the numpy reference (fem_anim/reference/mixed_energy.py) -----------------------------------------
@pytest.mark.skipif(MPI.COMM_WORLD.size > 1, reason="serial reference")
@pytest.mark.parametrize("d", [2, 3])
@pytest.mark.parametrize("model", ["neohookean", "stable_neohookean", "mooney_rivlin"])
def test_mixed_energy_matches_the_numpy_reference(d, model):
    """Pi(x, p), its gradient and Hessian on a P1/P1 mixed space against the reference: the
    same UFL energy (forms.mixed.lagrangian) the solver binds, at a perturbed state with a
    random pressure; 1/kappa > 0 so that the pressure block is tested too. Tolerance 1e4 eps
    relative to the largest entry, as ASSEMBLY_RTOL in test_reference_comparison.py."""
    from dolfinx import fem
    from dolfinx.fem import petsc as fem_petsc
    from fem_anim.forms.incompressible import lagrangian

    from fem_anim import reference
    from fem_anim.mesh.simplex import mesh_from_arrays
    from fem_anim.output.files import VertexGather
    from fem_anim.reference.mixed_energy import mixed_energy, mixed_gradient, mixed_hessian

    points, cells = reference.box_mesh((3,) * d, (1.0,) + (0.5,) * (d - 1))
    domain = mesh_from_arrays(MPI.COMM_SELF, points, cells, None, "mixed reference")
    mu, inv_kappa, ratio = 2.0, 0.3, 0.3
    W = compat.mixed_space(domain.mesh, 1, 1)
    V, u_dofs = compat.collapse_subspace(W, 0)
    Q, p_dofs = compat.collapse_subspace(W, 1)
    nodes_V, nodes_Q = VertexGather(domain, V).node_to_dof, VertexGather(domain, Q).node_to_dof
    n_vertices = points.shape[0]
    order = np.empty(points.size + n_vertices, dtype=np.int64)  # reference dof -> W dof
    vertices = domain.input_index
    order[(vertices[:, None] * d + np.arange(d)).ravel()] = \
        u_dofs[(nodes_V[:, None] * d + np.arange(d)).ravel()]
    order[points.size + vertices] = p_dofs[nodes_Q]
    rng = np.random.default_rng(17)
    x = points.ravel() + 0.01 * rng.standard_normal(points.size)
    p = rng.standard_normal(n_vertices)
    w = fem.Function(W)
    w.x.array[order] = np.concatenate([x - points.ravel(), p])
    u_w, p_w = ufl.split(w)
    dx = ufl.Measure("dx", domain=domain.mesh, metadata={"quadrature_degree": 2})
    energy = lagrangian(MIXED_MATERIALS[model], deformation_gradient(u_w), p_w, mu, inv_kappa,
                        ratio) * dx
    dw, dw2 = ufl.TestFunction(W), ufl.TrialFunction(W)
    forms = compat.compile_forms_together(
        {"energy": energy, "gradient": ufl.derivative(energy, w, dw),
         "hessian": ufl.derivative(ufl.derivative(energy, w, dw), w, dw2)}, {})
    args = (points, cells, model, mu, inv_kappa, x, p, ratio)
    rtol = 1e4 * np.finfo(float).eps
    assert fem.assemble_scalar(forms["energy"]) == pytest.approx(mixed_energy(*args), rel=rtol)
    gradient = fem_petsc.assemble_vector(forms["gradient"]).array[order]
    expected = mixed_gradient(*args)
    assert np.abs(gradient - expected).max() <= rtol * np.abs(expected).max()
    A = fem_petsc.assemble_matrix(forms["hessian"])
    A.assemble()
    indptr, indices, data = A.getValuesCSR()
    inverse = np.argsort(order)
    H = sp.csr_matrix((data, inverse[indices], indptr), shape=A.getSize())[order]
    expected_H = mixed_hessian(*args)
    assert abs(H - expected_H).max() <= rtol * abs(expected_H).max()


# -- the extremes suite (fem_anim/bench/extremes.py) ------------------------------------------
def test_mixed_rows_of_the_locking_table_do_not_lock():
    """2D cantilever, E = 1e7 Pa, settled under gravity: the mixed element at element size
    0.1 against itself at 0.05 within 2 % for nu = 0.49 ... 0.5, and within 5 % of plane-strain
    beam theory (P1 at nu = 0.4999 reaches 0.12 of it: tests/test_extremes.py)."""
    from fem_anim.bench.extremes import mixed_locking_rows

    rows = mixed_locking_rows(full=False)
    assert [r["nu"] for r in rows] == [0.49, 0.499, 0.4999, 0.5]
    for r in rows:
        assert abs(r["ratio"] - 1.0) < 0.02, r
        assert abs(r["reference"] / r["beam_theory"] - 1.0) < 0.05, r


def test_the_default_scene_mixed_keeps_its_damping_and_gets_a_saddle_point_preset():
    """The default scene made mixed keeps its Rayleigh damping and, naming no preset, gets
    ldlt (the saddle point is indefinite: cholesky cannot factorise it); a named preset that
    cannot solve it is one error naming the ones that can."""
    from fem_anim.errors import FemAnimError
    from fem_anim.scene import MIXED_DEFAULT_PRESET, load_scene
    from fem_anim.simulation.loop import solver_options

    mixed = ["element.degree=2", 'element.formulation="mixed"']
    scene = load_scene(None, mixed)
    assert scene.damped and scene["solver"]["preset"] == MIXED_DEFAULT_PRESET == "ldlt"
    assert load_scene(None, [*mixed, "solver.mode=\"preview\""])["solver"]["preset"] == "ldlt"
    assert load_scene(None, [*mixed, 'solver.preset="lu"'])["solver"]["preset"] == "lu"
    assert load_scene(None, [])["solver"]["preset"] == "cholesky"
    named = load_scene(None, [*mixed, 'solver.preset="cholesky"'])
    with pytest.raises(FemAnimError, match=r"cholesky.*use one of ldlt, lu, schur"):
        solver_options(named)
    with pytest.raises(FemAnimError, match=r"--solver = 'cg-icc'.*use one of ldlt"):
        solver_options(scene, preset="cg-icc")
