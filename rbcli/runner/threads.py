"""How many threads a run's kernels may use: `--threads N` / Simulation(threads=N), else the
RBSIM_THREADS environment variable, else every core this process may run on.

Issue 28 item 1 (docs/performance.md, "Threads"). This module only resolves and validates the count; it
imports neither numba nor numpy, so resolving it starts no thread pool (numba's threading layer is
launched by the first parallel region, never by `numba.set_num_threads` before one). Sweeps' Dask
workers get RBSIM_THREADS=1 (`WORKER_ENV`): each worker process is single-threaded already
(threads_per_worker=1), and a worker per core each running all cores would oversubscribe the machine.
"""

from __future__ import annotations

import os

ENV = "RBSIM_THREADS"
WORKER_ENV = {ENV: "1"}  # what a sweep's worker processes get unless the caller set RBSIM_THREADS itself


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity where the platform has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - platforms without sched_getaffinity
        return max(1, os.cpu_count() or 1)


def parse_threads(text: str, where: str) -> int:
    """A thread count from text: a positive integer, or 'all' (every core). ValueError naming `where`."""
    value = text.strip().lower()
    if value == "all":
        return available_cores()
    try:
        count = int(value)
    except ValueError:
        raise ValueError(f"{where}: expected a positive integer or 'all', got {text!r}") from None
    if count < 1:
        raise ValueError(f"{where}: expected a positive integer or 'all', got {text!r}")
    return count


def resolve_threads(threads: int | str | None = None, environ: dict[str, str] | None = None) -> int:
    """The thread count: `threads` when given, else RBSIM_THREADS, else every core; never more than the
    cores available (extra threads on a busy machine only add fork/join waits)."""
    env = os.environ if environ is None else environ
    if threads is not None:
        count = parse_threads(str(threads), "--threads")
    elif env.get(ENV, "").strip():
        count = parse_threads(env[ENV], ENV)
    else:
        count = available_cores()
    return min(count, available_cores())
