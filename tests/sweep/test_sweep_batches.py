"""How a sweep's variants are grouped into tasks (rbcli/sweeps/batches.py): every variant exactly once and
in order, tasks of at most TASK_SECONDS of measured work, shrinking towards TAIL_SECONDS at the end so the
slots finish together, and sized from every measured row rather than the first."""

from __future__ import annotations

import signal
from types import SimpleNamespace

import pytest

from rbcli.sweeps.batches import TAIL_SECONDS, TASK_SECONDS, Batcher, batch_size


def hand_out(n: int, slots: int, seconds: float, fixed: int | None = None) -> list[list[int]]:
    """Every group a Batcher hands out when each variant measures `seconds`, fed back as it would be on
    a cluster: a group's rows are measured before the next group is sized."""
    batcher = Batcher(list(range(n)), slots, fixed=fixed)
    groups = []
    while group := batcher.next_group():
        groups.append(group)
        batcher.measured([{"wall_s": seconds}] * len(group))
    assert batcher.sizes == [len(g) for g in groups]
    return groups


@pytest.mark.parametrize(
    ("n", "slots", "seconds"),
    [(192, 2, 0.066), (192, 1, 0.066), (64, 2, 0.75), (16, 2, 0.066), (1000, 2, 0.002), (5, 4, 0.01)],
)
def test_every_variant_once_in_order_with_tasks_of_bounded_work(n, slots, seconds):
    groups = hand_out(n, slots, seconds)
    assert [v for g in groups for v in g] == list(range(n))
    work = [len(g) * seconds for g in groups]
    # the probes are single variants; after them no task exceeds TASK_SECONDS unless one variant does
    assert all(w <= max(TASK_SECONDS, seconds) + 1e-12 for w in work)
    # the tail: the sizes never grow again once they start to shrink, and only the very last task (what
    # is left) or a task of a single variant is below the floor
    sizes = [len(g) for g in groups[slots:]]
    shrinking = sizes[sizes.index(max(sizes)) :]
    assert all(b <= a for a, b in zip(shrinking, shrinking[1:], strict=False))
    assert all(len(g) == 1 or len(g) * seconds >= TAIL_SECONDS - 1e-12 for g in groups[:-1])


def test_short_variants_are_batched_and_the_last_tasks_are_short():
    # 192 variants of 66 ms on 2 slots (the flip benchmark): about 1 s tasks, then down to ~0.2 s
    groups = hand_out(192, 2, 0.066)
    sizes = [len(g) for g in groups]
    assert max(sizes) == int(TASK_SECONDS / 0.066)
    assert sizes[-1] * 0.066 <= 2 * TAIL_SECONDS
    # enough tasks to even out the load: at least 4 per slot
    assert len(groups) >= 4 * 2


def test_long_variants_run_one_per_task():
    assert {len(g) for g in hand_out(64, 2, 0.75)} == {1}


def test_the_estimate_is_the_mean_of_every_row_not_the_first():
    batcher = Batcher(list(range(100)), 1)
    assert batcher.next_group() == [0]  # a probe
    batcher.measured([{"wall_s": 1.0}])  # a first variant slowed by another process
    batcher.measured([{"wall_s": 0.01}] * 9)  # then nine at their usual time: mean 0.109 s
    size = len(batcher.next_group())
    assert size == batch_size(1.09 / 10, 99, 1) == int(TASK_SECONDS / 0.109)


def test_a_fixed_batch_is_kept():
    assert [len(g) for g in hand_out(10, 2, 0.5, fixed=3)] == [3, 3, 3, 1]


def test_an_isolated_variant_is_submitted_only_when_nothing_else_is_in_flight():
    """dask_runner._Batches: a variant to run isolated waits for every task in flight (and for every new
    batch) and then runs with nothing beside it, so a worker's death can be blamed on it alone."""
    from rbcli.sweeps.dask_runner import ClusterInfo, SweepTask, _Batches

    submitted: list[tuple] = []

    class Client:
        def submit(self, fn, job, group, pure):  # noqa: ANN001, ANN202
            submitted.append(tuple(index for index, _ in group))
            return SimpleNamespace(key=f"task-{len(submitted)}")

    job = SimpleNamespace(current=lambda: None)
    info = ClusterInfo(workers=1, slots=1, dashboard=None, startup_s=0.0, warmup_s=0.0)
    batches = _Batches(Client(), job, [(0, ()), (1, ())], lambda rows: None, info, 1, [], {"w"})
    batches.again.append(SweepTask([(9, ())], alone=True, isolated=True))
    assert batches.submit() and batches.submit() and submitted == [(0,), (1,)]  # the new batches first
    assert batches.submit() == []  # the isolated one waits: two tasks are in flight
    batches.futures.clear()
    assert batches.submit() and submitted[-1] == (9,) and batches.isolating
    batches.again.append(SweepTask([(7, ())]))  # lost meanwhile: it waits until the isolated one is done
    assert batches.submit() == [] and submitted[-1] == (9,)


def test_a_failed_task_is_run_again_or_recorded_never_dropped():
    """What follows a Dask task that gave no rows (dask_runner.settle_failure): every variant of it either
    runs again or gets a row saying why; a KilledWorker splits a batch into single variants, runs a single
    variant again isolated (Dask blames the tasks queued on a dying worker too) and makes an isolated one
    "crashed"; any other failure (the cluster's) runs the task again LOST_TRIES - 1 times, then its
    variants are "lost" rows."""
    from distributed import KilledWorker
    from distributed.client import FutureCancelledError

    from rbcli.sweeps.dask_runner import LOST_TRIES, SweepTask, settle_failure

    killed = KilledWorker("run_batch-1", SimpleNamespace(address="tcp://127.0.0.1:1"), 3)  # allowed-failures 3
    rows, again = settle_failure(SweepTask([(4, (1.0,)), (5, (2.0,))]), killed)
    assert rows == [] and [t.group for t in again] == [[(4, (1.0,))], [(5, (2.0,))]] and all(t.alone for t in again)
    rows, again = settle_failure(again[0], killed)
    assert rows == [] and [t.group for t in again] == [[(4, (1.0,))]] and again[0].isolated
    rows, again = settle_failure(again[0], killed)
    assert again == [] and [(r["variant"], r["status"]) for r in rows] == [(4, "crashed")]
    assert "on each of its 4 tries" in rows[0]["message"]
    task = SweepTask([(7, ()), (8, ())])
    cancelled = FutureCancelledError("run_batch-2", "scheduler-connection-lost")
    for _ in range(LOST_TRIES - 1):
        rows, again = settle_failure(task, cancelled)
        assert rows == [] and again == [task]
    rows, again = settle_failure(task, cancelled)
    assert again == [] and [(r["variant"], r["status"]) for r in rows] == [(7, "lost"), (8, "lost")]
    assert "FutureCancelledError" in rows[0]["message"] and f"{LOST_TRIES} times" in rows[0]["message"]


def test_a_ctrl_c_that_lands_in_a_gc_callback_is_delivered_again_not_swallowed():
    """Python swallows an exception raised inside a gc callback ("Exception ignored in ..."), and
    distributed installs one: a Ctrl-C landing there while a sweep's cluster warmed up was lost (the sweep
    ran on and exited 0). Inside dask_runner._StopSignals it is sent again a moment later and raises in
    ordinary code; without it the sleep below runs to its end."""
    import gc
    import time

    from rbcli.sweeps.dask_runner import _StopSignals

    fired: list[bool] = []

    def interrupt_inside_gc(phase: str, info: dict) -> None:
        if phase == "start" and not fired:
            fired.append(True)
            signal.raise_signal(signal.SIGINT)  # its handler runs here, inside the callback

    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    gc.callbacks.append(interrupt_inside_gc)
    try:
        with _StopSignals(), pytest.raises(KeyboardInterrupt):
            gc.collect()
            assert fired
            deadline = time.monotonic() + 5.0
            while time.monotonic() < deadline:
                time.sleep(0.01)
    finally:
        gc.callbacks.remove(interrupt_inside_gc)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_ctrl_c_swallowed_in_a_weakref_callback_is_delivered_again():
    """Python swallows an exception raised in a weakref callback too, and no frame shows that it will (a CI
    run lost a Ctrl-C in WeakValueDictionary's `remove`, which a collection ran inside the gc test
    above): the handler's exception reaches sys.unraisablehook, and _StopSignals sends the signal again."""
    import time
    import weakref

    from rbcli.sweeps.dask_runner import _StopSignals

    class Thing:
        pass

    def interrupt_in_callback(ref: object) -> None:
        signal.raise_signal(signal.SIGINT)  # its handler runs here, inside the weakref callback

    thing = Thing()
    ref = weakref.ref(thing, interrupt_in_callback)
    with _StopSignals(), pytest.raises(KeyboardInterrupt):
        del thing  # the callback runs now: its KeyboardInterrupt is "ignored" by Python
        assert ref() is None
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline:
            time.sleep(0.01)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_stop_whose_exception_was_swallowed_is_raised_at_the_next_check():
    """The last guard of _StopSignals: a noted signal whose exception did not end the sweep (swallowed
    where no frame shows it) runs its handler again at the next check."""
    from rbcli.sweeps.dask_runner import _StopSignals

    with _StopSignals() as stops:
        stops.check()  # nothing noted: nothing happens
        try:
            stops._note(signal.SIGINT, None)  # the handler raises, and the exception is lost
        except KeyboardInterrupt:
            pass
        with pytest.raises(KeyboardInterrupt):
            stops.check()
        stops.check()  # delivered once
