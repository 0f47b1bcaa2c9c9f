"""The binomial checkpoint schedule: which forward states to keep, which to recompute.

The backward sweep (:mod:`fem_anim.adjoint.backward`) visits the steps of a run of N steps
of seed section 3.1 backwards, step n needing the state s_n at its start and s_{n+1} at
its end. Keeping every state costs N + 1 states of memory; keeping c of them
(checkpoints, s_0 among them) and re-running the forward steps between them costs
recomputation instead. Griewank's binomial (revolve) schedule reverses the chain with
the fewest forward steps for a given c (A. Griewank, A. Walther, "Algorithm 799:
revolve", ACM TOMS 26 (2000)): reversing l states from a checkpoint with s more free
checkpoint slots costs

    T(1, s) = 0,   T(l, 0) = l (l - 1) / 2,
    T(l, s) = min_{1 <= j < l} [ j + T(l - j, s - 1) + T(j, s) ]

forward steps (advance j steps and store a checkpoint there; reverse the part behind it
with one slot fewer; then the part before it with the slot freed). :func:`binomial_table`
solves this recursion exactly by dynamic programming, column by column in l and
vectorised over s and j (Griewank's closed form counts a re-run of each reversed step too,
which this sweep does not need: it holds s_{n+1} from the step it reversed before). The
forward run that records the tape walks the first chain of splits from s_0 to s_{N-1}
(N - 1 of T's steps), so the backward sweep recomputes
T(N, c - 1) - (N - 1) steps (:meth:`BinomialSchedule.recomputations`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["BinomialSchedule", "binomial_table"]


def binomial_table(length: int, slots: int) -> tuple[np.ndarray, np.ndarray]:
    """The optimal costs T(l, s) and first splits j(l, s) for l <= ``length``, s <= ``slots``.

    Returns:
        ``cost[s, l]`` (forward steps to reverse l states from a checkpoint with s free
        slots) and ``split[s, l]`` (the optimal first advance j; 0 where l <= 1 or s = 0).
    """
    ls = np.arange(length + 1, dtype=np.int64)
    cost = np.zeros((slots + 1, length + 1), dtype=np.int64)
    split = np.zeros((slots + 1, length + 1), dtype=np.int64)
    cost[0] = np.maximum(ls * (ls - 1) // 2, 0)
    # with s >= l - 1 slots every state is stored on the way: T(l, s) = l - 1, j = 1
    enough = ls[None, :] <= np.arange(slots + 1)[:, None] + 1
    cost[1:] = np.where(enough[1:], np.maximum(ls - 1, 0), 0)
    split[1:] = np.where(enough[1:] & (ls >= 2), 1, 0)
    if slots >= length - 1:  # the recursion then only meets l <= s + 1
        return cost, split
    for l in range(3, length + 1):  # column by column: T(., l) needs columns < l only
        s = np.arange(1, min(slots, l - 2) + 1)  # the rows without enough slots
        if s.size == 0:
            continue
        j = np.arange(1, l)
        total = j[None, :] + cost[s - 1][:, l - j] + cost[s][:, j]
        best = np.argmin(total, axis=1)  # the first minimiser: the shortest advance
        cost[s, l] = total[np.arange(s.size), best]
        split[s, l] = j[best]
    return cost, split


class BinomialSchedule:
    """The binomial schedule of a run of ``steps`` steps with ``checkpoints`` stored states.

    Args:
        steps: N, the number of steps.
        checkpoints: c >= 1, the most states kept at once (s_0 included; the backward
            sweep holds two working states besides: the one being advanced and the end of
            the step being reversed).
    """

    def __init__(self, steps: int, checkpoints: int):
        if checkpoints < 1:
            raise ValueError(f"checkpoints must be >= 1, got {checkpoints}")
        self.steps = int(steps)
        self.checkpoints = int(checkpoints)
        self.slots = min(self.checkpoints - 1, max(self.steps - 1, 0))
        self.cost, self.split = binomial_table(max(self.steps, 1), self.slots)

    def first_chain(self) -> list[int]:
        """The checkpoints the recording forward run stores after s_0, in order."""
        a, b, s, out = 0, self.steps, self.slots, []
        while b - a > 1 and s > 0:
            a += int(self.split[s, b - a])
            out.append(a)
            s -= 1
        return out

    def recomputations(self) -> int:
        """Forward steps the backward sweep re-runs (the recording run's are not counted)."""
        if self.steps <= 1:
            return 0
        return int(self.cost[self.slots, self.steps]) - (self.steps - 1)
