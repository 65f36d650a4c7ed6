"""Running batches of variants on Dask (`dask.distributed`): the only module of rbcli that imports Dask.

By default a `LocalCluster` sized to the machine: one single-threaded worker process per CPU this process
may use (the step kernels are serial and hold one core each; processes, not threads, so that the Python
around the kernels runs in parallel too), every endpoint on 127.0.0.1 unless another host is asked for.
With a scheduler address (`--scheduler tcp://host:8786`) the same batches go to an existing cluster,
whose workers must run the same rbsim and numba (checked: a mismatched worker stops the sweep with one
line naming both versions); mesh files travel with the job (execute.py), so no shared file system is
needed.

Nothing is lost when workers die:
- The job (the base scene's data, the axes, the mesh files' bytes) is a task, not scattered data: when
  every worker holding it dies, the scheduler computes it again from the task it keeps.
- A batch whose task was cancelled, or whose data was lost with its worker, is submitted again (up to
  LOST_TRIES times; then its variants are rows with status "lost", which resuming runs again): never the
  variant's own failure.
- A task that took down worker after worker (Dask's KilledWorker, after the scheduler's
  `allowed-failures` + 1 deaths, 4 with Dask's default) is split: its variants run one per task. A single
  variant's KilledWorker does not yet say it was the culprit: Dask blames every task a dying worker held,
  queued ones too (the memory test recorded its innocent 250-step variant "crashed" in 3 of 8 runs here).
  So it runs once more isolated, when nothing else is in flight, and only a variant that takes its worker
  down on each of those allowed-failures + 1 tries is a row with status "crashed" (out of memory, a crash
  in compiled code) while the others complete. A variant is tried at most 3 x (allowed-failures + 1)
  times (12 by default), the last of them alone.
- A worker lost while the sweep starts, or as it joins, is a lost worker too, never the sweep's end: killed
  while the local cluster starts (its nanny fails to start), the cluster is started again (up to
  LOCAL_START_TRIES times); killed before its version check or its warm-up at the start ended (tasks
  pinned to it, which would wait for it for good), or as it is asked its versions after joining (a broken
  comm for an answer), it is left out. The sweep goes on with the workers that live (and those that
  replace them: a local worker's nanny starts a new one) and notes each loss in ClusterInfo.incidents.
Rows come back to the client, which writes each batch's part as it arrives (table.write_part): a part is
never written by a worker.
"""

from __future__ import annotations

import contextlib
import gc
import importlib.util
import logging
import os
import signal
import sys
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import CancelledError
from dataclasses import dataclass, field
from typing import Any, cast

from rbcli.sweeps.batches import Batcher
from rbcli.sweeps.execute import (
    STATUS_CRASHED,
    STATUS_LOST,
    SweepJob,
    run_batch,
    runtime_versions,
    warm_up,
)

Variant = tuple[int, tuple[Any, ...]]
# Dask's own periodic work, turned down for the local cluster: a sweep's task is one long compiled loop,
# and on a machine with one worker per core every cycle these take comes out of a worker's core. Measured
# on a 1-worker cluster running the flip variants of benchmarks/bench_sweep.py: the worker's other threads
# used 5-6 ms of CPU per 70 ms variant (7-8 %) with the defaults, about 1 ms with these. The profiler
# samples the task thread's stack every 10 ms (holding the GIL); the tick checks the event loop's health
# 50 times a second; the system monitor and the nanny's memory check poll psutil every 0.5 and 0.1 s.
# The dashboard loses its profile page and has coarser graphs; nothing else changes.
LOCAL_CLUSTER_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.memory.monitor-interval": "1s",
}
# Where the local cluster's scheduler, workers and dashboard listen unless asked otherwise: this machine
# only (Dask's dashboard default, ":8787", is every interface).
LOCAL_HOST = "127.0.0.1"


def _worker_env() -> dict[str, str]:
    """RBSIM_THREADS=1 and NUMBA_NUM_THREADS=1 for the local workers unless this process set them
    (runner/threads.py): each worker is one process per core, so its kernels run on one thread."""
    import os

    from rbcli.runner.threads import WORKER_ENV

    wanted = {**WORKER_ENV, "NUMBA_NUM_THREADS": "1"}
    return {name: os.environ.get(name, value) for name, value in wanted.items()}


# Tasks submitted per slot at a time: the one running and the next, queued on the worker (Dask's scheduler
# keeps it there, worker-saturation 1.1 rounding up), so a worker starts its next task without a round trip.
IN_FLIGHT_PER_SLOT = 2
# Times a batch is submitted again after the cluster lost it for its own reasons (cancelled, its data lost
# with a worker, a lost connection) before its variants are recorded "lost": several, since a pre-emptible
# cluster can lose the same task more than once, but bounded, so a cluster that loses everything ends.
LOST_TRIES = 5
# How often the client asks the scheduler for its workers (those that joined resize the batches and are
# version-checked; a warm-up whose worker left is dropped): a round trip of a few milliseconds, small
# beside tasks of up to a second.
WORKERS_POLL_SECONDS = 0.5
# Times the local cluster is started before its failure ends the sweep: a worker process killed while it
# starts fails the whole LocalCluster ("Nanny failed to start"), and a second start rarely meets a second
# kill; a cluster that cannot start (a host it cannot bind) fails every time, so the count stays small.
LOCAL_START_TRIES = 3
Rows = list[dict[str, Any]]


class ClusterRefused(RuntimeError):
    """A worker that cannot give this process's rows (another rbsim or numba, or no rbcli at all)."""


class ClusterStartFailed(RuntimeError):
    """The local cluster failed to start LOCAL_START_TRIES times."""


@dataclass
class ClusterInfo:
    """What the sweep ran on: workers (processes), slots (threads in all), the dashboard (None without
    bokeh), the seconds to start or reach the cluster, to warm every worker's kernels and to close the
    client and cluster at the end, the largest task's variants, the number of tasks, how many were
    submitted again after the cluster lost them, the workers that joined after the start, and a line for
    each worker lost while the sweep started or as it joined (`incidents`: the sweep went on without it)."""

    workers: int
    slots: int
    dashboard: str | None
    startup_s: float
    warmup_s: float
    batch: int = 0  # the largest task's variants
    tasks: int = 0
    shutdown_s: float = 0.0
    resubmitted: int = 0
    joined: int = 0
    incidents: list[str] = field(default_factory=list)


def default_workers() -> int:
    """One worker per CPU this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def run_on_dask(
    job: SweepJob,
    pending: list[Variant],
    on_rows: Callable[[Rows], None],
    *,
    scheduler: Any = None,
    workers: int | None = None,
    batch: int | None = None,
    on_ready: Callable[[ClusterInfo], None] | None = None,
    host: str | None = None,
) -> ClusterInfo:
    """Run every pending variant in batches; `on_rows` gets each batch's rows as it finishes (in the
    client's thread). scheduler: None (a LocalCluster of `workers` listening on `host`, default
    127.0.0.1), an address, or a distributed.Client. Raises ClusterRefused for a mismatched worker.
    A stop signal (Ctrl-C, SIGTERM, SIGHUP) raises in the caller's thread as its handler says, and is
    never lost (_StopSignals)."""
    from distributed import Client

    quiet = contextlib.nullcontext() if isinstance(scheduler, Client) else _dask_logs_quiet()  # a Client: theirs
    with _StopSignals() as stops, quiet:
        return _run(job, pending, on_rows, stops, scheduler, workers, batch, on_ready, host)


# The loggers through which Dask prints in this process: those with handlers of their own (distributed's
# configuration gives distributed.client and tornado.application theirs), and asyncio's, which reaches
# stderr through logging's last resort.
DASK_LOGGERS = ("distributed", "distributed.client", "tornado", "tornado.application", "bokeh", "asyncio")


@contextlib.contextmanager
def _dask_logs_quiet() -> Iterator[None]:
    """Hold back Dask's log lines in this process (all but CRITICAL) while the sweep runs and closes its
    cluster or client, and put the levels back after.

    Every failure they tell of (a worker lost, a task's data gone with it) the sweep handles and tells in
    a line of its own. LocalCluster's `silence_logs` only sets its handlers' levels, and puts them back
    inside its close, while coroutines still end on its loop: SIGTERM mid-sweep (to the sweep's process
    group) then printed an INFO line with the traceback of a closed comm, or an ERROR line, beside the
    clean exit 143 in 3 of 25 runs here. A logger's own level holds until the close has returned."""
    loggers = [logging.getLogger(name) for name in DASK_LOGGERS]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for logger, level in zip(loggers, levels, strict=True):
            logger.setLevel(level)


def _run(
    job: SweepJob,
    pending: list[Variant],
    on_rows: Callable[[Rows], None],
    stops: _StopSignals,
    scheduler: Any,
    workers: int | None,
    batch: int | None,
    on_ready: Callable[[ClusterInfo], None] | None,
    host: str | None,
) -> ClusterInfo:
    from distributed import Client

    started = time.perf_counter()
    cluster = None
    client: Any = None
    own_client = not isinstance(scheduler, Client)
    futures: list[Any] = []
    info: ClusterInfo | None = None
    interrupts = contextlib.ExitStack()
    incidents: list[str] = []
    try:
        if not own_client:
            client = scheduler
        elif scheduler:
            client = Client(scheduler, timeout="30s")
        else:
            interrupts.enter_context(_workers_ignore_interrupts())  # until the cluster is closed
            cluster, client = _start_local_cluster(workers or default_workers(), host or LOCAL_HOST, incidents)
        stops.check()
        if cluster is None:
            client.wait_for_workers(1, timeout=60)
        slots_by_worker = client.nthreads()
        for address in _check_versions(client, list(slots_by_worker)):  # workers that left as they were asked
            incidents.append(f"worker {address} was lost as its versions were checked; the sweep goes on without it")
            del slots_by_worker[address]
        info = ClusterInfo(
            workers=len(slots_by_worker),
            slots=sum(slots_by_worker.values()),
            dashboard=_dashboard(client),
            startup_s=time.perf_counter() - started,
            warmup_s=0.0,
            incidents=incidents,
        )
        shared = None
        if pending:
            warming = time.perf_counter()
            shared = _ClusterJob(client, job)
            for address in _warm_workers(client, shared.future, pending[0][1], list(slots_by_worker)):
                incidents.append(f"worker {address} was lost while its kernels warmed up; the sweep goes on without it")
                del slots_by_worker[address]
            info.workers, info.slots = len(slots_by_worker), sum(slots_by_worker.values())
            info.warmup_s = time.perf_counter() - warming
        stops.check()
        if on_ready is not None:
            on_ready(info)
        if shared is not None:
            batches = _Batches(client, shared, pending, on_rows, info, batch, futures, set(slots_by_worker))
            batches.run(stops.check)
        stops.check()
        return info
    finally:
        closing = time.perf_counter()
        with _signals_deferred():  # a second Ctrl-C must not cut the close short (workers left behind)
            if client is not None and futures:
                client.cancel(futures)
            if client is not None and own_client:
                client.close()
            if cluster is not None:
                cluster.close()
            interrupts.close()
        if info is not None:  # the shut-down is reported apart, as the start-up is
            info.shutdown_s = time.perf_counter() - closing


def _start_local_cluster(workers: int, host: str, incidents: list[str]) -> tuple[Any, Any]:
    """A LocalCluster and its client. A stop signal that arrives while it starts is held until both
    exist and then raised (KeyboardInterrupt), so the caller always has a cluster to close: a signal
    landing inside Dask's start-up would leave its processes and coroutines to die with tracebacks.
    A start that fails (a worker process killed before it joined fails the whole LocalCluster, which
    closes itself) is tried again, up to LOCAL_START_TRIES times, each failure a line in `incidents`."""
    import dask
    from distributed import Client, LocalCluster

    with _signals_deferred(), dask.config.set(LOCAL_CLUSTER_CONFIG):  # the nannies hand it on to the workers
        for attempt in range(1, LOCAL_START_TRIES + 1):
            try:
                cluster = LocalCluster(
                    n_workers=workers,
                    threads_per_worker=1,
                    processes=True,
                    env=_worker_env(),  # one kernel thread per worker: a worker per core already fills the cores
                    host=host,
                    dashboard_address=f"{host}:0",  # any free port: 8787 may be another cluster's (needs bokeh)
                    # the sweep tells each failure Dask meets in its own line (a lost worker is run around);
                    # Dask's ERROR lines (a worker's broken comm, with its traceback) would come beside it
                    silence_logs=logging.CRITICAL,
                )
                break
            except Exception as exc:  # noqa: BLE001 - tried again, then told as the failure it is
                failure = f"{type(exc).__name__}: {exc}"
                if attempt == LOCAL_START_TRIES:
                    raise ClusterStartFailed(
                        f"the local Dask cluster failed to start {attempt} times; the last time: {failure}"
                    ) from None
                incidents.append(
                    f"the local cluster failed to start ({failure}: a worker lost as it started); "
                    f"starting it again (try {attempt + 1} of {LOCAL_START_TRIES})"
                )
        try:
            client = Client(cluster)
        except BaseException:
            cluster.close()
            raise
    return cluster, client


class _StopSignals:
    """While a sweep runs on Dask, SIGINT, SIGTERM and SIGHUP (main thread, where their handlers are Python
    functions: Python's own KeyboardInterrupt for Ctrl-C, the CLI's for the others) are noted before
    their handler runs, and `check()` runs the handler again for a signal whose exception did not end
    the sweep.

    Why: a handler's exception is raised wherever the main thread happens to be, and Python swallows an
    exception raised inside a garbage-collection callback or a finaliser with an "Exception ignored"
    line. distributed installs a gc callback (distributed.gc.GCDiagnosis), and a Ctrl-C landing in it
    while the cluster warmed up was lost: the sweep printed that traceback, ran to the end and exited 0
    (measured: 1 in ~10 Ctrl-Cs 0.4 s into the start-up). So a signal that finds the main thread inside a
    gc callback or a __del__ is noted and sent again REDELIVER_SECONDS later (then it finds ordinary
    code). Python swallows exceptions in other places that no frame shows (a weakref callback that a
    collection runs: WeakValueDictionary's `remove`, seen in a CI run), and reports each to
    `sys.unraisablehook`: while a stop is being delivered, that hook sends a swallowed stop again the
    same way instead of printing it. As a last guard the checks (after the start, after the warm-up, at
    each task's end and at the end) run the handler for a noted signal whose exception did not end the
    sweep."""

    def __init__(self) -> None:
        self.pending: list[int] = []
        self._previous: dict[int, Callable[[int, Any], Any]] = {}  # the handlers noted signals go on to
        self._redeliveries: list[threading.Timer] = []  # cancelled once a stop is delivered: one stop, once
        self._unraisable_hook: Callable[[Any], Any] | None = None  # the hook installed before ours
        self._delivering: BaseException | None = None  # what the handler being delivered raised

    def __enter__(self) -> _StopSignals:
        if threading.current_thread() is threading.main_thread():
            for number in _stop_signals():
                handler = signal.getsignal(number)
                if callable(handler):
                    self._previous[number] = cast(Callable[[int, Any], Any], handler)
                    signal.signal(number, self._note)
            self._unraisable_hook = sys.unraisablehook
            sys.unraisablehook = self._unraisable
        return self

    def _note(self, signum: int, frame: Any) -> None:
        if _in_finaliser(frame):  # its exception would be swallowed here: deliver it again in a moment
            self._send_again(signum)
            return
        self._deliver(signum, frame, noted=True)

    def _send_again(self, signum: int) -> None:
        self.pending.append(signum)
        timer = threading.Timer(REDELIVER_SECONDS, _redeliver, (signum,))
        self._redeliveries.append(timer)
        timer.start()

    def _unraisable(self, unraisable: Any) -> None:  # noqa: ANN401 - sys.UnraisableHookArgs
        """sys.unraisablehook while installed: the stop exception being delivered, swallowed where Python
        cannot raise it, is sent again; anything else goes to the previous hook."""
        if self._delivering is not None and unraisable.exc_value is self._delivering and self.pending:
            self._delivering = None
            self._send_again(self.pending[0])
            return
        previous = self._unraisable_hook or sys.__unraisablehook__
        previous(unraisable)

    def check(self) -> None:
        """Run the handler again for the first noted signal (its exception was swallowed), if any."""
        if self.pending:
            self._deliver(self.pending[0], None, noted=False)

    def _deliver(self, signum: int, frame: Any, noted: bool) -> None:
        """Run the handler for signum, with no redelivery left due (it would raise a second time, maybe in
        the caller's own handling of the first); `noted`: kept in `pending` while the handler runs, for a
        check to raise again if its exception is swallowed (a check's own raise propagates)."""
        for timer in self._redeliveries:
            timer.cancel()
        self._redeliveries.clear()
        self.pending[:] = [signum] if noted else []
        try:
            self._previous[signum](signum, frame)
        except BaseException as exc:  # the stop: noted for the unraisable hook, should it be swallowed
            self._delivering = exc
            raise
        self.pending.clear()  # the handler returned without raising: nothing to deliver again

    def __exit__(self, *exc: object) -> None:
        for timer in self._redeliveries:
            timer.cancel()
        for number, handler in self._previous.items():
            signal.signal(number, handler)
        if self._unraisable_hook is not None:
            sys.unraisablehook = self._unraisable_hook
            self._unraisable_hook = None


# a stop signal that landed in a gc callback or a finaliser is sent again after this long [s]
REDELIVER_SECONDS = 0.01


def _stop_signals() -> list[int]:
    """SIGINT, SIGTERM and SIGHUP, those this platform has."""
    return [int(getattr(signal, name)) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)]


def _in_finaliser(frame: Any) -> bool:  # noqa: ANN401 - a frame
    """Whether `frame` runs inside a gc callback or a __del__ method (Python swallows their exceptions)."""
    callbacks = {getattr(getattr(cb, "__func__", cb), "__code__", None) for cb in gc.callbacks}
    for _ in range(64):
        if frame is None:
            return False
        if frame.f_code in callbacks or frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def _redeliver(signum: int) -> None:
    """The signal again, to the main thread (it wakes a blocking wait there, as the first one did)."""
    main = threading.main_thread().ident  # the thread Python runs signal handlers in
    if main is not None and hasattr(signal, "pthread_kill"):
        signal.pthread_kill(main, signum)
    else:  # pragma: no cover - not POSIX
        import _thread

        _thread.interrupt_main(signal.Signals(signum))


@contextlib.contextmanager
def _signals_deferred() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP (main thread only) until the block ends, then deliver the first
    that arrived to the handler that was there before (the CLI's: a KeyboardInterrupt and its exit status)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    previous: dict[int, Any] = {}

    def hold(signum: int, frame: Any) -> None:
        arrived.append(signum)

    for number in _stop_signals():
        previous[number] = signal.signal(number, hold)
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        if arrived:
            signal.raise_signal(arrived[0])


@contextlib.contextmanager
def _workers_ignore_interrupts() -> Iterator[None]:
    """Worker processes spawned meanwhile (at the start, or when a nanny restarts one) ignore SIGINT.

    A terminal's Ctrl-C goes to the whole process group: the workers of the local cluster got it too and
    printed KeyboardInterrupt tracebacks (interrupted in their imports, or in a task), while this process,
    which owns them, stops the sweep and closes them anyway. A handler cannot be inherited, but an ignored
    signal is, across exec: multiprocessing starts the workers through a two-line shell script that
    ignores SIGINT and executes the same Python (`multiprocessing.set_executable`, restored after)."""
    import multiprocessing.spawn as spawn
    import shlex
    import shutil
    import tempfile

    shell = shutil.which("sh")
    if os.name != "posix" or shell is None:  # pragma: no cover - the workers keep Python's own handler
        yield
        return
    python = spawn.get_executable()
    folder = tempfile.mkdtemp(prefix="rbsim-workers-")
    wrapper = os.path.join(folder, "python")
    with open(wrapper, "w", encoding="utf-8") as handle:
        handle.write(f"#!{shell}\ntrap '' INT\nexec {shlex.quote(os.fsdecode(python))} \"$@\"\n")
    os.chmod(wrapper, 0o755)
    spawn.set_executable(wrapper)
    try:
        yield
    finally:
        spawn.set_executable(python)
        shutil.rmtree(folder, ignore_errors=True)


def _check_versions(client: Any, addresses: list[str]) -> list[str]:
    """Refuse workers at the start whose rbsim or numba differ from this process's (one line naming both);
    return those lost before they answered, which the sweep goes on without. Asked with a task pinned to
    each (_run_on_each): nothing runs on them yet, and a task asks nothing of a worker that died."""
    if not addresses:
        return []
    answers, lost = _run_on_each(client, addresses, runtime_versions)
    _refuse_mismatched({a: f.exception() if f.status == "error" else f.result() for a, f in answers.items()})
    return lost


def _check_joined_versions(client: Any, addresses: list[str]) -> list[str]:
    """Refuse workers that joined while the sweep runs whose rbsim or numba differ from this process's;
    return those lost as they were asked. Asked with client.run, which runs in each worker's event loop at
    once, beside the batch the scheduler may already have given it (a task would wait for that batch,
    and the client's loop with it). An answer that is a comm error (CommClosedError, a connection timeout:
    OSErrors) is not the worker's answer but the worker lost; before, it was refused as one that "cannot
    run rbsim". (A worker that died before the scheduler's connection reached it costs that connection's
    retries, distributed.comm.timeouts.connect, 30 s by default.)"""
    if not addresses:
        return []
    try:
        theirs = client.run(runtime_versions, workers=addresses, on_error="return")
    except Exception as exc:  # noqa: BLE001 - told as the refusal it is
        raise ClusterRefused(f"cannot ask the workers for their versions: {type(exc).__name__}: {exc}") from None
    lost = [address for address in addresses if isinstance(theirs.get(address), OSError)]
    _refuse_mismatched({address: got for address, got in theirs.items() if address not in lost})
    return lost


def _refuse_mismatched(answers: dict[str, Any]) -> None:
    """Raise ClusterRefused (one line naming both versions) for the first worker, by address, whose answer
    to runtime_versions is an exception (no rbcli there, say) or versions other than this process's."""
    mine = runtime_versions()
    for address in sorted(answers):
        got = answers[address]
        if isinstance(got, BaseException):
            raise ClusterRefused(f"worker {address} cannot run rbsim {mine[0]}'s variants: {type(got).__name__}: {got}")
        if tuple(got) != mine:
            raise ClusterRefused(
                f"worker {address} runs rbsim {got[0]} with numba {got[1]}, this rbsim is {mine[0]} with numba "
                f"{mine[1]}: install the same versions on every worker"
            )


def _run_on_each(client: Any, addresses: list[str], function: Callable, *args: Any) -> tuple[dict[str, Any], list[str]]:
    """Run function(*args) once on each worker, as a task pinned to it and ahead of the batches queued there;
    returns (address -> its finished future, the workers lost before theirs ended).

    A task pinned to a worker that died waits for that address for good (a replacement has another: the
    warm-up hung so), so every WORKERS_POLL_SECONDS the tasks of workers the scheduler no longer has are
    cancelled. Not client.run: the scheduler it asks through retries connecting to a worker that died as
    it was asked for distributed.comm.timeouts.connect (30 s), and a task asks nothing of a dead worker."""
    from distributed import wait

    running = {
        client.submit(function, *args, workers=[address], allow_other_workers=False, pure=False, priority=1): address
        for address in addresses
    }
    answers: dict[str, Any] = {}
    lost: list[str] = []
    while running:
        # a timeout, or a task cancelled meanwhile (the scheduler's doing): the statuses below tell which
        with contextlib.suppress(TimeoutError, CancelledError):
            wait(list(running), timeout=WORKERS_POLL_SECONDS, return_when="FIRST_COMPLETED")
        present = client.nthreads()
        for future, address in list(running.items()):
            if future.status in ("finished", "error"):
                answers[running.pop(future)] = future
            elif future.status == "cancelled" or address not in present:
                future.cancel()
                lost.append(running.pop(future))
    return answers, lost


def _dashboard(client: Any) -> str | None:
    if importlib.util.find_spec("bokeh") is None:
        return None
    try:
        return str(client.dashboard_link)
    except Exception:  # noqa: BLE001 - a cluster without a dashboard
        return None


def job_value(job: SweepJob) -> SweepJob:
    """The job as a task's result: the scheduler keeps the task (with the job in it), so it can compute
    the job again on another worker when every worker holding it has died, which scattered data cannot."""
    return job


class _ClusterJob:
    """The job's future on the cluster, submitted again should the cluster forget it altogether."""

    def __init__(self, client: Any, job: SweepJob) -> None:
        self._client = client
        self._job = job
        self.future = self._submit()

    def _submit(self) -> Any:
        return self._client.submit(job_value, self._job, key=f"rbsim-sweep-job-{uuid.uuid4().hex}", pure=False)

    def current(self) -> Any:
        """The job's future, resubmitted when cancelled or failed (a lost one the scheduler recomputes)."""
        if self.future.status in ("cancelled", "error"):
            self.future = self._submit()
        return self.future


def _warm_workers(client: Any, shared: Any, values: tuple[Any, ...], addresses: list[str]) -> list[str]:
    """Load the first variant's kernels on every worker (in parallel), so no timed batch pays for it; the
    job is fetched and unpickled there on the way, once per worker. Returns the workers lost before their
    warm-up ended. A warm-up that failed is no loss: that worker's first batch compiles the kernels."""
    return _run_on_each(client, addresses, warm_up, shared, values)[1]


@dataclass
class SweepTask:
    """A task's variants and how often the cluster lost it; `alone`: split out of a task that killed
    its workers; `isolated`: a single variant whose task did, run again with nothing else in flight."""

    group: list[Variant]
    lost: int = 0  # times the cluster lost this group's task so far
    alone: bool = False  # split out of a task that killed its workers
    isolated: bool = False  # one variant whose task killed its workers: runs with nothing else in flight


class _Batches:
    """Keep IN_FLIGHT_PER_SLOT tasks per slot submitted, each sized when it is submitted from the time of
    every row back so far (batches.Batcher): a worker always has its next task queued, so it never waits
    for the client, and the last tasks are the short ones. Workers that join are counted in (and checked)
    as they come; a task the cluster lost is submitted again before any new one."""

    def __init__(
        self,
        client: Any,
        job: _ClusterJob,
        pending: list[Variant],
        on_rows: Callable[[Rows], None],
        info: ClusterInfo,
        batch: int | None,
        futures: list[Any],
        known: set[str],
    ) -> None:
        self.client, self.job, self.on_rows, self.info, self.futures = client, job, on_rows, info, futures
        self.batcher = Batcher(pending, info.slots, fixed=batch)
        self.tasks: dict[Any, SweepTask] = {}
        self.again: deque[SweepTask] = deque()  # lost or split tasks, submitted before new groups
        self.known = known
        self.polled = time.monotonic()
        self.isolating = False  # an isolated task is in flight: nothing else is submitted meanwhile

    def run(self, check_stops: Callable[[], None]) -> None:
        """Submit and collect until every variant has rows; `check_stops` at each task's end (a stop
        signal whose exception was swallowed is raised there: _StopSignals)."""
        from distributed import as_completed

        # workers that joined since the slots were counted (while the caller's on_ready ran, or during the
        # warm-up) are taken in before the first batches are sized: a short sweep may end before the first
        # timed poll, and it then ran on the workers of the start alone
        self.poll_workers(force=True)
        queue = as_completed([f for _ in range(IN_FLIGHT_PER_SLOT * self.info.slots) for f in self.submit()])
        for future in queue:
            check_stops()
            task = self.tasks.pop(future.key)
            self.futures.remove(future)
            self.isolating = self.isolating and not task.isolated
            rows = self.outcome(task, future)
            future.release()  # the scheduler may forget it: a worker lost later must not run it again
            self.poll_workers()
            while len(self.futures) < IN_FLIGHT_PER_SLOT * max(1, self.info.slots) and (new := self.submit()):
                queue.update(new)  # before the rows are handed on: the part's write does not delay it
            if rows:
                self.batcher.measured(rows)
                self.on_rows(rows)
        self.info.batch = max(self.batcher.sizes, default=0)
        self.info.tasks = len(self.batcher.sizes)

    def submit(self) -> list[Any]:
        """Submit the next task: one to run again, else a new batch, else (once nothing else is in
        flight) an isolated variant; [] when there is none, or an isolated one runs."""
        if self.isolating:
            return []
        task = next((t for t in self.again if not t.isolated), None)
        if task is None:
            group = self.batcher.next_group()
            if group:
                task = SweepTask(group)
            elif self.again and not self.futures:
                task = self.again.popleft()
                self.isolating = True
            else:
                return []
        else:
            self.again.remove(task)
        future = self.client.submit(run_batch, self.job.current(), task.group, pure=False)
        self.tasks[future.key] = task
        self.futures.append(future)
        return [future]

    def outcome(self, task: SweepTask, future: Any) -> Rows:
        """The task's rows; or [] with the task queued to run again (lost by the cluster, or split after
        killing its workers); or, out of tries, a row per variant saying what happened."""
        try:
            return list(future.result())
        except Exception as exc:  # noqa: BLE001 - never the sweep's end: run again, or rows that say why
            rows, again = settle_failure(task, exc)
            self.again.extend(again)
            self.info.resubmitted += sum(len(t.group) for t in again)
            return rows

    def poll_workers(self, force: bool = False) -> None:
        """Take in workers that joined: count their slots (the batches and the tasks in flight follow) and
        check their versions; forget those that left. At most every WORKERS_POLL_SECONDS unless `force`."""
        now = time.monotonic()
        if not force and now - self.polled < WORKERS_POLL_SECONDS:
            return
        self.polled = now
        slots_by_worker = self.client.nthreads()
        joined = [address for address in slots_by_worker if address not in self.known]
        for address in _check_joined_versions(self.client, joined):  # lost as it was asked: gone from the cluster
            self.info.incidents.append(f"worker {address} was lost as it joined; the sweep goes on without it")
            del slots_by_worker[address]
            joined.remove(address)
        self.info.joined += len(joined)
        self.known = set(slots_by_worker)
        self.info.slots = max(1, sum(slots_by_worker.values()))
        self.info.workers = len(slots_by_worker)
        self.batcher.slots = self.info.slots


def settle_failure(task: SweepTask, exc: BaseException) -> tuple[Rows, list[SweepTask]]:
    """What follows a task that gave no rows: (rows, tasks to submit again). A task the scheduler gave up
    on after it killed allowed-failures + 1 workers (KilledWorker) is split into one task per variant, a
    single variant's runs again isolated (module docstring), and an isolated variant's is a "crashed" row;
    anything else (cancelled, data lost with a worker, a connection) is the cluster's doing: the task runs
    again, up to LOST_TRIES times, then its variants are "lost" rows."""
    from distributed import KilledWorker

    if isinstance(exc, KilledWorker):
        if len(task.group) > 1:  # one variant (or more) kills its worker: find which, one per task
            return [], [SweepTask([variant], alone=True) for variant in task.group]
        if not task.isolated:  # it may have been queued on the culprit's worker: try it with nothing beside it
            return [], [SweepTask(task.group, alone=True, isolated=True)]
        return failed_rows(task.group, STATUS_CRASHED, _crash_message(exc, int(exc.allowed_failures) + 1)), []
    task.lost += 1
    if task.lost < LOST_TRIES:
        return [], [task]
    return failed_rows(task.group, STATUS_LOST, _lost_message(exc, task.lost)), []


def failed_rows(group: list[Variant], status: str, message: str) -> Rows:
    """A row per variant of a task that gave none (status "crashed" or "lost")."""
    return [{"variant": index, "status": status, "message": message} for index, _ in group]


def _crash_message(exc: BaseException, tries: int) -> str:
    return (
        f"the variant took down its worker on each of its {tries} tries with nothing else running (out of "
        f"memory, or a crash); "
        f"{type(exc).__name__}: {exc}"
    )


def _lost_message(exc: BaseException, tries: int) -> str:
    return (
        f"the cluster lost this variant's task {tries} times (cancelled, or its data lost with a worker); "
        f"run the sweep again to retry it; {type(exc).__name__}: {exc}"
    )
