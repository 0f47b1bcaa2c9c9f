"""The gradient per cell: dJ/dc with a parameter's value taken cell by cell.

The material constants (E, nu, rho), the Rayleigh coefficients and an obstacle's friction
coefficient enter the step objective g of seed eq. 4 as piecewise-constant (DG0)
coefficients (:mod:`fem_anim.adjoint.parameters`), and the backward sweep assembles
-<dR/dc, lambda> in the direction of the DG0 test function: one value per cell, summed over
the steps (:attr:`fem_anim.adjoint.backward.BackwardSweep.cell_gradient`). Per cell it is
dJ/dtheta_c, the derivative with respect to the parameter's value on that cell alone
(E and nu combined from mu and lambda by the chain rule at the cell's values); summed over
the parameter's cells it is the parameter's gradient. Zero off the parameter's cells.

:func:`cell_functions` gives them as DG0 Functions (for UFL or DOLFINx's writers);
:func:`write_cell_gradient` writes them as cell data of a VTU file in the input mesh's cell
order (ParaView and meshio read it; the same file on any number of ranks).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from dolfinx import fem
from petsc4py import PETSc

from fem_anim import compat
from fem_anim.errors import FemAnimError, describe_os_error

__all__ = ["cell_functions", "owned_cell_values", "write_cell_gradient"]


def owned_cell_values(model) -> dict[str, np.ndarray]:
    """The last evaluation's gradient per cell: parameter name -> one value per owned cell
    in local cell order (the parameters without one, e.g. an initial velocity, absent).

    Args:
        model: An :class:`~fem_anim.adjoint.differentiate.AdjointModel` after
            :meth:`~fem_anim.adjoint.differentiate.AdjointModel.evaluate`.
    """
    p = model.problem
    topology = p.domain.mesh.topology
    owned = topology.index_map(topology.dim).size_local
    dofs = compat.cell_dofs(p.W0)[:owned, 0]
    return {name: np.asarray(values)[dofs] for name, values in
            model.sweep.cell_gradient.items()}


def cell_functions(model) -> dict[str, fem.Function]:
    """The last evaluation's gradient per cell as DG0 Functions (ghosts updated;
    collective)."""
    out = {}
    for name, values in model.sweep.cell_gradient.items():
        f = fem.Function(model.problem.W0, name=f"dJ/d{name}")
        f.x.array[: values.size] = values
        compat.petsc_vec(f).ghostUpdate(addv=PETSc.InsertMode.INSERT,
                                        mode=PETSc.ScatterMode.FORWARD)
        out[name] = f
    return out


def write_cell_gradient(path: Path, model, values: dict[str, np.ndarray] | None = None) -> None:
    """Write the gradient per cell as cell data (one array per parameter, named by its
    key) of a VTU file of the input mesh (collective; rank 0 writes).

    Args:
        path: The file (``.vtu``).
        model: The :class:`~fem_anim.adjoint.differentiate.AdjointModel`.
        values: Per owned cell values (:func:`owned_cell_values`; default: the last
            evaluation's).

    Raises:
        FemAnimError: (collectively) the file cannot be written.
    """
    from fem_anim.output.files import CellGather

    values = owned_cell_values(model) if values is None else values
    gather = CellGather(model.problem.domain)
    gathered = {name: gather.gather(v) for name, v in values.items()}
    comm = model.problem.comm
    error = None
    if comm.rank == 0:
        import meshio

        domain = model.problem.domain
        points = domain.points
        if points.shape[1] == 2:  # ParaView wants 3-vectors
            points = np.hstack([points, np.zeros((points.shape[0], 1))])
        cell_type = {3: "triangle", 4: "tetra"}[domain.cells.shape[1]]
        try:
            meshio.write(path, meshio.Mesh(points, [(cell_type, domain.cells)],
                                           cell_data={n: [v] for n, v in gathered.items()}))
        except OSError as err:
            error = f"cannot write {path}: {describe_os_error(err)}"
    error = comm.bcast(error, root=0)
    if error is not None:
        raise FemAnimError(error)
