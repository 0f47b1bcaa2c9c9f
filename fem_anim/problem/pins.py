"""Pins: the Dirichlet conditions of the step objective and who decides them.

Each ``[[pin]]`` (and each body's pin, :func:`fem_anim.mesh.bodies.body_pins`) holds the
nodes of the displacement space V inside its box at the values of
:attr:`~fem_anim.problem.objective.EnergyProblem.u_bc`: zero for a fixed pin, the
prescribed rigid motion of an animated handle (:class:`~fem_anim.problem.handles.PinMotion`)
otherwise. In each step's minimisation (seed eq. 4) pinned dofs are not unknowns.

:class:`Pins` is a part of :class:`~fem_anim.problem.objective.EnergyProblem`: it reads the
problem's ``scene``, ``comm``, ``d``, ``V``, ``u``, ``u_bc``, ``bodies`` and ``cell_body``.
"""

from __future__ import annotations

import numpy as np
from dolfinx import fem
from mpi4py import MPI

from fem_anim import compat
from fem_anim.errors import SceneError
from fem_anim.mesh.bodies import body_pins
from fem_anim.problem.handles import PinMotion

__all__ = ["Pins"]


class Pins:
    """Locating the pinned nodes, moving the handles, and their prescribed rates."""

    #: The animated pins (``velocity`` or ``angular_velocity`` given), set by ``_pins``.
    moving_pins: list[PinMotion]

    def _pins(self) -> list:
        """One ``dirichletbc`` on V per pin, holding ``u_bc`` on its nodes (collective).

        Also sets ``moving_pins`` and the nodes of each pin (``_pin_dofs``).

        Raises:
            SceneError: a pin's box holds no mesh vertex (of its body, for a body's pin).
        """
        bcs = []
        self.moving_pins = []
        self._pin_dofs: list[np.ndarray] = []  # nodes of V held by each pin
        coordinates = self.V.tabulate_dof_coordinates()[:, : self.d]
        for body, where, pin in body_pins(self.scene):
            lo = np.asarray(pin["min"], dtype=float)
            hi = np.asarray(pin["max"], dtype=float)

            def inside(x, lo=lo, hi=hi):
                d = lo.size
                return np.all((x[:d].T >= lo) & (x[:d].T <= hi), axis=1)

            dofs = fem.locate_dofs_geometrical(self.V, inside)
            if body is not None:  # a body's pin holds that body's vertices only
                k = [b["name"] for b in self.bodies].index(body)
                cells = np.flatnonzero(self.cell_body == k).astype(np.int32)
                dofs = np.intersect1d(dofs, compat.dofs_of_cells(self.V, cells))
                dofs = dofs.astype(np.int32)
            dofs = self._owners_choice(dofs)
            coordinates_i = coordinates[dofs]
            owned = dofs[dofs < self.V.dofmap.index_map.size_local]
            if self.comm.allreduce(owned.size, op=MPI.SUM) == 0:
                of = f" of body {body!r}" if body is not None else ""
                raise SceneError(f"{where} ({pin['name']}): the box min {pin['min']}, max "
                                 f"{pin['max']} contains no mesh vertex{of}")
            bcs.append(fem.dirichletbc(self.u_bc, dofs))
            self._pin_dofs.append(dofs)
            if pin["velocity"] is not None or pin["angular_velocity"] != 0:
                self.moving_pins.append(PinMotion.from_scene(pin, dofs, coordinates_i))
        return bcs

    def _owners_choice(self, nodes: np.ndarray) -> np.ndarray:
        """The pinned nodes of V as their owners chose them, ghosts included (collective).

        ``locate_dofs_geometrical`` tests each rank's own dof coordinates, which DOLFINx
        computes through each rank's cells: a vertex on a pin box's face can fall inside on
        one rank and outside on another (round-off), and a ghost pinned on one rank but free
        on its owner corrupts the assembly near it. The owner decides; its ghosts follow.

        Args:
            nodes: Local node indices of V this rank found in the box.

        Returns:
            The local node indices (owned and ghost) whose owner found them in the box.
        """
        marker = fem.Function(self.V)
        values = marker.x.array.reshape(-1, self.d)
        owned = nodes[nodes < self.V.dofmap.index_map.size_local]
        values[owned, 0] = 1.0
        marker.x.scatter_forward()
        return np.flatnonzero(values[:, 0] == 1.0).astype(np.int32)

    def set_pinned_displacement(self, t: float) -> None:
        """Move the animated pins to their prescribed displacement at time ``t`` (s)."""
        values = self.u_bc.x.array.reshape(-1, self.d)
        for motion in self.moving_pins:
            values[motion.dofs] = motion.displacement(t)

    def prescribe_pin_rates(self, t: float, v: np.ndarray, a: np.ndarray) -> None:
        """Overwrite ``v`` and ``a`` (local dof arrays of V) at the animated pins with their
        prescribed velocity (m/s) and acceleration (m/s^2) at time ``t`` (s)."""
        for motion in self.moving_pins:
            rates = motion.rates(t)
            for array, value in zip((v, a), rates):
                array.reshape(-1, self.d)[motion.dofs] = value

    def _pins_on_target(self) -> bool:
        """Whether every pinned node of this rank (ghosts included) has u = u_bc exactly."""
        u = self.u.x.array.reshape(-1, self.d)
        u_bc = self.u_bc.x.array.reshape(-1, self.d)
        return all(np.array_equal(u[dofs], u_bc[dofs]) for dofs in self._pin_dofs)
