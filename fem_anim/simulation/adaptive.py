"""Adaptive time stepping: a frame reached by substeps, a failed substep retried smaller.

A frame of length h is reached by substeps. A substep whose minimisation does not converge
(or whose result is not finite) is discarded, the state is left as it was, and it is retried
with dt halved, down to ``time.min_dt``; after each success dt is doubled again, up to h.
Substeps never overshoot a frame time, so frames stay at multiples of h and no frame comes
from a failed step. BDF2's history assumes a constant step: after a change of dt it restarts
with one implicit Euler step. With ``time.adaptive = false`` the first failure stops the run.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import replace

from fem_anim.errors import ConvergenceError
from fem_anim.simulation.integrators import State

__all__ = ["AdaptiveStepper"]


class AdaptiveStepper:
    """Halve dt when a step fails, grow it back after successes.

    Args:
        sim: The :class:`~fem_anim.simulation.loop.Simulation` whose
            :meth:`~fem_anim.simulation.loop.Simulation.timed_step` takes the substeps.
        h: Frame length (s), the largest substep.
        time_cfg: The scene's ``[time]`` table (``adaptive``, ``min_dt``).
    """

    def __init__(self, sim, h: float, time_cfg: dict):
        self.sim = sim
        self.h = h
        self.adaptive = time_cfg["adaptive"]
        self.min_dt = time_cfg["min_dt"] if time_cfg["min_dt"] is not None else h / 256.0
        self.dt = h
        self.last_dt = h

    def advance(self, state: State, t_end: float) -> Iterator[tuple[State, dict]]:
        """Yield (state, stats row) for each accepted substep until ``t_end`` (s).

        Each row is :meth:`~fem_anim.simulation.loop.Simulation.timed_step`'s with
        ``retries``, the failed tries before it, and ``retry_wall_s``, their wall time (s;
        discarded work, not in the row's ``step_wall_s``).

        Raises:
            ConvergenceError: a substep failed with adaptivity off, or at ``time.min_dt``.
        """
        retries, retry_wall = 0, 0.0
        while t_end - state.time > 1e-9 * self.h:
            dt = min(self.dt, t_end - state.time)
            if dt > t_end - state.time - 1e-9 * self.h:
                dt = t_end - state.time  # land exactly on the frame time
            trial = state
            if self.sim.integrator.name == "bdf2" and abs(dt - self.last_dt) > 1e-12 * self.h:
                trial = replace(state, u_old=None, v_old=None)
            start = time.perf_counter()
            try:
                new, row = self.sim.timed_step(trial, dt)
            except ConvergenceError as err:
                retry_wall += time.perf_counter() - start
                if not self.adaptive or self.dt / 2.0 < self.min_dt:
                    floor = "" if not self.adaptive else \
                        f" (time.min_dt = {self.min_dt:.3g} s reached)"
                    raise ConvergenceError(f"{err}{floor}") from None
                self.dt /= 2.0
                retries += 1
                continue
            row["retries"], row["retry_wall_s"] = retries, retry_wall
            retries, retry_wall = 0, 0.0
            self.last_dt = dt
            if dt == self.dt:
                self.dt = min(2.0 * self.dt, self.h)
            state = new
            yield state, row
