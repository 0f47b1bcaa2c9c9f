"""The one place that knows which DOLFINx release is installed.

Written against Debian's DOLFINx 0.5.2. Names that changed in later releases are
wrapped here, so moving to a newer DOLFINx is a change to this file only:

=======================================  ==========================================
0.5.2 (here)                             later releases
=======================================  ==========================================
``fem.VectorFunctionSpace(mesh, el)``    ``fem.functionspace(mesh, element(...))``
``fem.FunctionSpace(mesh, el)``          ``fem.functionspace``
``u.vector``                             ``u.x.petsc_vec``
``mesh.geometry.dofmap`` (adjacency)     ``mesh.geometry.dofmap`` (2D array)
``Quadrature`` ufl element                basix quadrature element (0.7)
``mesh.create_mesh(comm, cells, x, d)``  ``d`` became a basix/ufl element (0.8)
``geometry.BoundingBoxTree(mesh, d)``    ``geometry.bb_tree(mesh, d)`` (0.7)
``fem.FormMetaClass``, ``jit.ffcx_jit``   ``fem.Form``, ``form_cpp_class`` (0.7)
=======================================  ==========================================
"""

from __future__ import annotations

import ffcx
import ffcx.codegeneration.jit
import numpy as np
import ufl
from dolfinx import cpp as _cpp
from dolfinx import fem, geometry, jit
from dolfinx import mesh as dmesh

__all__ = [
    "vector_space",
    "cell_space",
    "quadrature_space",
    "petsc_vec",
    "cell_dofs",
    "geometry_dofmap",
    "create_mesh",
    "colliding_cells",
    "compile_forms_together",
]


def vector_space(mesh, degree: int) -> fem.FunctionSpace:
    """Vector-valued continuous Lagrange space of the given degree."""
    return fem.VectorFunctionSpace(mesh, ("Lagrange", degree))


def cell_space(mesh) -> fem.FunctionSpace:
    """Piecewise-constant scalars: one value per cell (DG0)."""
    return fem.FunctionSpace(mesh, ("DG", 0))


def quadrature_space(mesh, degree: int, shape: tuple[int, ...] = ()) -> fem.FunctionSpace:
    """Quadrature-point data space of the default scheme at ``degree``."""
    cell = mesh.ufl_cell()
    if shape:
        element = ufl.TensorElement("Quadrature", cell, degree, shape=shape,
                                    quad_scheme="default")
    else:
        element = ufl.FiniteElement("Quadrature", cell, degree, quad_scheme="default")
    return fem.FunctionSpace(mesh, element)


def petsc_vec(u: fem.Function):
    """The PETSc vector that holds a Function's degrees of freedom."""
    return u.vector



def cell_dofs(V) -> np.ndarray:
    """Cell -> dof (block) indices of a function space as a (num_cells, dofs_per_cell) array
    (0.9: ``V.dofmap.list`` is that array already)."""
    dofs = V.dofmap.list.array
    return dofs.reshape(-1, V.dofmap.dof_layout.num_dofs)


def geometry_dofmap(mesh) -> np.ndarray:
    """Cell -> geometry node indices as a (num_cells, nodes_per_cell) array."""
    dofmap = mesh.geometry.dofmap
    num_cells = mesh.topology.index_map(mesh.topology.dim).size_local + \
        mesh.topology.index_map(mesh.topology.dim).num_ghosts
    return dofmap.array.reshape(num_cells, -1)


def create_mesh(comm, cells: np.ndarray, x: np.ndarray, gdim: int, cell_name: str):
    """Distribute a P1 simplex mesh given on one rank (other ranks pass empty arrays)."""
    domain = ufl.Mesh(ufl.VectorElement("Lagrange", ufl.Cell(cell_name, geometric_dimension=gdim),
                                        1))
    return dmesh.create_mesh(comm, cells, x, domain)




def colliding_cells(mesh, points: np.ndarray):
    """Local cells containing each of ``points`` (n, 3): an adjacency list point -> cells."""
    tree = geometry.BoundingBoxTree(mesh, mesh.topology.dim)
    candidates = geometry.compute_collisions(tree, points)
    return geometry.compute_colliding_cells(mesh, candidates, points)


def compile_forms_together(forms: dict[str, ufl.Form],
                           jit_params: dict) -> dict[str, fem.FormMetaClass]:
    """Compile several real-valued forms on one mesh into one FFCx module (one gcc run).

    ``fem.form`` compiles every form into its own C module; the forms of one problem
    compiled together take about half the time (9 forms of the default scene: 3.0 s
    against 5.8 s with a cold cache). Under MPI rank 0 compiles and the others then load
    the module from the cache (DOLFINx's ``mpi_jit_decorator``). The Forms built are the
    ones ``fem.form`` builds (same coefficients, constants, subdomain data).
    """
    ufl_forms = list(forms.values())
    mesh = ufl_forms[0].ufl_domain().ufl_cargo()
    p_ffcx = ffcx.get_parameters({"scalar_type": "double"})
    p_jit = jit.get_parameters(jit_params)

    @jit.mpi_jit_decorator
    def compile_all():
        return ffcx.codegeneration.jit.compile_forms(ufl_forms, parameters=p_ffcx, **p_jit)

    compiled, module, code = compile_all(mesh.comm)
    formcls = type("Form", (fem.FormMetaClass, _cpp.fem.Form_float64), {})
    out = {}
    for name, form, ufcx_form in zip(forms, ufl_forms, compiled):
        subdomains, = form.subdomain_data().values()
        spaces = [arg.ufl_function_space()._cpp_object for arg in form.arguments()]
        original = form.coefficients()
        coefficients = [original[ufcx_form.original_coefficient_position[i]]._cpp_object
                        for i in range(ufcx_form.num_coefficients)]
        constants = [c._cpp_object for c in form.constants()]
        types = _cpp.fem.IntegralType
        markers = {types.cell: subdomains.get("cell"),
                   types.exterior_facet: subdomains.get("exterior_facet"),
                   types.interior_facet: subdomains.get("interior_facet"),
                   types.vertex: subdomains.get("vertex")}
        out[name] = formcls(ufcx_form, spaces, coefficients, constants, markers, mesh,
                            module.ffi, code)
    return out
