"""Watch numba compile: how many functions so far, for how long, which one now; and a stop asked for
meanwhile (a signal) carried out at the next point where stopping is safe.

numba announces every real compilation of a function with a "numba:compile" event and every pass of its
compiler with a "numba:run_pass" event (numba.core.event); a load from its cache fires neither, so a run
whose kernels are all cached sees no event at all, and the first event means kernels are being compiled.

Stopping. numba holds the GIL while it compiles and a Python signal handler runs between any two
bytecodes, also in the ctypes callback LLVM calls once it has emitted a module's object code (numba's
`CodeLibrary._object_compiled_hook`): a KeyboardInterrupt raised there is printed and dropped by ctypes,
the library never receives its object code, and numba's cache save then fails with `RuntimeError: no
compiled object yet for <Library ...>` (the traceback of a Ctrl-C in a first run, issue 44). So the
handler only records the signal, and the watch raises CompileInterrupted at the start of the next function
compile or compiler pass: plain Python in numba's pipeline, outside any callback and any cache write.
CompileInterrupted is a BaseException, as KeyboardInterrupt is, so numba's `except Exception` handlers
(which turn errors into typing errors) let it through. The functions whose compile it cuts short are not
saved; every function finished before was saved whole: numba saves a function after its compile ends,
writing the cache index and then the data file, each to a temporary name renamed into place
(`IndexDataCacheFile._open_for_write`), and no event fires inside a save, so a save is never cut (a
SIGKILL between the two would leave an index naming a missing file, which numba loads as a miss). The
longest stretch without an event is one pass of one function (LLVM optimising the run's chunk loop with
everything it inlines: a few seconds), which bounds how long a stop waits.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numba.core.event as numba_event

WATCHED_EVENTS = ("numba:compile", "numba:run_pass")
# a pass fires far more often than anyone reads a progress line: report the passes at most this often [s]
PASS_REPORT_SECONDS = 0.25


class CompileInterrupted(BaseException):
    """A stop was asked for while numba compiled; raised at the start of a function's compile or of a
    compiler pass (see the module docstring), out of the call that needed the kernel."""


@dataclass(frozen=True)
class CompileProgress:
    """What numba compiled since the watch began: `functions` compiles started (cache loads are not
    compiles), over `seconds` of wall time since the first, `current`: the function being compiled now
    (module.qualname; "" between compiles), `done`: the compile of every function started has ended."""

    functions: int
    seconds: float
    current: str
    done: bool


class _CompileWatch(numba_event.Listener):
    """Listens to numba:compile (a function's compile starts, and ends compiled or failed) and numba:run_pass
    (a compiler pass starts: the points within a function's compile); reports and stops (see above)."""

    def __init__(self, report: Callable[[CompileProgress], None] | None, stop_requested: Callable[[], bool]) -> None:
        self.report = report
        self.stop_requested = stop_requested
        self.functions = 0
        self.started: float | None = None  # perf_counter at the first compile
        # the compiles started and not ended, innermost last: (the event's data, which its end event
        # carries too, and the function's name)
        self.compiling: list[tuple[object, str]] = []
        self.reported = 0.0

    def progress(self) -> CompileProgress:
        seconds = 0.0 if self.started is None else time.perf_counter() - self.started
        current = self.compiling[-1][1] if self.compiling else ""
        return CompileProgress(self.functions, seconds, current, done=not self.compiling)

    def on_start(self, event: numba_event.Event) -> None:
        if self.stop_requested():
            raise CompileInterrupted
        if event.kind == "numba:run_pass":
            if time.perf_counter() - self.reported >= PASS_REPORT_SECONDS:
                self._report()
            return
        function = event.data["dispatcher"].py_func
        if self.started is None:
            self.started = time.perf_counter()
        self.functions += 1
        self.compiling.append((event.data, f"{function.__module__}.{function.__qualname__}"))
        self._report()

    def on_end(self, event: numba_event.Event) -> None:  # never raises: it also ends a compile that failed
        if event.kind != "numba:compile" or not self.compiling or self.compiling[-1][0] is not event.data:
            return  # a pass, or the end of a start this watch stopped before counting it
        self.compiling.pop()
        if not self.compiling:
            self._report()

    def _report(self) -> None:
        if self.report is not None:
            self.reported = time.perf_counter()
            self.report(self.progress())


@contextmanager
def watch_compiles(
    report: Callable[[CompileProgress], None] | None = None, stop_requested: Callable[[], bool] = lambda: False
) -> Iterator[Callable[[], CompileProgress]]:
    """Within the block, `report(progress)` at the start of each function numba compiles, at its last
    end, and every PASS_REPORT_SECONDS in between; CompileInterrupted at the next safe point once
    `stop_requested()` is true. Yields a function returning the progress so far (0 functions: every
    kernel came from the cache)."""
    watch = _CompileWatch(report, stop_requested)
    for kind in WATCHED_EVENTS:
        numba_event.register(kind, watch)
    try:
        yield watch.progress
    finally:
        for kind in WATCHED_EVENTS:
            numba_event.unregister(kind, watch)
