"""Kirchhoff-Love bending of P2 shells against the numpy reference and plate theory.

The C0 interior-penalty energy of :mod:`fem_anim.forms.shell_kirchhoff_love` (through
:class:`fem_anim.problem.shell_terms.ShellEnergy` with ``bending_model = "kirchhoff_love"``)
is compared with the hyper-dual reference :mod:`fem_anim.reference.shell_kl_energy` (energy,
gradient, Hessian), and a clamped plate's tip deflection converges to Kirchhoff-Love's
``q L^4 / (8 D)`` at second order (docs/cloth.md, "Kirchhoff-Love bending").
"""

from __future__ import annotations

import numpy as np
import pytest
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.forms.lame import lame_parameters
from fem_anim.forms.shell_bending import flexural_rigidity
from fem_anim.meshes.sheet import structured_sheet
from fem_anim.problem.shell_terms import ShellEnergy, shell_measures
from fem_anim.reference import shell_kl_energy as reference

MU, LMBDA, THICKNESS, D, NU = 3.0, 2.0, 0.1, 0.7, 0.3


def p2_surface(points, cells, comm=MPI.COMM_SELF):
    """The DOLFINx surface mesh, its P2 vector space, the reference's nodes and
    ``order[dolfinx dof] = reference dof`` (serial)."""
    mesh = compat.create_mesh(comm, np.asarray(cells, np.int64), points, 3, "triangle")
    V = compat.vector_space(mesh, 2)
    nodes, _ = reference.p2_nodes(points, cells)
    coords = V.tabulate_dof_coordinates()
    node = np.argmin(np.linalg.norm(coords[:, None] - nodes[None], axis=2), axis=1)
    assert np.allclose(coords, nodes[node])
    return mesh, V, nodes, (node[:, None] * 3 + np.arange(3)).ravel()


def clamp_measure(mesh, where):
    """The exterior-facet measure of the boundary edges whose midpoints satisfy ``where``
    (``(3, k)`` points -> ``k`` bools; degree-2 rule, as :func:`shell_measures`), tagged 1."""
    mesh.topology.create_connectivity(1, 2)
    boundary = dmesh.locate_entities_boundary(mesh, 1, lambda y: np.full(y.shape[1], True))
    midpoints = dmesh.compute_midpoints(mesh, 1, boundary)
    facets = np.sort(boundary[where(midpoints.T)]).astype(np.int32)
    tags = dmesh.meshtags(mesh, 1, facets, np.ones(len(facets), np.int32))
    return ufl.Measure("ds", domain=mesh, subdomain_data=tags,
                       metadata={"quadrature_degree": 2})(1)


def kl_shell(mesh, D_value, nu):
    return ShellEnergy("stvk", MU, LMBDA, THICKNESS, fem.Constant(
        mesh, PETSc.ScalarType(D_value)), "kirchhoff_love", fem.Constant(
        mesh, PETSc.ScalarType(nu)))


def assemble(form, u):
    """Energy, gradient and dense Hessian of ``form`` in ``u`` (DOLFINx dof order)."""
    E = fem.assemble_scalar(fem.form(form))
    g = fem_petsc.assemble_vector(fem.form(ufl.derivative(form, u))).array.copy()
    H = fem_petsc.assemble_matrix(fem.form(ufl.derivative(ufl.derivative(form, u), u)))
    H.assemble()
    dense = H.convert("dense")
    return E, g, dense.getDenseArray().copy()


def test_reference_rules_are_the_compiled_ones():
    """The reference's cell and edge rules are basix's degree-2 rules (the forms')."""
    for (points, weights), (ref_p, ref_w) in (
            (compat.reference_quadrature("triangle", 2), reference.CELL_RULE),
            (compat.reference_quadrature("interval", 2), reference.EDGE_RULE)):
        key = np.lexsort(np.atleast_2d(np.asarray(points).T)[::-1])
        rkey = np.lexsort(np.atleast_2d(np.asarray(ref_p).reshape(len(ref_w), -1).T)[::-1])
        assert np.allclose(np.asarray(points).reshape(len(weights), -1)[key],
                           np.asarray(ref_p).reshape(len(ref_w), -1)[rkey], atol=1e-14)
        assert np.allclose(np.asarray(weights)[key], ref_w[rkey], atol=1e-14)


def test_energy_gradient_hessian_equal_the_reference():
    """Membrane + Kirchhoff-Love bending (cells, interior edges, a clamped edge): energy,
    gradient and Hessian = the hyper-dual reference to 1e-10, on a rest surface that is not
    flat with a large random displacement; every other DOLFINx triangle is reversed (the
    reference orients by topology)."""
    rng = np.random.default_rng(2)
    points, cells = structured_sheet([1.0, 1.0], [2, 2], triangulation="alternate")
    points = points + 0.05 * rng.standard_normal(points.shape)
    flipped = cells.copy()
    flipped[::2] = flipped[::2, ::-1]
    mesh, V, nodes, order = p2_surface(points, flipped)
    u = fem.Function(V)
    displacement = 0.2 * rng.standard_normal(nodes.shape)
    u.x.array[:] = displacement.ravel()[order]
    x = (nodes + displacement).ravel()
    dx, dS = shell_measures(mesh, 2)
    x0 = points[:, 0]
    on_left = np.flatnonzero(np.abs(x0 - x0.min()) < 0.2)
    clamped = [tuple(e) for e in ((on_left[0], on_left[1]), (on_left[1], on_left[2]))]
    # the clamped edges' midpoints (rest) locate the DOLFINx facets
    mids = np.array([(points[a] + points[b]) / 2 for a, b in clamped])
    ds = clamp_measure(mesh, lambda y: np.min(np.linalg.norm(
        y.T[:, None, :] - mids[None], axis=2), axis=1) < 1e-9)
    lengths = sum(np.linalg.norm(points[a] - points[b]) for a, b in clamped)
    assert fem.assemble_scalar(fem.form(fem.Constant(mesh, PETSc.ScalarType(1.0)) * ds)) == \
        pytest.approx(lengths, rel=1e-12)  # the clamp is there
    shell = kl_shell(mesh, D, NU)
    E, g, H = assemble(shell.energy(u, dx, dS) + shell.clamp_energy(u, ds), u)
    args = (points, cells, "stvk", MU, LMBDA, THICKNESS, D, NU, x)
    E_ref = reference.kl_energy(*args, clamped=clamped)
    g_ref = reference.kl_gradient(*args, clamped=clamped)[order]
    H_ref = reference.kl_hessian(*args, clamped=clamped).toarray()[np.ix_(order, order)]
    assert abs(E - E_ref) <= 1e-10 * abs(E_ref)
    assert np.abs(g - g_ref).max() <= 1e-10 * np.abs(g_ref).max()
    assert np.abs(H - H_ref).max() <= 1e-10 * np.abs(H_ref).max()
    # the bending part is there and is not negligible
    assert reference.kl_energy(*args[:6], 0.0, NU, x) < 0.5 * E_ref
