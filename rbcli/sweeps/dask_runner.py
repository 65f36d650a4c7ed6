"""Running batches of variants on Dask (`dask.distributed`): the only module of rbcli that imports Dask.

By default a `LocalCluster` sized to the machine: one single-threaded worker process per CPU this process
may use (the step kernels are serial and hold one core each; processes, not threads, so that the Python
around the kernels runs in parallel too). With a scheduler address (`--scheduler tcp://host:8786`) the
same batches go to an existing cluster, whose workers must have rbcli installed and see the base scene's
folder (mesh files) and, for logs, the output folder at the same paths.

Dask's own guarantees carry the "nothing lost" promise: a task of a worker that dies is run again on
another worker (the scheduler's `allowed-failures`, default 3, then KilledWorker: that batch's variants
become rows with status "error" and the message). Rows come back to the client, which writes each batch's
part as it arrives (table.write_part): a part is never written by a worker.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rbcli.sweeps.batches import Batcher
from rbcli.sweeps.execute import STATUS_ERROR, SweepJob, run_batch, warm_up

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
# Tasks submitted per slot at a time: the one running and the next, queued on the worker (Dask's scheduler
# keeps it there, worker-saturation 1.1 rounding up), so a worker starts its next task without a round trip.
IN_FLIGHT_PER_SLOT = 2
Rows = list[dict[str, Any]]


@dataclass
class ClusterInfo:
    """What the sweep ran on: workers (processes), slots (threads in all), the dashboard (None without
    bokeh), the seconds to start or reach the cluster, to warm every worker's kernels and to close the
    client and cluster at the end, the largest task's variants and the number of tasks."""

    workers: int
    slots: int
    dashboard: str | None
    startup_s: float
    warmup_s: float
    batch: int = 0  # the largest task's variants
    tasks: int = 0
    shutdown_s: float = 0.0


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
) -> ClusterInfo:
    """Run every pending variant in batches; `on_rows` gets each batch's rows as it finishes (in the
    client's thread). scheduler: None (a LocalCluster of `workers`), an address, or a distributed.Client."""
    from distributed import Client, LocalCluster

    started = time.perf_counter()
    cluster = None
    client: Any
    if isinstance(scheduler, Client):
        client, own_client = scheduler, False
    elif scheduler:
        client, own_client = Client(scheduler, timeout="30s"), True
    else:
        import dask

        with dask.config.set(LOCAL_CLUSTER_CONFIG):  # the nannies hand it on to the worker processes
            cluster = LocalCluster(
                n_workers=workers or default_workers(),
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",  # any free port: 8787 may be another cluster's (the dashboard needs bokeh)
                silence_logs=logging.ERROR,
            )
            client, own_client = Client(cluster), True
    futures: list[Any] = []
    info: ClusterInfo | None = None
    try:
        if cluster is None:
            client.wait_for_workers(1, timeout=60)
        slots_by_worker = client.nthreads()
        info = ClusterInfo(
            workers=len(slots_by_worker),
            slots=sum(slots_by_worker.values()),
            dashboard=_dashboard(client),
            startup_s=time.perf_counter() - started,
            warmup_s=0.0,
        )
        shared = None
        if pending:
            warming = time.perf_counter()
            shared = client.scatter(job, broadcast=True)  # sent once per worker, not once per task
            _warm_workers(client, shared, pending[0][1], list(slots_by_worker))
            info.warmup_s = time.perf_counter() - warming
        if on_ready is not None:
            on_ready(info)
        if shared is not None:
            _run_batches(client, shared, pending, on_rows, info, batch, futures)
        return info
    finally:
        closing = time.perf_counter()
        if futures:
            client.cancel(futures)
        if own_client:
            client.close()
        if cluster is not None:
            cluster.close()
        if info is not None:  # the shut-down is reported apart, as the start-up is
            info.shutdown_s = time.perf_counter() - closing


def _dashboard(client: Any) -> str | None:
    if importlib.util.find_spec("bokeh") is None:
        return None
    try:
        return str(client.dashboard_link)
    except Exception:  # noqa: BLE001 - a cluster without a dashboard
        return None


def _warm_workers(client: Any, shared: Any, values: tuple[Any, ...], addresses: list[str]) -> None:
    """Load the first variant's kernels on every worker (in parallel), so no timed batch pays for it; the
    scattered job is unpickled there on the way, once per worker."""
    warm = [
        client.submit(warm_up, shared, values, workers=[address], allow_other_workers=False, pure=False)
        for address in addresses
    ]
    client.gather(warm, errors="skip")


def _run_batches(
    client: Any,
    shared: Any,
    pending: list[Variant],
    on_rows: Callable[[Rows], None],
    info: ClusterInfo,
    batch: int | None,
    futures: list[Any],
) -> None:
    """Keep IN_FLIGHT_PER_SLOT tasks per slot submitted, each sized when it is submitted from the time of
    every row back so far (batches.Batcher): a worker always has its next task queued, so it never waits
    for the client, and the last tasks are the short ones."""
    from distributed import as_completed

    groups: dict[Any, list[Variant]] = {}  # each task's variants, for the failed rows should it fail
    batcher = Batcher(pending, info.slots, fixed=batch)

    def submit() -> list[Any]:
        group = batcher.next_group()
        if not group:
            return []
        future = client.submit(run_batch, shared, group, pure=False, retries=1)
        groups[future.key] = group
        futures.append(future)
        return [future]

    queue = as_completed([f for _ in range(IN_FLIGHT_PER_SLOT * info.slots) for f in submit()])
    for future in queue:
        rows = _rows_of(future, groups.pop(future.key))
        futures.remove(future)
        batcher.measured(rows)
        queue.update(submit())  # before the rows are handed on: the part's write does not delay it
        on_rows(rows)
    info.batch = max(batcher.sizes, default=0)
    info.tasks = len(batcher.sizes)


def _rows_of(future: Any, group: list[Variant]) -> Rows:
    """The batch's rows, or for a task that failed outright (KilledWorker: it took several workers down
    with it), a failed row per variant saying so."""
    try:
        return list(future.result())
    except Exception as exc:  # noqa: BLE001 - never the sweep's end: these variants are reported failed
        message = f"the task failed on the cluster: {type(exc).__name__}: {exc}"
        return [{"variant": index, "status": STATUS_ERROR, "message": message} for index, _ in group]
