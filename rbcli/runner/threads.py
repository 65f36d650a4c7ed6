"""How many threads a run's kernels may use: `--threads N` / Simulation(threads=N), else the
RBSIM_THREADS environment variable, else every core this process may run on.

Issue 28 item 1 (docs/performance.md, "Threads"). This module resolves and validates the count and says
whether a run uses it (`chunk_threads`); it imports neither numba nor numpy, so resolving it starts no
thread pool (numba launches its threading layer at `numba.set_num_threads` or the first parallel
region, which only a run on the threaded loop reaches). Sweeps' Dask
workers get RBSIM_THREADS=1 (`WORKER_ENV`): each worker process is single-threaded already
(threads_per_worker=1), and a worker per core each running all cores would oversubscribe the machine.
"""

from __future__ import annotations

import os

ENV = "RBSIM_THREADS"
# Below this many bodies a run keeps the serial chunk loop whatever the thread count: the threaded
# step's two fork/joins cost ~4 us per step on 2 threads, which free bodies repay from ~170 bodies on
# (split2 with gravity, measured on 2 cores: 0.74x the serial rate at 100 bodies, 1.22x at 300, 1.60x
# at 1,000, 1.89x at 10,000; docs/performance.md, "Threads")
PARALLEL_MIN_BODIES = 256
# Scenes with contact keep the serial loop: the 1,000-ball pile ran 0.91x its serial rate on 2 threads
# with the serial contact stages between the threaded passes (bench_threads.py), and ~1.0x with the
# pair search on threads too (contact_threads). The threaded loop gives them the same bits
# (tests/physics/test_threaded_loop.py sets this to check it).
THREADED_CONTACT = False
# The contact stage's pair search runs on threads (physics/contact/threaded.py) in scenes of at least
# this many contact spheres. Measured on 2 cores (piles of bench_contact.py through landing, steps
# 1-600, whole Simulation.step, 2 threads against 1): 0.73x at 64 balls, 0.77x at 125, 0.76x at 216,
# 0.80x at 256, 1.04x at 512, 1.10x at 1,000: the records pass's fork/join (~4-10 us per step) is
# repaid from ~500 spheres on (docs/performance.md, "Threads")
CONTACT_PARALLEL_MIN_SPHERES = 512
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


def chunk_threads(
    threads: int, has_parallel_loop: bool, body_count: int, contact: bool = False, joints: bool = False
) -> int:
    """The threads a run's chunk loop uses: `threads` for an integrator with a threaded loop and a scene
    of at least PARALLEL_MIN_BODIES bodies without contact (THREADED_CONTACT) or joints, else 1 (the
    serial loop: no thread pool is started). A scene with joints steps by joints/rattle.py's serial
    RATTLE step, never the threaded passes, so the threaded loop would only start a pool. (Before
    RATTLE it ran split2's threaded passes between the serial joint stages: 4.7 ms of CPU per step of
    the 400-link chain, of which the joint stages took 0.65, on the loaded 2-core machine.)"""
    if threads <= 1 or not has_parallel_loop or body_count < PARALLEL_MIN_BODIES or joints:
        return 1
    if contact and not THREADED_CONTACT:
        return 1
    return threads


def contact_threads(threads: int, sphere_count: int) -> int:
    """The threads the contact stage's pair search uses: `threads` for a scene of at least
    CONTACT_PARALLEL_MIN_SPHERES contact spheres, else 1 (the serial search; no threaded kernel is
    compiled). Independent of the chunk loop's choice: contact scenes keep the serial loop."""
    return threads if threads > 1 and sphere_count >= CONTACT_PARALLEL_MIN_SPHERES else 1
