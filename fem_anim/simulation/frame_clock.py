"""When frames are: the output frame rate, the time step that reaches each frame, the frame count.

A run writes frame k at exactly t_k = k / ``output.fps`` (k = 0, 1, ..., K), whatever
``time.dt`` is: each frame interval 1/fps is split into the fewest equal substeps no longer
than ``time.dt``::

    n = ceil((1/fps) / dt),    h = (1/fps) / n <= dt,

so every frame is a converged state of the integrator at its own time (seed section 3.1:
each step minimises the step objective, eq. 4), never an interpolation across a step, and
the step is the same throughout the run (BDF2 keeps its history, Newmark its order). The
run covers the time ``time.steps * time.dt`` it was asked for, up to the next whole frame:
K = ceil(steps * dt * fps), with a product within 1e-6 of an integer taken as that integer.
Frame k is numbered ``output.start_frame + k`` in file names and USD time codes.

Without ``output.fps`` a run keeps the step clock: frame k is step k, at t = k dt, and
``time.steps`` frames are written (one step each), exactly as a run has always been stepped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from fem_anim.errors import SceneError
from fem_anim.scene.constraints import MAX_STEPS

__all__ = ["FrameClock", "frame_clock"]

#: A product (steps * dt * fps, or an interval over dt) this close to an integer is that
#: integer: 1/60 s steps make 1/30 s frames in 2 substeps, not 3.
ROUND_OFF = 1e-6


def _ceil(x: float) -> int:
    """ceil(x), with x within :data:`ROUND_OFF` (relative) of an integer taken as it."""
    nearest = round(x)
    return int(nearest) if abs(x - nearest) <= ROUND_OFF * max(1.0, abs(x)) else math.ceil(x)


@dataclass(frozen=True)
class FrameClock:
    """The frames of a run and the substep that reaches them.

    Attributes:
        fps: The output frame rate (frames/s).
        start_frame: The number of frame 0 (file names, USD time codes).
        substeps: Equal substeps per frame interval, n = ceil((1/fps) / dt).
        count: The last frame K (frames 0..K are written, frame 0 the initial state).
        step_clock: ``time.dt`` when ``output.fps`` is not given: frame k is step k at
            t = k dt (fps is then 1/dt); None for an output frame rate.
    """

    fps: float
    start_frame: int
    substeps: int
    count: int
    step_clock: float | None = None

    @property
    def interval(self) -> float:
        """The frame interval 1/fps (s): ``time.dt`` on the step clock."""
        return self.step_clock if self.step_clock is not None else 1.0 / self.fps

    @property
    def step(self) -> float:
        """The time step h = (1/fps) / n (s), at most ``time.dt``."""
        return self.interval / self.substeps

    @property
    def end(self) -> float:
        """The time of the last frame, K/fps (s)."""
        return self.time(self.count)

    def time(self, k: int) -> float:
        """The time of frame k, k/fps (s): a quotient, so no round-off accumulates
        (k dt on the step clock)."""
        return k * self.step_clock if self.step_clock is not None else k / self.fps

    def number(self, k: int) -> int:
        """The number of frame k in file names and USD time codes: start_frame + k."""
        return self.start_frame + k


def frame_clock(scene) -> FrameClock:
    """The frame clock of a scene's ``[time]`` and ``[output]`` tables.

    Args:
        scene: A validated scene (``time.dt``, ``time.steps``, ``output.fps``,
            ``output.start_frame``).

    Returns:
        The :class:`FrameClock`: frames at k/fps up to the first frame time at or after
        ``steps * dt``, reached by substeps of (1/fps)/ceil((1/fps)/dt); without
        ``output.fps``, the step clock (frame k at k dt, ``steps`` frames).

    Raises:
        SceneError: if the run would take more than
            :data:`~fem_anim.scene.constraints.MAX_STEPS` steps.

    Examples:
        >>> clock = FrameClock(24.0, 1, _ceil((1 / 24) / (1 / 60)), _ceil(60 * (1 / 60) * 24))
        >>> clock.substeps, clock.count, round(clock.step * 72, 12), clock.number(0)
        (3, 24, 1.0, 1)
    """
    dt, steps = scene["time"]["dt"], scene["time"]["steps"]
    start = scene["output"]["start_frame"]
    if scene["output"]["fps"] is None:  # the step clock: one frame per step
        return FrameClock(1.0 / dt, start, 1, steps, step_clock=dt)
    fps = float(scene["output"]["fps"])
    substeps, count = max(1, _ceil((1.0 / fps) / dt)), max(1, _ceil(steps * dt * fps))
    if substeps * count > MAX_STEPS:
        raise SceneError(f"time.steps * time.dt = {steps * dt:g} s at output.fps = {fps:g} is "
                         f"{count} frames of {substeps} steps, more than {MAX_STEPS} steps "
                         "(is time.dt or output.fps a typo?)")
    return FrameClock(fps, start, substeps, count)
