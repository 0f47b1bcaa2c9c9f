"""Lamé parameters from Young's modulus and Poisson's ratio (seed §4.4).

The energy densities of seed §4.4 are written with the Lamé parameters ``mu`` (shear modulus)
and ``lmbda``. Plane strain (``d = 2``) uses the same formulas as 3D: the out-of-plane stretch is
held at one, so the 2D densities are the 3D ones restricted to in-plane deformations.
"""

from __future__ import annotations

from typing import TypeVar

__all__ = ["lame_parameters"]

T = TypeVar("T")


def lame_parameters(E: T, nu: T) -> tuple[T, T]:
    """Return ``(mu, lmbda)`` for Young's modulus ``E`` and Poisson's ratio ``nu``.

    ``mu = E / (2 (1 + nu))`` and ``lmbda = E nu / ((1 + nu)(1 - 2 nu))``; valid for
    ``-1 < nu < 1/2``. Works for floats, numpy arrays and UFL expressions alike.

    Args:
        E: Young's modulus (Pa).
        nu: Poisson's ratio (dimensionless).

    Returns:
        The Lamé parameters ``(mu, lmbda)`` in Pa.
    """
    mu = E / (2 * (1 + nu))
    lmbda = E * nu / ((1 + nu) * (1 - 2 * nu))
    return mu, lmbda
