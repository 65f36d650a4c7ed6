"""How variants are grouped into tasks: big enough that a task's fixed cost (Dask: a few milliseconds to
schedule, send and gather; everywhere: writing one part file) is small beside its work, small enough
that every worker stays busy to the end and an interrupted sweep loses little.

Without a fixed `batch`, the sizes are guided by the time measured so far (guided self-scheduling,
Polychronopoulos and Kuck 1987, in its "factoring" form): the first variants run one per task, then
each new task takes 1/(GUIDED_FACTOR x slots) of the variants still to hand out, at most TASK_SECONDS
and at least TAIL_SECONDS of measured work. Early tasks are long (few of them, so little fixed cost),
the last ones short, so the slots finish within about TAIL_SECONDS of each other instead of one slot
running a whole long batch alone at the end. The per-variant time is the mean over every row back so
far, so one slow first variant (another process on the core) does not size the whole sweep.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Generic, TypeVar

T = TypeVar("T")

# At most ~1 s of work per task: Dask's per-task cost (about 1-5 ms here, measured by
# benchmarks/bench_sweep.py) is then well under 1 %, and Ctrl-C loses at most a second per worker.
TASK_SECONDS = 1.0
# At least ~0.2 s per task in the tail: still 40x a task's fixed cost, and the slots end this close.
TAIL_SECONDS = 0.2
# A task takes 1/(GUIDED_FACTOR x slots) of what is left: 2 halves each round's share (factoring's choice),
# so there are about 4 tasks per slot over the last half of a sweep, enough for the load to even out.
GUIDED_FACTOR = 2
MAX_BATCH = 10_000


def batch_size(seconds_per_variant: float, remaining: int, slots: int) -> int:
    """Variants in the next task when `remaining` are still to hand out to `slots` parallel slots and a
    variant takes `seconds_per_variant` (measured)."""
    if remaining <= 0:
        return 1
    cost = max(seconds_per_variant, 1e-6)
    guided = math.ceil(remaining / (max(1, slots) * GUIDED_FACTOR))
    size = min(guided, TASK_SECONDS / cost, MAX_BATCH)
    size = max(size, min(math.ceil(TAIL_SECONDS / cost), remaining))  # a tail task does the floor's work
    return int(max(1, min(size, remaining)))


class Batcher(Generic[T]):
    """Hands out the pending variants in order, a task's group at a time.

    fixed: the size of every group (a sweep's `batch`); None: the first `probes` groups hold one variant
    each (their time is the first measurement), the later ones `batch_size` from the mean time so far.
    """

    def __init__(self, pending: Sequence[T], slots: int, fixed: int | None = None, probes: int | None = None) -> None:
        self._pending = list(pending)
        self._next = 0
        self._slots = max(1, slots)
        self._fixed = fixed
        self._probes = self._slots if probes is None else probes
        self._seconds = 0.0
        self._measured = 0
        self.sizes: list[int] = []  # every group's size, in the order handed out

    @property
    def slots(self) -> int:
        """The parallel slots the later groups are sized for; set it as workers join or leave."""
        return self._slots

    @slots.setter
    def slots(self, value: int) -> None:
        self._slots = max(1, value)

    @property
    def remaining(self) -> int:
        return len(self._pending) - self._next

    def measured(self, rows: Sequence[dict[str, Any]]) -> None:
        """Take the wall time of finished rows into the per-variant estimate."""
        for row in rows:
            seconds = row.get("wall_s")
            if seconds is not None:
                self._seconds += float(seconds)
                self._measured += 1

    def next_group(self) -> list[T]:
        """The next task's variants ([] once every variant is handed out)."""
        if self.remaining <= 0:
            return []
        if self._fixed is not None:
            size = self._fixed
        elif len(self.sizes) < self._probes or not self._measured:
            size = 1
        else:
            size = batch_size(self._seconds / self._measured, self.remaining, self._slots)
        group = self._pending[self._next : self._next + size]
        self._next += len(group)
        self.sizes.append(len(group))
        return group
