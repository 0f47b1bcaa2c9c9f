"""Animated handles: pins whose vertices follow a prescribed rigid path.

A ``[[pin]]`` of a scene fixes the mesh vertices in its box as Dirichlet values of each
step's minimisation (seed eq. 4). With ``velocity`` or ``angular_velocity`` it becomes a
handle: :class:`PinMotion` gives the pinned dofs' displacement at time t (a rigid
motion, Rodrigues' rotation formula) and its exact first and second time derivatives,
which replace the integrator's own update at those dofs. :class:`EnergyProblem
<fem_anim.problem.objective.EnergyProblem>` builds one per moving pin from its located dofs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["PinMotion"]


@dataclass
class PinMotion:
    """A pin that follows a prescribed rigid path: an animated handle (scene data only).

    The pinned rest points X move to c + R(omega t') (X - c) + v t' with t' = min(t, until),
    R the rotation by omega t' about ``axis`` through ``center`` (2D: about z).
    """

    dofs: np.ndarray
    X: np.ndarray
    velocity: np.ndarray
    omega: float
    axis: np.ndarray
    center: np.ndarray
    until: float

    @classmethod
    def from_scene(cls, pin: dict, dofs: np.ndarray, X: np.ndarray) -> "PinMotion":
        """The motion of a validated ``[[pin]]`` table (centre: the box's, axis: z, by
        default) for its located nodes ``dofs`` with rest coordinates ``X`` (m)."""
        d = X.shape[1]
        center = pin["center"] if pin["center"] is not None else \
            0.5 * (np.asarray(pin["min"]) + np.asarray(pin["max"]))
        axis = np.asarray(pin["axis"] if pin["axis"] is not None else [0.0, 0.0, 1.0], float)
        velocity = pin["velocity"] if pin["velocity"] is not None else [0.0] * d
        return cls(dofs, X, np.asarray(velocity, float), float(pin["angular_velocity"]),
                   axis / np.linalg.norm(axis), np.asarray(center, float),
                   np.inf if pin["until"] is None else float(pin["until"]))

    def _rotated(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(r, R(omega t') r) with r = X - c (Rodrigues' rotation formula)."""
        theta = self.omega * min(t, self.until)
        r = self.X - self.center
        if r.shape[1] == 2:
            c, s = np.cos(theta), np.sin(theta)
            return r, np.stack([c * r[:, 0] - s * r[:, 1], s * r[:, 0] + c * r[:, 1]], axis=1)
        k = self.axis
        return r, (r * np.cos(theta) + np.cross(k, r) * np.sin(theta)
                   + np.outer(r @ k, k) * (1.0 - np.cos(theta)))

    def _spin(self, r: np.ndarray) -> np.ndarray:
        """omega x r (2D: omega about z)."""
        if r.shape[1] == 2:
            return self.omega * np.stack([-r[:, 1], r[:, 0]], axis=1)
        return self.omega * np.cross(self.axis, r)

    def displacement(self, t: float) -> np.ndarray:
        """Displacement of the pinned dofs at time ``t``."""
        r, rotated = self._rotated(t)
        return rotated - r + self.velocity * min(t, self.until)

    def rates(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """Velocity and acceleration of the pinned dofs at time ``t`` (zero once stopped).

        v = omega x R r + velocity, a = omega x (omega x R r): the time derivatives of
        :meth:`displacement` while the handle moves (from ``until`` on, it rests; a step
        time within round-off of ``until``, such as 10 x 0.005 = 0.049999..., counts as
        stopped, since the step that ends there is the one in which the handle stops).
        """
        if t >= self.until * (1.0 - 1e-12):
            return np.zeros_like(self.X), np.zeros_like(self.X)
        _, rotated = self._rotated(t)
        spin = self._spin(rotated)
        return spin + self.velocity, self._spin(spin)
