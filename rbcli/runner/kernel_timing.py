"""Timing a compiled run honestly: serial, in this process, the kernel and not the Python around it.

`time_kernel(reset, advance, steps, min_time)` times whole runs of `steps` steps from the initial
state. Runs are gathered into samples of about min_time / TIMING_SAMPLES seconds (as many whole runs as
fill that), and samples are taken until min_time seconds of runs are spent and at least MIN_SAMPLES
samples exist. Inside each sample the same number of 0-step calls is timed right after the runs: their
mean is the per-call overhead (argument unboxing of the chunk loop, the binding's dispatch), taken off
the sample, so a run of 25 steps of one body (tens of microseconds, of which ~10 us is the call) is
billed for its steps alone. Interleaving the two in every sample makes a change of machine load hit
both alike. Reported: the median per-step time over samples and the fastest and slowest sample.

The clock is the CPU time of the calling thread (`time.thread_time`): the chunk loops and MuJoCo's
`mj_step` are single-threaded and run in the caller's thread, so on a quiet machine this is the wall
time, and on a shared one it leaves out the time the core was given to other processes (measured on
this project's 2-core machine at load 6.7, 1 body, 500 rk4 steps: wall 1,220-2,000 ns/step, a 1.64x
spread; thread CPU time 465-572 ns/step, 1.23x). The wall time is measured beside it and reported.

Nothing is compiled inside a timing: the caller hands a `Simulation` (or a MuJoCo twin) that has run
once already. Timings are never taken on pool or Dask workers that share cores with other work.
"""

from __future__ import annotations

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
    did (fewer when a run diverges: the time is per step done). reset is outside the timed calls."""
    cpu, wall = time.thread_time, time.perf_counter

    def batch(count: int, runs: int) -> tuple[float, float, int]:
        total, total_wall, done = 0.0, 0.0, 0
        for _ in range(runs):
            reset()
            started, started_wall = cpu(), wall()
            done += advance(count)
            total += cpu() - started
            total_wall += wall() - started_wall
        return total, total_wall, done

    # the first run touches the data and warms the caches: not a sample; when it alone fills a sample,
    # first-touch costs are noise next to it and it serves as the estimate (a long run is not repeated)
    one = batch(steps, 1)[0]
    if one < min_time / TIMING_SAMPLES:
        one = batch(steps, 1)[0]
    runs = max(1, math.ceil(min_time / TIMING_SAMPLES / max(one, 1e-7)))
    samples: list[float] = []
    samples_wall: list[float] = []
    overheads: list[float] = []
    spent, total_runs = 0.0, 0
    while len(samples) < MIN_SAMPLES or spent < min_time:
        whole, whole_wall, done = batch(steps, runs)
        empty, empty_wall, _ = batch(0, runs)
        spent += whole
        total_runs += runs
        # a run shorter than the clock's resolution can come out at or below its own call overhead: keep
        # the whole time then rather than a zero or negative cost
        samples.append((whole - empty if whole > empty else whole) / max(done, 1))
        samples_wall.append((whole_wall - empty_wall if whole_wall > empty_wall else whole_wall) / max(done, 1))
        overheads.append(empty / runs)
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


def simulation_advance(sim, record_every: int) -> Callable[[int], int]:  # noqa: ANN001 - Simulation
    """advance(n) for `time_kernel`: n steps of the simulation's compiled loop from its current step,
    recording every `record_every` steps into reused frame buffers (the study's cadence, so a method
    whose work is per recorded frame is billed for its frames), no sink; stops at a divergence."""
    body_count = sim.model.body_count
    capacity = max(1, min(TIMING_BUFFER_BYTES // (13 * 8 * max(1, body_count)), sim.settings.steps // record_every + 1))
    frames = empty_buffers(capacity, body_count)

    def advance(n: int) -> int:
        done = 0
        while done < n:
            steps, _, status = sim.advance(n - done, record_every, frames, 0)
            sim.data.state.step += int(steps)
            done += int(steps)
            if status == STATUS_DIVERGED or (status != STATUS_OK and steps == 0):
                break
        return done

    return advance
