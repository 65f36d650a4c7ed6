"""The default thread count's choice as a run goes (issue 45): one thread or all of them, whichever the
wall clock says is faster now, re-chosen between slices of a chunk.

Any thread count gives the same bits (the threaded passes sum nothing across bodies), so the choice can
change between any two steps without changing a result. The governor runs its current choice in slices
of ~SLICE_SECONDS and keeps a running mean of its wall seconds per step. Now and then it probes the
other choice: first a short run (PROBE_FRACTION of a slice's time), rejected at once when slower by
EARLY_REJECT, then a whole slice's time, taken when it beats the current choice (by SWITCH_GAIN).
Probes are sized in steps from the other choice's last cost, so a probe of a much slower choice stays
short in wall time; a rejected probe doubles the slices until the next one (up to MAX_WAIT), so a
choice that keeps losing costs < 1 %. A switch, or the current choice's cost moving by CHANGE since the
last comparison (load came or went), brings the next probe forward. It starts on one thread, the safe
choice while nothing is known, and the first run of each choice (which launches or wakes its threads)
is not measured.

It only decides: `plan` says what to run next, `record` is told what that took. The caller times (the
Simulation, with time.perf_counter), so tests drive the rule with made-up timings.
"""

from __future__ import annotations

# a slice's wall time: ~25 us of Python and dispatch per slice is ~0.05 % of it, and it spans several of
# the scheduler's time slices (~3 ms), so a slice that lost the core for one of them still measures the rate
SLICE_SECONDS = 0.05
PROBE_FRACTION = 0.25  # a probe's short run, as a fraction of a slice's time
EARLY_REJECT = 1.5  # the short run is rejected when its cost per step is this much above the current's
# the whole-slice probe must be this much cheaper per step to take over: more threads must win clearly
# (a wrong switch to threads under load costs more than a missed gain), one thread merely win
SWITCH_GAIN = {True: 1.1, False: 1.0}  # keyed by "the probe has more threads"
MIN_WAIT = 2  # slices of the current choice before the first probe, and after a switch
# the longest wait between probes (~1.6 s of slices): a load that leaves without changing the current
# choice's speed (a second run that kept to its own core) is noticed this late
MAX_WAIT = 32
CHANGE = 1.3  # the current choice's cost moved by this factor since the last comparison: probe soon
SMOOTHING = 0.3  # weight of a new slice in the current choice's running mean
RECENT = 4  # one thread's cost a probe of more threads must beat: the least of its last RECENT slices


class ThreadGovernor:
    """Chooses, slice by slice, between 1 thread and `threads` (module docstring)."""

    def __init__(self, threads: int, slice_seconds: float = SLICE_SECONDS) -> None:
        if threads < 2:
            raise ValueError(f"a governor chooses between 1 and more threads, got {threads}")
        self.most = threads
        self.slice_seconds = slice_seconds
        self.current = 1
        self.cost: dict[int, float] = {}  # seconds per step: the current choice's running mean, the other's last probe
        self.slice_steps = 1  # steps of the next slice of the current choice (grown from 1 as it is timed)
        self.wait = MIN_WAIT  # slices between probes, doubled by each rejected probe
        self.until_probe = MIN_WAIT
        self.reference: float | None = None  # the current choice's cost at the last comparison
        self.probe: str | None = None  # None, "short" or "full": the part of a probe the next slice runs
        self.warm: set[int] = set()  # choices run once (their first run is not measured)
        self.steps_on = {1: 0, threads: 0}  # steps run on each choice, for the run's report
        self.switches = 0
        self.recent: list[float] = []  # the current choice's last RECENT slice costs per step

    @property
    def other(self) -> int:
        return self.most if self.current == 1 else 1

    def plan(self, remaining: int) -> tuple[int, int]:
        """(threads, steps) of the next slice, at most `remaining` steps (>= 1)."""
        if self.probe is None and self.until_probe <= 0 and self.current in self.cost:
            self.probe = "short"
        if self.probe is None:
            threads, steps = self.current, self.slice_steps
        else:  # sized in time from the other choice's last cost: a probe of a much slower choice stays short
            threads = self.other
            seconds = self.slice_seconds * (PROBE_FRACTION if self.probe == "short" else 1.0)
            steps = max(1, int(seconds / self.cost.get(threads, self.cost[self.current])))
        if threads not in self.warm:
            steps = 1
        return threads, max(1, min(steps, remaining))

    def record(self, threads: int, steps: int, seconds: float) -> None:
        """A slice ran `steps` steps on `threads` threads in `seconds` of wall time."""
        self.steps_on[threads] = self.steps_on.get(threads, 0) + steps
        if steps <= 0:
            return
        if threads not in self.warm:  # launched or woke its threads: not a measure of either choice
            self.warm.add(threads)
            return
        per_step = seconds / steps
        if threads == self.current:
            self._current_ran(per_step)
            return
        self.cost[threads] = per_step  # the other choice's latest cost sizes its next probe
        if self.probe == "short":
            if per_step > EARLY_REJECT * self._beat():
                self._reject()
            else:
                self.probe = "full"
        elif self.probe == "full":
            if SWITCH_GAIN[threads > self.current] * per_step < self._beat():
                self._switch(per_step)
            else:
                self._reject()

    def _beat(self) -> float:
        """The cost per step a probe must beat. On one thread, the least of its recent slices: a probe
        that comes when a burst of other work slowed the last slices (the change that brought the probe
        forward) would otherwise win against the burst, not against one thread; on more threads, their
        running mean, so that doubt leans to one thread."""
        if self.current == 1 and self.recent:
            return min(self.recent)
        return self.cost[self.current]

    def _current_ran(self, per_step: float) -> None:
        old = self.cost.get(self.current)
        cost = per_step if old is None else old + SMOOTHING * (per_step - old)
        self.cost[self.current] = cost
        self.recent = [*self.recent[1 - RECENT :], per_step]
        self._size_slices(cost)
        self.until_probe -= 1
        if self.reference is None:
            self.reference = cost
        elif cost > CHANGE * self.reference or CHANGE * cost < self.reference:  # the load changed: look again
            self.until_probe = min(self.until_probe, 0)
            self.reference = cost

    def _size_slices(self, cost: float) -> None:
        """Slices of ~slice_seconds, growing or shrinking at most 4x at a time (as the runner's chunks)."""
        target = int(self.slice_seconds / max(cost, 1e-12))
        self.slice_steps = max(1, min(max(target, self.slice_steps // 4), 4 * self.slice_steps))

    def _reject(self) -> None:
        self.probe = None
        self.wait = min(2 * self.wait, MAX_WAIT)
        self.until_probe = self.wait
        self.reference = self.cost[self.current]

    def _switch(self, per_step: float) -> None:
        self.probe = None
        self.current = self.other
        self.cost[self.current] = per_step
        self.recent = [per_step]
        self._size_slices(per_step)
        self.wait = self.until_probe = MIN_WAIT
        self.reference = per_step
        self.switches += 1

    def describe(self) -> str:
        """How the steps were shared, e.g. '2 threads for 93 % of 12,000 steps, 3 switches'."""
        total = sum(self.steps_on.values())
        if not total:
            return f"1 or {self.most} threads by measured speed (no steps yet)"
        share = 100.0 * self.steps_on.get(self.most, 0) / total
        switches = f", {self.switches} switch{'es' if self.switches != 1 else ''}"
        return f"{self.most} threads for {share:.0f} % of {total:,} steps{switches}"
