"""Quasi-static verification of the mixed (u, p) formulation: Cook's membrane and a
manufactured solution.

    python -m fem_anim.bench.mixed_verification [--full]

Both are boundary-value problems of the perturbed Lagrangian of :mod:`fem_anim.forms.incompressible`
on the Taylor-Hood space of :func:`fem_anim.compat.mixed_space`, solved by Newton's method
on the residual with a MUMPS LDL^T (the time stepper is not involved: no inertia),

    Pi(u, p) = int W(F(u), p) dX - int f . u dX - int h p dX - int_Gamma_N t . u dA.

* :func:`cook_membrane`: the trapezoid (0, 0), (48, 0), (48, 60), (0, 44) mapped from a
  48 x 44 block (Cook 1974), clamped at x = 0, a vertical traction of total force 1 per
  unit thickness on x = 48, plane strain, lambda = 7500, mu = 0.375 (nu = 0.499975). The
  converged vertical displacement of the mid point (48, 52) of the loaded edge is
  16.4326 (linear elasticity; Krysl, FinEALE ``Cook_3D_strain_T10.m``: ``convutip =
  16.432584376299037``, NICE-T6 with Richardson extrapolation). The neo-Hookean split
  is linear elasticity with the same mu, lambda at small strain, so the load is scaled
  by ``load`` (1e-4) and the displacement divided by it.
* :func:`manufactured_errors`: a smooth (u, p) on the unit square, its body force
  f = -div P(u, p) and volumetric source h = g(J) - p/kappa computed symbolically, u = u_ex
  on the boundary; L2 errors of u and p for the orders of accuracy (Taylor-Hood: 3 and 2).
"""

from __future__ import annotations

import argparse
import math

import numpy as np
import ufl
from dolfinx import fem
from dolfinx import mesh as dmesh
from dolfinx.fem import petsc as fem_petsc
from mpi4py import MPI
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.forms.kinematics import deformation_gradient
from fem_anim.forms.incompressible import MIXED_MATERIALS, compliance, lagrangian
from fem_anim.bench.measure import PointSampler

__all__ = ["COOK_REFERENCE", "StaticMixed", "cook_membrane", "main", "manufactured_errors"]

#: Converged mid-edge vertical displacement of the plane-strain Cook membrane (module docs).
COOK_REFERENCE = 16.432584376299037


class StaticMixed:
    """Newton on the residual of Pi(u, p) above, on a Taylor-Hood space (P2/P1).

    Args:
        mesh: The mesh.
        model: A key of :data:`fem_anim.forms.incompressible.MIXED_MATERIALS`.
        E, nu: Young's modulus and Poisson's ratio in (0, 0.5].
        loads: ``loads(u, p, x)`` -> the UFL load potential (subtracted from int W).
        dirichlet: ``(marker, values)``: u = values(x) (numpy, shape (d, n)) where marker(x).
        held: Components held at zero at every node (3D plane strain: ``(2,)``).
    """

    def __init__(self, mesh, model: str, E: float, nu: float, loads, dirichlet,
                 quadrature_degree: int = 4, held: tuple[int, ...] = ()):
        self.mesh = mesh
        d = mesh.topology.dim
        self.W = compat.mixed_space(mesh, 2, 1)
        self.V, self.u_dofs = compat.collapse_subspace(self.W, 0)
        self.Q, self.p_dofs = compat.collapse_subspace(self.W, 1)
        self.w = fem.Function(self.W)
        u, p = ufl.split(self.w)
        material = MIXED_MATERIALS[model]
        self.mu = E / (2.0 * (1.0 + nu))
        self.inv_kappa = compliance(material, E, nu, d)
        x = ufl.SpatialCoordinate(mesh)
        dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": quadrature_degree})
        energy = lagrangian(material, deformation_gradient(u), p, self.mu, self.inv_kappa) * dx
        energy -= loads(u, p, x)
        dw, w_ = ufl.TestFunction(self.W), ufl.TrialFunction(self.W)
        residual = ufl.derivative(energy, self.w, dw)
        forms = compat.compile_forms_together(
            {"residual": residual, "jacobian": ufl.derivative(residual, self.w, w_)}, {})
        self.residual_form, self.jacobian_form = forms["residual"], forms["jacobian"]
        marker, values = dirichlet
        boundary = fem.Function(self.V)
        boundary.interpolate(values)
        blocks = fem.locate_dofs_geometrical(self.V, marker)
        unrolled = (blocks[:, None] * d + np.arange(d)).ravel()
        self.w.x.array[self.u_dofs[unrolled]] = boundary.x.array[unrolled]
        every = np.arange(self.V.dofmap.index_map.size_local
                          + self.V.dofmap.index_map.num_ghosts)
        for component in held:
            unrolled = np.union1d(unrolled, every * d + component)
        zero = fem.Function(self.V)
        self.bcs = [fem.dirichletbc(zero, [self.u_dofs[unrolled], unrolled.astype(np.int32)],
                                    self.W.sub(0))]

    def solve(self, rtol: float = 1e-10, max_it: int = 25) -> int:
        """Newton iterations to ||r|| <= rtol ||r_0||, or to the round-off floor (an
        iteration that no longer halves ||r|| once it is below 1e-6 ||r_0||: quadratic
        convergence has ended); returns their number."""
        A = fem_petsc.create_matrix(self.jacobian_form)
        b = fem_petsc.create_vector(self.residual_form)
        ksp = PETSc.KSP().create(self.mesh.comm)
        ksp.setType("preonly")
        pc = ksp.getPC()
        pc.setType("lu")
        pc.setFactorSolverType("mumps")
        w = compat.petsc_vec(self.w)
        step = w.duplicate()
        first = previous = None
        try:
            for it in range(max_it + 1):
                with b.localForm() as local:
                    local.set(0.0)
                fem_petsc.assemble_vector(b, self.residual_form)
                b.ghostUpdate(addv=PETSc.InsertMode.ADD, mode=PETSc.ScatterMode.REVERSE)
                fem_petsc.set_bc(b, self.bcs)  # zero: the increments keep the boundary values
                norm = b.norm()
                first = norm if first is None else first
                if norm <= rtol * first or norm == 0.0 or (
                        previous is not None and norm > 0.5 * previous and norm < 1e-6 * first):
                    return it
                previous = norm
                A.zeroEntries()
                fem_petsc.assemble_matrix(A, self.jacobian_form, self.bcs)
                A.assemble()
                ksp.setOperators(A)
                ksp.solve(b, step)
                w.axpy(-1.0, step)
                w.ghostUpdate(addv=PETSc.InsertMode.INSERT, mode=PETSc.ScatterMode.FORWARD)
            raise RuntimeError(f"Newton did not converge in {max_it} iterations "
                               f"(residual {norm:.3e} of {first:.3e})")
        finally:
            for obj in (A, b, ksp, step):
                obj.destroy()

    def fields(self) -> tuple[fem.Function, fem.Function]:
        """The displacement and the pressure as Functions of their own spaces."""
        u, p = fem.Function(self.V), fem.Function(self.Q)
        u.x.array[:] = self.w.x.array[self.u_dofs]
        p.x.array[:] = self.w.x.array[self.p_dofs]
        return u, p


def cook_mesh(n: int, comm=MPI.COMM_WORLD, dim: int = 2):
    """Cook's trapezoid, n x n squares of the 48 x 44 block cut into triangles, mapped; in 3D
    a slab of one layer of thickness 48 / n (tetrahedra)."""
    if dim == 2:
        mesh = dmesh.create_rectangle(comm, [np.zeros(2), np.array([48.0, 44.0])], [n, n],
                                      dmesh.CellType.triangle)
    else:
        mesh = dmesh.create_box(comm, [np.zeros(3), np.array([48.0, 44.0, 48.0 / n])],
                                [n, n, 1], dmesh.CellType.tetrahedron)
    x = mesh.geometry.x
    x[:, 1] += x[:, 0] / 48.0 * (44.0 - x[:, 1] / 44.0 * 28.0)
    return mesh


def cook_membrane(n: int, model: str = "neohookean", load: float = 1e-4,
                  comm=MPI.COMM_WORLD, dim: int = 2) -> float:
    """Vertical displacement of (48, 52) over ``load`` (compare :data:`COOK_REFERENCE`).

    ``dim = 3``: the same plane-strain problem on a one-layer slab of tetrahedra with
    u_z = 0 at every node (FinEALE's 3D version of it).
    """
    lmbda, mu = 7500.0, 0.375
    nu = lmbda / (2.0 * (lmbda + mu))
    E = mu * (3.0 * lmbda + 2.0 * mu) / (lmbda + mu)
    mesh = cook_mesh(n, comm, dim)
    facets = dmesh.locate_entities_boundary(mesh, dim - 1, lambda x: np.isclose(x[0], 48.0))
    tags = dmesh.meshtags(mesh, dim - 1, np.sort(facets).astype(np.int32),
                          np.ones(facets.size, dtype=np.int32))
    ds = ufl.Measure("ds", domain=mesh, subdomain_data=tags)
    traction = ufl.as_vector([0.0, load / 16.0, 0.0][:dim])

    def loads(u, p, x):
        return ufl.dot(traction, u) * ds(1)

    problem = StaticMixed(mesh, model, E, nu, loads,
                          (lambda x: np.isclose(x[0], 0.0), lambda x: np.zeros((dim, x.shape[1]))),
                          held=(2,) if dim == 3 else ())
    problem.solve()
    u, _ = problem.fields()
    point = np.array([[48.0, 52.0, 24.0 / n][:dim]])
    return float(PointSampler(mesh, point).sample(u)[0, 1] / load)


def _exact(x, amplitude: float, mu: float):
    """u_ex, p_ex (UFL) on the unit square: a smooth shear flow and a pressure ~ mu."""
    pi = math.pi
    u = amplitude * ufl.as_vector([ufl.sin(pi * x[0]) * ufl.cos(pi * x[1]),
                                   -ufl.cos(pi * x[0]) * ufl.sin(pi * x[1])
                                   + 0.5 * ufl.sin(pi * x[0]) * x[1] ** 2])
    p = 0.3 * mu * ufl.cos(pi * x[0]) * ufl.cos(pi * x[1])
    return u, p


def manufactured_errors(n: int, model: str = "neohookean", nu: float = 0.499,
                        amplitude: float = 0.05, comm=MPI.COMM_WORLD) -> tuple[float, float]:
    """L2 errors ``(||u - u_ex||, ||p - p_ex|| / mu)`` on an n x n unit-square mesh."""
    E = 1.0
    mu = E / (2.0 * (1.0 + nu))
    material = MIXED_MATERIALS[model]
    inv_kappa = compliance(material, E, nu, 2)
    mesh = dmesh.create_unit_square(comm, n, n)
    x = ufl.SpatialCoordinate(mesh)
    u_ex, p_ex = _exact(x, amplitude, mu)
    F = ufl.variable(deformation_gradient(u_ex))
    P = ufl.diff(lagrangian(material, F, p_ex, mu, inv_kappa), F)
    f = -ufl.div(P)
    h = material.constraint(ufl.det(F)) - inv_kappa * p_ex
    dx = ufl.Measure("dx", domain=mesh, metadata={"quadrature_degree": 8})

    def loads(u, p, _):
        return (ufl.dot(f, u) + h * p) * dx

    pi = math.pi

    def boundary(x):
        return (amplitude * np.vstack([np.sin(pi * x[0]) * np.cos(pi * x[1]),
                                       -np.cos(pi * x[0]) * np.sin(pi * x[1])
                                       + 0.5 * np.sin(pi * x[0]) * x[1] ** 2]))

    problem = StaticMixed(mesh, model, E, nu, loads, (lambda x: np.full(x.shape[1], True),
                                                      boundary))
    problem.solve()
    u, p = problem.fields()
    errors = compat.compile_forms_together(
        {"u": ufl.inner(u - u_ex, u - u_ex) * dx, "p": (p - p_ex) ** 2 / mu**2 * dx}, {})
    return tuple(math.sqrt(comm.allreduce(fem.assemble_scalar(errors[k]), op=MPI.SUM))
                 for k in ("u", "p"))


def main(argv: list[str] | None = None) -> int:
    """Print the Cook membrane and the manufactured-solution tables."""
    parser = argparse.ArgumentParser(prog="python -m fem_anim.bench.mixed_verification")
    parser.add_argument("--full", action="store_true", help="finer meshes")
    args = parser.parse_args(argv)
    sizes = (4, 8, 16, 32) if args.full else (4, 8, 16)
    rank0 = MPI.COMM_WORLD.rank == 0
    rows = [(n, cook_membrane(n)) for n in sizes]
    if rank0:
        print(f"Cook's membrane, plane strain, nu = 0.499975, P2/P1 (reference "
              f"{COOK_REFERENCE:.4f})\n\n| n x n | u_y(48, 52) | error |\n|---|---|---|")
        for n, value in rows:
            print(f"| {n} | {value:.4f} | {100 * (value / COOK_REFERENCE - 1):+.3f} % |")
    rows3 = [(n, cook_membrane(n, dim=3)) for n in sizes[:3]]
    if rank0:
        print("\nThe same, 3D: one layer of tetrahedra, u_z = 0 (plane strain)\n\n"
              "| n x n x 1 | u_y(48, 52) | error |\n|---|---|---|")
        for n, value in rows3:
            print(f"| {n} | {value:.4f} | {100 * (value / COOK_REFERENCE - 1):+.3f} % |")
    errors = [manufactured_errors(n) for n in sizes]
    if rank0:
        print("\nManufactured solution, neo-Hookean, nu = 0.499\n\n"
              "| n | L2 error u | order | L2 error p / mu | order |\n|---|---|---|---|---|")
        for i, (n, (eu, ep)) in enumerate(zip(sizes, errors)):
            orders = ["", ""] if i == 0 else [
                f"{math.log2(errors[i - 1][k] / errors[i][k]):.2f}" for k in (0, 1)]
            print(f"| {n} | {eu:.3e} | {orders[0]} | {ep:.3e} | {orders[1]} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
