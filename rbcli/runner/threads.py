"""How many threads a run's kernels may use: `--threads N` / Simulation(threads=N), else the
RBSIM_THREADS environment variable, else every core this process may run on, and whether the governor
(runner/governor.py) chooses between one thread and all of them as the run goes.

Issue 28 item 1 and issue 45 (docs/performance.md, "Threads"). This module resolves and validates the
count (`plan_threads`: the count, `auto`, and the reason a run reports) and says whether a run uses it
(`chunk_threads`); it imports neither numba nor numpy, so resolving it starts no thread pool (numba
launches its threading layer at `numba.set_num_threads` or the first parallel region, which only a run
on the threaded loop reaches). An explicit count (a number or 'all', from the flag or RBSIM_THREADS) is
obeyed as given; the default, or 'auto', lets the governor pick per slice of a chunk. Sweeps' Dask
workers get RBSIM_THREADS=1 (`WORKER_ENV`): each worker process is single-threaded already
(threads_per_worker=1), and a worker per core each running all cores would oversubscribe the machine;
pytest-xdist workers default to one thread for the same reason.
"""

from __future__ import annotations

import os
import threading
from dataclasses import dataclass

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
XDIST_ENV = "PYTEST_XDIST_WORKER"  # set in each pytest-xdist worker: one per core, so one thread each
AUTO = "auto"
# libgomp's idle threads spin GOMP_SPINCOUNT rounds (~20 ns each here) before they sleep; its default,
# 300,000 (~5.5 ms), has a spinning thread take the core from the work another process (or this one's
# other thread) would do there, and a descheduled spinner answers a fork only when its turn comes again
# (~ms): 0.10-0.27x of one thread under load (benchmarks/bench_forkjoin.py). 2,000 (~40 us) still spans
# the serial gap between a step's two passes, so an idle machine keeps its gain (docs/performance.md,
# "Threads"). Set only when the user set neither variable, and only before libgomp loads.
GOMP_SPINCOUNT = "2000"


@dataclass(frozen=True)
class ThreadPlan:
    """The threads a run may use (count), whether the governor chooses between 1 and count as the run
    goes (auto), and why (a few words for `rbsim run`'s summary)."""

    count: int
    auto: bool
    why: str


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
    """The most threads a run may use (`plan_threads(...).count`)."""
    return plan_threads(threads, environ).count


def plan_threads(threads: int | str | None = None, environ: dict[str, str] | None = None) -> ThreadPlan:
    """`threads` when given, else RBSIM_THREADS, else every core (one in a pytest-xdist worker); never
    more than the cores available (extra threads on a busy machine only add fork/join waits). A count
    or 'all' is fixed; the default and 'auto' leave the choice between 1 and every core to the governor."""
    env = os.environ if environ is None else environ
    cores = available_cores()
    given, where = (str(threads), "--threads") if threads is not None else (env.get(ENV, "").strip(), ENV)
    if given and given.strip().lower() != AUTO:
        count = min(parse_threads(given, where), cores)
        source = f"--threads {given.strip()}" if threads is not None else f"{ENV}={given}"
        return ThreadPlan(count, False, source)
    if not given and env.get(XDIST_ENV):
        return ThreadPlan(1, False, "a pytest-xdist worker")
    return ThreadPlan(cores, cores > 1, f"{AUTO}: 1 or {cores} by measured speed" if cores > 1 else "one core")


def prepare_pool(environ: dict[str, str] | None = None) -> None:
    """Before numba's threading layer loads: libgomp's spin before sleep cut to GOMP_SPINCOUNT, unless
    the user chose a wait policy (OMP_WAIT_POLICY or GOMP_SPINCOUNT) or libgomp is loaded already."""
    env = os.environ if environ is None else environ
    if "OMP_WAIT_POLICY" in env or "GOMP_SPINCOUNT" in env or _libgomp_loaded():
        return
    env["GOMP_SPINCOUNT"] = GOMP_SPINCOUNT


def _libgomp_loaded() -> bool:
    """Whether this process has mapped libgomp (its settings were read when it loaded)."""
    try:
        with open("/proc/self/maps") as maps:
            return "libgomp" in maps.read()
    except OSError:  # pragma: no cover - no /proc: assume not, the variable is then merely unused
        return False


def chunk_threads(
    threads: int, has_parallel_loop: bool, body_count: int, contact: bool = False, joints: bool = False
) -> int:
    """The threads a run's chunk loop uses: `threads` for an integrator with a threaded loop and a scene
    of at least PARALLEL_MIN_BODIES bodies without contact (THREADED_CONTACT) or joints, else 1 (the
    serial loop: no thread pool is started).

    Jointed scenes keep the serial loop: the joint stages (the solver's factor and solves along the
    tree) are serial and dominate their step, so the threaded body passes gain little, while the threaded
    loop with the joint stages is a whole second compile (~80 CPU-s on a first run: the 1,000-bead rope
    of scenes/joints/rope_1000.yaml met it, and ran 8x slower than one thread on a loaded machine).
    Since RATTLE (joints/rattle.py) a jointed scene steps by a serial step anyway, never split2's
    threaded passes: the threaded loop would only start a pool."""
    if threads <= 1 or not has_parallel_loop or body_count < PARALLEL_MIN_BODIES or joints:
        return 1
    if contact and not THREADED_CONTACT:
        return 1
    return threads


def serial_reason(has_parallel_loop: bool, body_count: int, contact: bool, joints: bool = False) -> str:
    """Why a run allowed several threads keeps to one (for its report)."""
    if joints:
        return "a jointed scene (its joint stages are serial)"
    if contact:
        return f"a contact scene under {CONTACT_PARALLEL_MIN_SPHERES} contact spheres"
    if not has_parallel_loop:
        return "its integrator has no threaded loop"
    if body_count < PARALLEL_MIN_BODIES:
        return f"under {PARALLEL_MIN_BODIES} bodies"
    return "NUMBA_NUM_THREADS=1"


def contact_threads(threads: int, sphere_count: int) -> int:
    """The threads the contact stage's pair search uses: `threads` for a scene of at least
    CONTACT_PARALLEL_MIN_SPHERES contact spheres, else 1 (the serial search; no threaded kernel is
    compiled). Independent of the chunk loop's choice: contact scenes keep the serial loop."""
    return threads if threads > 1 and sphere_count >= CONTACT_PARALLEL_MIN_SPHERES else 1


_numba_threads = threading.local()  # the count use_threads last gave numba in this thread


def use_threads(count: int) -> None:
    """numba.set_num_threads(count) for the calling thread (numba's count is per thread), unless this
    thread's last call asked for the same count: the call costs ~1 us, as much as a step of a small scene
    (a user stepping one step per Simulation.step). A count set by other code between two calls is not
    seen; only speed depends on it (results are bitwise the same at any thread count)."""
    if getattr(_numba_threads, "count", None) != count:
        import numba

        numba.set_num_threads(count)
        _numba_threads.count = count
