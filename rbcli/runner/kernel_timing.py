"""Timing a compiled run honestly: serial, in this process, the kernel and not the Python around it.

`time_kernel(reset, advance, steps, min_time)` times whole runs of `steps` steps from the initial
state. Each run is followed by a 0-step call of the same loop (argument unboxing of the chunk loop, the
binding's dispatch: ~10-20 us for rbsim's loops, ~0.5 us for `mj_step`), and the run's kernel time is
its time minus that call's, so a run of 10 steps of one body (~5 us of steps inside ~20 us) is billed
for its steps alone; pairing each run with its own call makes a drift of the machine's speed hit both
alike. Runs are gathered into samples of about min_time / TIMING_SAMPLES seconds (as many whole runs as
fill that); a sample's value is the median over its runs (an interrupt or a page fault charged to one
run is not the kernel's cost), and samples are taken until min_time seconds of runs are spent and at
least MIN_SAMPLES exist. Reported: the median over samples and the fastest and slowest sample.

The clock is the CPU time of the calling thread (`time.thread_time`): the chunk loops and MuJoCo's
`mj_step` are single-threaded and run in the caller's thread, so on a quiet machine this is the wall
time, and on a shared one it leaves out the time the core was given to other processes (measured on
this project's 2-core machine at load 6.7, 1 body, 500 rk4 steps: wall 1,220-2,000 ns/step, a 1.64x
spread; thread CPU time 465-572 ns/step, 1.23x). The wall time is measured beside it and reported; it
is the clock where the thread clock is coarser than a microsecond.

Nothing is compiled inside a timing: the caller hands a `Simulation` (or a MuJoCo twin) that has run
once already. Timings are never taken on pool or Dask workers that share cores with other work.
"""

from __future__ import annotations

import gc
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from rbcli.physics.step import STATUS_DIVERGED, STATUS_OK, empty_buffers

# Each point is timed in about this many samples of min_time / TIMING_SAMPLES seconds each ...
TIMING_SAMPLES = 7
# ... and never fewer than this (a median and a spread need three).
MIN_SAMPLES = 3
# A sample whose runs measure at or below the call overhead keeps this fraction of its whole time.
KERNEL_FLOOR = 0.05
# Frame buffers of the timed loop hold at most this many bytes (13 float64 per body and frame): a run
# whose frames do not fit hands the full buffer back and continues, as the runner does.
TIMING_BUFFER_BYTES = 16 * 1024 * 1024


@dataclass(frozen=True)
class KernelTiming:
    """Per-step time [s] of a run (CPU time of the running thread): median, fastest and slowest sample;
    `wall` the median of the same samples in wall time; `samples` samples of `runs` whole runs in all,
    `seconds` [s] of CPU time spent in them; `overhead` [s] the per-call time taken off."""

    median: float
    low: float
    high: float
    wall: float
    samples: int
    runs: int
    seconds: float
    overhead: float

    @property
    def spread(self) -> float:
        """Slowest over fastest sample (1.0 = no spread)."""
        return self.high / self.low if self.low > 0 else math.inf


def time_kernel(reset: Callable[[], None], advance: Callable[[int], int], steps: int, min_time: float) -> KernelTiming:
    """Time `advance(steps)` runs from `reset()` (see the module docstring); advance returns the steps it
    did (fewer when a run diverges: the time is per step done) and must make its call into compiled code
    also for 0 steps (that call is the overhead taken off). reset is outside the timed calls."""
    wall = time.perf_counter
    # a thread clock coarser than a microsecond (some platforms tick it at the scheduler's 1-16 ms)
    # cannot time a short run: the wall clock then, whose samples include other processes' time
    cpu = time.thread_time if time.get_clock_info("thread_time").resolution <= 1e-6 else wall

    def batch(count: int, runs: int) -> tuple[float, float, float, float, float]:
        """`runs` runs, each followed by a 0-step call (so a drift of the machine's speed hits both alike):
        the median over runs of (run - its call) per step, in CPU and wall seconds (a median: an
        interrupt or page fault charged to one run is not the kernel's), the CPU seconds of the runs,
        the mean CPU seconds of a call, and the steps per run."""
        kernel = np.empty(runs)
        kernel_wall = np.empty(runs)
        total, calls, done = 0.0, 0.0, 0
        for i in range(runs):
            reset()
            started, started_wall = cpu(), wall()
            steps_done = advance(count)
            run, run_wall = cpu() - started, wall() - started_wall
            reset()
            started, started_wall = cpu(), wall()
            advance(0)
            call, call_wall = cpu() - started, wall() - started_wall
            kernel[i] = _kernel_per_step(run, call, steps_done)
            kernel_wall[i] = _kernel_per_step(run_wall, call_wall, steps_done)
            total, calls, done = total + run, calls + call, done + steps_done
        return float(np.median(kernel)), float(np.median(kernel_wall)), total, calls / runs, done / runs

    # the first run touches the data and warms the caches (and may load the kernel from numba's cache):
    # not a sample, and an estimate only when it alone is longer than min_time (then a second first-touch
    # cost is noise next to it, and the run is not repeated just to estimate it)
    target = min_time / TIMING_SAMPLES
    one = batch(steps, 1)[2]
    if one < min_time:
        one = min(one, batch(steps, 1)[2])
    runs = max(1, math.ceil(target / max(one, 1e-7)))
    samples: list[float] = []
    samples_wall: list[float] = []
    overheads: list[float] = []
    spent, total_runs = 0.0, 0
    collecting = gc.isenabled()
    gc.disable()  # as timeit does: a collection inside a timed call is not the kernel's cost
    try:
        while len(samples) < MIN_SAMPLES or spent < min_time:
            per_step, per_step_wall, seconds, overhead, _ = batch(steps, runs)
            if seconds < 0.5 * target:  # the estimate ran slow (a hiccup): not a sample; size them again
                runs = math.ceil(runs * target / max(seconds, 1e-7))
                continue
            spent += seconds
            samples.append(per_step)
            total_runs += runs
            samples_wall.append(per_step_wall)
            overheads.append(overhead)
    finally:
        if collecting:
            gc.enable()
    return KernelTiming(
        median=float(np.median(samples)),
        low=float(min(samples)),
        high=float(max(samples)),
        wall=float(np.median(samples_wall)),
        samples=len(samples),
        runs=total_runs,
        seconds=spent,
        overhead=float(np.median(overheads)),
    )


def _kernel_per_step(whole: float, calls: float, steps: int) -> float:
    """(time of a run - time of its 0-step call) / steps done. A run whose kernel time is below the noise
    of its call overhead can come out at or below it: it keeps KERNEL_FLOOR of its whole time (a
    positive, visibly tiny cost) instead of a zero or negative one."""
    return max(whole - calls, KERNEL_FLOOR * whole) / max(steps, 1)


def simulation_advance(sim, record_every: int) -> Callable[[int], int]:  # noqa: ANN001 - Simulation
    """advance(n) for `time_kernel`: n steps of the simulation's compiled loop from its current step,
    recording every `record_every` steps into reused frame buffers (the study's cadence, so a method
    whose work is per recorded frame is billed for its frames), no sink; stops at a divergence."""
    body_count = sim.model.body_count
    capacity = max(1, min(TIMING_BUFFER_BYTES // (13 * 8 * max(1, body_count)), sim.settings.steps // record_every + 1))
    frames = empty_buffers(capacity, body_count)

    def advance(n: int) -> int:
        done = 0
        while True:  # at least one call, also for n = 0: that call is the overhead time_kernel takes off
            steps, _, status = sim.advance(n - done, record_every, frames, 0)
            sim.data.state.step += int(steps)
            done += int(steps)
            if done >= n or status == STATUS_DIVERGED or (status != STATUS_OK and steps == 0):
                return done

    return advance
