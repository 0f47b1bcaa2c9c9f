"""Terminal progress bar of a run (rank 0, stderr): steps/s and Newton iterations.

The bar draws only when stderr is a terminal: a log file or a pipe gets no carriage
returns and escape codes.
"""

from __future__ import annotations

import sys

__all__ = ["Progress"]


class Progress:
    """A tqdm bar over the steps; a no-op when disabled (``--quiet``, ranks > 0) or when
    stderr is not a terminal."""

    def __init__(self, total: int, disable: bool = False):
        self._bar = None
        if not disable and sys.stderr.isatty():
            from tqdm import tqdm

            self._bar = tqdm(total=total, unit="step", desc="fem-anim", dynamic_ncols=True)

    def update(self, newton_its: int, advance: int = 1) -> None:
        """Advance the bar by ``advance`` frames, showing the last step's Newton iterations."""
        if self._bar is not None:
            self._bar.set_postfix(newton=newton_its, refresh=False)
            self._bar.update(advance)

    def close(self) -> None:
        """Close the bar."""
        if self._bar is not None:
            self._bar.close()
