"""Time-stepping state: predictors and updates of each scheme (seed section 3.1).

The minimisation itself is the same for every scheme (:mod:`fem_anim.problem.objective`,
:mod:`fem_anim.forms.time_schemes`); a scheme differs only in the predictor y it stages before the
solve and in how it updates velocity (and acceleration) after it:

* :meth:`Integrator.predictor` gives y - X and :meth:`Integrator.weight` the energy weight
  w, from the state (u_n, v_n, a_n, and u_{n-1}, v_{n-1} for BDF2);
* :meth:`Integrator.update` computes v_{n+1} (and a_{n+1}) from the solution.

:meth:`fem_anim.simulation.loop.Simulation.step` stages these into the problem
(:meth:`fem_anim.problem.objective.EnergyProblem.stage`) and solves.

All updates are whole-array numpy operations on local (owned + ghost) values, which are
consistent across ranks because every operand is.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fem_anim.forms.time_schemes import SCHEMES, Scheme

__all__ = ["Integrator", "State"]


@dataclass
class State:
    """The time-stepping state, as local arrays (displacement, velocity, acceleration).

    ``u_old``/``v_old`` hold step n-1 for BDF2; ``step`` counts completed steps.
    """

    u: np.ndarray
    v: np.ndarray
    a: np.ndarray
    u_old: np.ndarray | None = None
    v_old: np.ndarray | None = None
    time: float = 0.0
    step: int = 0
    extra: dict = field(default_factory=dict)


class Integrator:
    """Predictor and update of one scheme of :data:`fem_anim.forms.time_schemes.SCHEMES`."""

    def __init__(self, name: str):
        self.scheme: Scheme = SCHEMES[name]

    @property
    def name(self) -> str:
        """The scheme's name (``time.integrator``)."""
        return self.scheme.name

    def weight(self, h: float, state: State) -> float:
        """Energy weight w of the step objective (BDF2's first step is implicit Euler)."""
        if self.name == "bdf2" and state.u_old is None:
            return h * h
        return self.scheme.weight * h * h

    def predictor(self, h: float, state: State) -> np.ndarray:
        """y - X for the step from ``state`` (table in :mod:`fem_anim.forms.time_schemes`)."""
        if self.name == "newmark":
            return state.u + h * state.v + 0.25 * h * h * state.a  # seed eq. 3
        if self.name == "bdf2" and state.u_old is not None:
            return ((4.0 * state.u - state.u_old) / 3.0
                    + h * (8.0 * state.v - 2.0 * state.v_old) / 9.0)
        return state.u + h * state.v

    def damping_anchor(self, h: float, state: State) -> tuple[float, np.ndarray]:
        """(c, u_d) of the Rayleigh dissipation potential c/2 (u - u_d)^T C (u - u_d).

        With v_{n+1} = (u - u_d)/tau for the scheme, c = w/tau (:mod:`fem_anim.forms.damping`):
        newmark tau = h/2, u_d = u_n + h/2 v_n (v_{n+1} = 2 (u - u_n)/h - v_n);
        bdf2 tau = 2h/3, u_d = (4 u_n - u_{n-1})/3; implicit Euler tau = h, u_d = u_n.
        Symplectic Euler takes the damping implicitly, as implicit Euler does.
        """
        w = self.weight(h, state)
        if self.name == "newmark":
            return w / (0.5 * h), state.u + 0.5 * h * state.v
        if self.name == "bdf2" and state.u_old is not None:
            return w / (2.0 * h / 3.0), (4.0 * state.u - state.u_old) / 3.0
        return w / h, state.u

    def update(self, h: float, state: State, u_new: np.ndarray, u_pred: np.ndarray) -> State:
        """The state after the step, given the minimiser ``u_new`` of the staged objective."""
        w = self.weight(h, state)
        if self.name == "newmark":
            a_new = (u_new - u_pred) / w  # stationarity of seed eq. 4
            v_new = state.v + 0.5 * h * (state.a + a_new)  # seed eq. 1b
        else:
            if self.name == "bdf2" and state.u_old is not None:
                v_new = 1.5 / h * (u_new - (4.0 * state.u - state.u_old) / 3.0)
            else:
                v_new = (u_new - state.u) / h
            a_new = (v_new - state.v) / h
        return State(u=u_new, v=v_new, a=a_new, u_old=state.u.copy(), v_old=state.v.copy(),
                     time=state.time + h, step=state.step + 1, extra=state.extra)
