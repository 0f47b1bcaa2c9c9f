"""Per-quadrature-point data of the elastic rule, computed in numpy (seed section 4.4).

Some materials' psi needs a quantity UFL cannot express (corotated's tr sqrt(C), a
batched SVD: :data:`fem_anim.forms.material.EXTRA_DATA`), and the projected Newton Hessian
needs the PSD projection of the material tangent
(:func:`fem_anim.solver.hessian_modification.project_psd`).
:class:`QuadratureData` holds such a field as a quadrature-space Function and refreshes it
from a compiled UFL expression and a vectorised numpy map.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from dolfinx import fem

from fem_anim import compat

__all__ = ["QuadratureData"]


@dataclass
class QuadratureData:
    """Per-quadrature-point data computed in numpy from a compiled UFL expression.

    Holds a quadrature-space Function and a compiled expression (F, or the material
    tangent) at the points of the elastic quadrature rule; :meth:`update` evaluates it on
    every local cell (owned and ghost, so no communication is needed), or only on ``cells``
    when given (the cells whose forms read the field: a multi-material mesh's corotated body;
    the other cells' values are never read and stay 0), and applies a numpy map in one
    vectorised call: the extra data of
    :data:`fem_anim.forms.material.EXTRA_DATA`, or the PSD projection of
    :func:`fem_anim.solver.hessian_modification.project_psd`.
    """

    function: fem.Function
    expression: fem.Expression
    evaluate: object
    num_cells: int
    value_shape: tuple[int, ...]
    #: Local cells to evaluate on (None: all ``num_cells``).
    cells: np.ndarray | None = None

    def update(self) -> None:
        """Evaluate the expression on its cells and store its numpy map there."""
        cells = np.arange(self.num_cells, dtype=np.int32) if self.cells is None else self.cells
        if cells.size == 0:  # no cell of this rank reads the field
            return
        mesh = self.function.function_space.mesh
        values = compat.evaluate(self.expression, mesh, cells).reshape(-1, *self.value_shape)
        values = self.evaluate(values).reshape(cells.size, -1)
        dofs = compat.cell_dofs(self.function.function_space)[cells]
        bs = self.function.function_space.dofmap.bs
        target = self.function.x.array.reshape(-1, bs)
        target[dofs.ravel()] = values.reshape(-1, bs)
