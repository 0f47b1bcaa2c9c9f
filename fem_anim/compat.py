"""The one place that knows which DOLFINx release is installed.

Written against Debian's DOLFINx 0.5.2. Names that changed in later releases are
wrapped here, so moving to a newer DOLFINx is a change to this file only:

=======================================  ==========================================
0.5.2 (here)                             later releases
=======================================  ==========================================
``fem.VectorFunctionSpace(mesh, el)``    ``fem.functionspace(mesh, element(...))``
``fem.FunctionSpace(mesh, el)``          ``fem.functionspace``
``u.vector``                             ``u.x.petsc_vec``
``plot.create_vtk_mesh``                 ``plot.vtk_mesh``
``mesh.geometry.dofmap`` (adjacency)     ``mesh.geometry.dofmap`` (2D array)
``fem.Expression(e, points)``            same, ``X`` attribute renamed
``cpp.io.distribute_entity_data(m, ..)`` signature changed (0.7)
``mesh.create_mesh(comm, cells, x, d)``  ``d`` became a basix/ufl element (0.8)
=======================================  ==========================================
"""

from __future__ import annotations

import numpy as np
import ufl
from dolfinx import cpp as _cpp
from dolfinx import fem, plot
from dolfinx import mesh as dmesh

__all__ = [
    "vector_space",
    "scalar_space",
    "quadrature_space",
    "petsc_vec",
    "vtk_mesh",
    "geometry_dofmap",
    "create_mesh",
    "cell_tags",
    "quadrature_points",
    "interpolation_points",
]


def vector_space(mesh, degree: int) -> fem.FunctionSpace:
    """Vector-valued continuous Lagrange space of the given degree."""
    return fem.VectorFunctionSpace(mesh, ("Lagrange", degree))


def scalar_space(mesh, family: str, degree: int) -> fem.FunctionSpace:
    """Scalar space, e.g. ``("DG", 0)`` for per-cell data."""
    return fem.FunctionSpace(mesh, (family, degree))


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


def vtk_mesh(V_or_mesh):
    """VTK topology, cell types and geometry of a mesh or P1/P2 function space."""
    return plot.create_vtk_mesh(V_or_mesh)


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


def cell_tags(mesh, cells: np.ndarray, values: np.ndarray):
    """Distribute per-input-cell markers onto the distributed mesh as MeshTags."""
    tdim = mesh.topology.dim
    entities, local_values = _cpp.io.distribute_entity_data(mesh, tdim, cells, values)
    mesh.topology.create_connectivity(tdim, 0)
    adj = _cpp.graph.AdjacencyList_int32(entities)
    return dmesh.meshtags_from_entities(mesh, tdim, adj, local_values.astype(np.int32))


def interpolation_points(V: fem.FunctionSpace) -> np.ndarray:
    """Reference points at which a space's interpolation evaluates expressions."""
    return V.element.interpolation_points


def quadrature_points(V: fem.FunctionSpace) -> np.ndarray:
    """Reference quadrature points of a quadrature space (same as its interpolation points)."""
    return interpolation_points(V)
