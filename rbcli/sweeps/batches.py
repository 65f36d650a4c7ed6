"""How variants are grouped into tasks: big enough that a task's fixed cost (Dask: a few milliseconds to
schedule, send and gather; everywhere: writing one part file) is small beside its work, small enough
that every worker stays busy to the end and an interrupted sweep loses little.

Without a fixed `batch`, the first variants run one per task (one per worker slot), and their wall time
sizes the rest: tasks of about TASK_SECONDS, but at least TASKS_PER_SLOT tasks per slot while there are
variants enough, so the last tasks of a sweep finish close together.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from typing import TypeVar

T = TypeVar("T")

# ~0.5 s of work per task: Dask's per-task cost (about 1-5 ms here, measured by benchmarks/bench_sweep.py)
# is then below 1 %, and Ctrl-C loses at most half a second per worker.
TASK_SECONDS = 0.5
TASKS_PER_SLOT = 4
MAX_BATCH = 10_000


def batch_size(seconds_per_variant: float, remaining: int, slots: int) -> int:
    """Variants per task for the `remaining` variants on `slots` parallel slots."""
    if remaining <= 0:
        return 1
    by_time = TASK_SECONDS / max(seconds_per_variant, 1e-6)
    by_balance = math.ceil(remaining / (max(1, slots) * TASKS_PER_SLOT))
    return int(max(1, min(by_time, by_balance, MAX_BATCH)))


def chunks(items: Sequence[T], size: int) -> Iterator[list[T]]:
    """Consecutive groups of `size` (the last may be shorter)."""
    for start in range(0, len(items), max(1, size)):
        yield list(items[start : start + size])
