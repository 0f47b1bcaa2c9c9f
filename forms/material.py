"""Registry of the energy densities of seed §4.4, keyed by the names scene files use.

Each :class:`Material` exposes ``psi(F, mu, lmbda, **extra)`` (pure UFL) and says which extra
per-quadrature-point data its ``psi`` takes in ``d`` dimensions (:meth:`Material.needs`). The
module that binds the forms to DOLFINx computes that data with the numpy function in
:data:`EXTRA_DATA` from the current ``F`` at the quadrature points, stores it in a terminal of
the given shape and passes it to ``psi`` under the given keyword.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from ufl.core.expr import Expr

from fem_anim.forms import corotated, linear, neohookean, stable_neohookean, stvk

__all__ = ["EXTRA_DATA", "MATERIALS", "ExtraData", "Material", "get_material"]


@dataclass(frozen=True)
class ExtraData:
    """Per-quadrature-point data computed in numpy from ``F`` and passed to ``psi``.

    Attributes:
        keyword: Keyword argument of ``psi`` that receives the terminal.
        rank: Tensor rank of the terminal: 0 (scalar) or 2 (``d x d``).
        evaluate: Maps ``F`` values of shape ``(n, d, d)`` to values of shape ``(n, *shape)``.
    """

    keyword: str
    rank: int
    evaluate: Callable[[np.ndarray], np.ndarray]

    def value_shape(self, d: int) -> tuple[int, ...]:
        """Shape of the terminal.

        Args:
            d: The dimension (2 or 3).
        """
        return (d,) * self.rank


EXTRA_DATA: dict[str, ExtraData] = {
    "stretch_trace": ExtraData("s0", 0, corotated.stretch_trace),
    "rotation": ExtraData("R", 2, corotated.polar_rotation),
}


@dataclass(frozen=True)
class Material:
    """An energy density ``psi(F, mu, lmbda, **extra)`` and what it needs.

    Attributes:
        name: Scene-file name.
        psi: The UFL energy density.
        requires_positive_J: True if ``psi`` is only defined for ``det F > 0``, so the solver
            must reject steps that invert an element.
        needs_2d: Keys of :data:`EXTRA_DATA` that ``psi`` takes in 2D.
        needs_3d: Keys of :data:`EXTRA_DATA` that ``psi`` takes in 3D.
        exact_hessian: False if ``ufl.diff`` of ``psi`` is not the true Hessian (lagged data).
    """

    name: str
    psi: Callable[..., Expr]
    requires_positive_J: bool = False
    needs_2d: tuple[str, ...] = ()
    needs_3d: tuple[str, ...] = ()
    exact_hessian: bool = True

    def needs(self, d: int) -> tuple[str, ...]:
        """Keys of :data:`EXTRA_DATA` that ``psi`` takes.

        Args:
            d: The dimension of ``F`` (2 or 3).
        """
        return {2: self.needs_2d, 3: self.needs_3d}[d]


MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        Material("linear", linear.psi),
        Material("stvk", stvk.psi),
        Material("corotated", corotated.psi, needs_3d=("stretch_trace",)),
        Material("neohookean", neohookean.psi, requires_positive_J=True),
        Material("stable_neohookean", stable_neohookean.psi),
        Material(
            "corotated_lagged",
            corotated.psi_lagged,
            needs_2d=("rotation",),
            needs_3d=("rotation",),
            exact_hessian=False,
        ),
    )
}


def get_material(name: str) -> Material:
    """Look up a material by its scene-file name.

    Args:
        name: ``material.model`` of a scene.

    Returns:
        The material.

    Raises:
        ValueError: If ``name`` is not a key of :data:`MATERIALS`.
    """
    try:
        return MATERIALS[name]
    except KeyError:
        message = f"material.model must be one of {sorted(MATERIALS)}, got {name!r}"
        raise ValueError(message) from None
