"""A shell's wind and aerodynamic drag bound to DOLFINx (``[wind]``).

:mod:`fem_anim.forms.aerodynamic_drag` writes the normal pressure drag
``f = -C_d rho_a |s| s n / 2`` per deformed area, ``s = (v - w) . n``, as a dissipation
potential of the step objective (seed §3.1, eq. 4) with the normal and area lagged at the
step's start. :class:`WindDrag` holds the scene's wind velocity, drag coefficient and air
density as DOLFINx Constants and builds the two forms the problem needs: the drag's part of
the objective (through the scheme's ``c = w / tau`` and anchor ``u_d``, the ones Rayleigh
damping uses, :meth:`fem_anim.simulation.integrators.Integrator.damping_anchor`) and the
force at a given velocity (the initial acceleration of Newmark).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import ufl
from dolfinx import fem
from petsc4py import PETSc

from fem_anim.forms import aerodynamic_drag

__all__ = ["WindDrag"]


def _rest_jacobian(u: fem.Function):
    """The rest Jacobian ``dX/dxi`` (3x2) of the surface ``u`` lives on."""
    return ufl.Jacobian(u.function_space.mesh.ufl_domain())


@dataclass
class WindDrag:
    """The wind and drag law of a scene's ``[wind]``.

    Attributes:
        velocity: The wind velocity ``w`` (m/s, a 3-vector Constant).
        drag_coefficient: ``C_d`` (a Constant).
        air_density: ``rho_a`` (kg/m^3, a Constant).
    """

    velocity: fem.Constant
    drag_coefficient: fem.Constant
    air_density: fem.Constant

    @classmethod
    def from_scene(cls, scene, mesh) -> WindDrag:
        """The drag of a validated scene's ``[wind]`` table on the surface ``mesh``."""
        cfg = scene["wind"]
        return cls(fem.Constant(mesh, np.asarray(cfg["velocity"], dtype=PETSc.ScalarType)),
                   fem.Constant(mesh, PETSc.ScalarType(cfg["drag_coefficient"])),
                   fem.Constant(mesh, PETSc.ScalarType(cfg["air_density"])))

    def step_potential(self, u, u_anchor, u_n, coefficient, weight, dx: ufl.Measure
                       ) -> ufl.Form:
        """The drag's part of the step objective divided by ``w`` (it joins the terms the
        objective weighs by ``w``; :func:`fem_anim.forms.aerodynamic_drag.drag_step_potential`).

        Args:
            u: The displacement (the step's unknown).
            u_anchor: The scheme's anchor ``u_d``.
            u_n: The displacement at the step's start (normal and area).
            coefficient: ``c = w / tau`` (staged per step).
            weight: ``w`` (staged per step).
            dx: The surface's cell measure.
        """
        return aerodynamic_drag.drag_step_potential(
            u, u_anchor, u_n, self.velocity, coefficient, weight, self.drag_coefficient,
            self.air_density, _rest_jacobian(u), dx)

    def force_potential(self, v, u, dx: ufl.Measure) -> ufl.Form:
        """``int phi((v - w) . n(u)) da(u)``, whose ``v``-derivative is minus the drag force
        (:func:`fem_anim.forms.aerodynamic_drag.drag_force_potential`)."""
        return aerodynamic_drag.drag_force_potential(v, u, self.velocity,
                                                     self.drag_coefficient, self.air_density,
                                                     _rest_jacobian(u), dx)
