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
    every local cell (owned and ghost, so no communication is needed) and applies a numpy
    map in one vectorised call: the extra data of
    :data:`fem_anim.forms.material.EXTRA_DATA`, or the PSD projection of
    :func:`fem_anim.solver.hessian_modification.project_psd`.
    """

    function: fem.Function
    expression: fem.Expression
    evaluate: object
    num_cells: int
    value_shape: tuple[int, ...]

    def update(self) -> None:
        """Evaluate the expression on every local cell and store its numpy map."""
        cells = np.arange(self.num_cells, dtype=np.int32)
        mesh = self.function.function_space.mesh
        values = compat.evaluate(self.expression, mesh, cells).reshape(-1, *self.value_shape)
        values = self.evaluate(values).reshape(self.num_cells, -1)
        dofs = compat.cell_dofs(self.function.function_space)[: self.num_cells]
        bs = self.function.function_space.dofmap.bs
        target = self.function.x.array.reshape(-1, bs)
        target[dofs.ravel()] = values.reshape(-1, bs)
