"""`rbsim sweep SWEEP.yaml`: run every variant of a sweep on Dask and gather one Parquet table.

Exit status (cli/exit_codes.py): 0 when every variant has its own result (variants that diverged, that
the loader rejected or that raised are rows too, with their status and message), 4 when some have none:
lost to the cluster more often than it retries, or taking their worker down on every try (run the same
command again: it retries the lost ones, with --retry-failed every variant that did not complete), 1 for
an invalid sweep file, an output folder that cannot take it, a scheduler that cannot be reached or
workers of another rbsim or numba version, 128 + the signal when stopped (130 Ctrl-C, 143 SIGTERM, 129
SIGHUP; the finished batches are kept: run the same command again to resume).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import typer

from rbcli.cli import messages
from rbcli.cli.exit_codes import ExitCode, signal_exit


def sweep(
    file: Path = typer.Argument(
        ..., metavar="SWEEP", help="Sweep file (YAML): a base scene and the axes to vary (docs/sweeps.md)."
    ),
    scheduler: str | None = typer.Option(
        None,
        "--scheduler",
        metavar="ADDRESS",
        help="Address of a running Dask scheduler, tcp://host:8786 [default: a local cluster]",
    ),
    workers: int | None = typer.Option(
        None, "--workers", "-w", min=1, metavar="N", help="Worker processes of the local cluster [default: one per CPU]"
    ),
    serial: bool = typer.Option(False, "--serial", help="Run the variants one by one in this process (no Dask)"),
    batch: int | None = typer.Option(
        None, "--batch", min=1, metavar="N", help="Variants per task [default: the file's batch, else ~0.5 s of work]"
    ),
    output: Path | None = typer.Option(
        None, "--output", "-o", metavar="FOLDER", help="Results folder [default: outputs/<sweep name>]"
    ),
    fresh: bool = typer.Option(False, "--fresh", help="Discard the folder's earlier results instead of resuming"),
    retry_failed: bool = typer.Option(
        False, "--retry-failed", help="On resuming, run again every variant that did not complete, not only lost ones"
    ),
    host: str | None = typer.Option(
        None, "--host", metavar="HOST", help="Interface the local cluster listens on [default: 127.0.0.1]"
    ),
    logs: bool | None = typer.Option(
        None,
        "--logs/--no-logs",
        help="Write each variant's recording to <folder>/logs [default: the sweep file's logs setting]",
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar"),
) -> None:
    """Run a sweep (a base scene over a grid, a list or random samples of its values); resumes by default."""
    from rbcli.sweeps.dask_runner import ClusterRefused, ClusterStartFailed  # (Dask only inside its functions)
    from rbcli.sweeps.load import analyse_sweep
    from rbcli.sweeps.run import SERIAL, SweepOutputError, run_sweep

    if not file.is_file():
        raise messages.fail(f"sweep file not found: {file}", expected="a path to a YAML sweep file")
    spec, issues = analyse_sweep(file)
    messages.issues(issues, file)
    if spec is None:
        raise typer.Exit(ExitCode.INVALID)
    messages.status(
        f"sweep {spec.name}: {spec.variant_count} variants of {spec.scene_path} "
        f"({len(spec.axes)} ax{'is' if len(spec.axes) == 1 else 'es'}, {spec.combine})"
    )
    progress = _Progress(quiet)
    received: list[int] = []  # the stop signals (SIGTERM, SIGHUP) that reached the sweep
    try:
        with _terminate_as_interrupt() as received:
            result = run_sweep(
                spec,
                scheduler=SERIAL if serial else scheduler,
                workers=workers,
                batch=batch,
                output=output,
                fresh=fresh,
                logs=logs,
                on_start=progress.start,
                on_rows=progress.advance,
                retry_failed=retry_failed,
                host=host,
            )
    except (SweepOutputError, ClusterRefused, ClusterStartFailed) as exc:
        progress.stop()
        raise messages.fail(str(exc)) from None
    except (OSError, TimeoutError) as exc:  # no scheduler at that address, or no workers joined it
        progress.stop()
        where = f"the Dask scheduler at {scheduler}" if scheduler else "the local Dask cluster"
        raise messages.fail(
            f"cannot run on {where}: {type(exc).__name__}: {exc}; the variants finished so far are kept",
            expected="a reachable scheduler; run the same command again to resume",
        ) from None
    except KeyboardInterrupt:
        progress.stop()
        done = f"{progress.finished} of {progress.total} variants finished and kept" if progress.started else ""
        messages.status(f"interrupted: {done or 'before any variant ran'}; run the same command again to resume")
        raise typer.Exit(signal_exit(received[0]) if received else ExitCode.SIGINT) from None
    progress.stop()
    progress.incidents(result.cluster)  # workers lost as they joined, after the start was reported
    from rbcli.sweeps.report import failures, status_counts
    from rbcli.sweeps.table import RESULTS_FILE

    counts = status_counts(result.table)
    rate = f"{result.ran} variants in {result.wall_s:.2f} s" if result.ran else "nothing left to run"
    messages.status(
        f"{result.variants} variants: " + ", ".join(f"{n} {s}" for s, n in counts.most_common()) + f" ({rate}) "
        f"-> {result.output / RESULTS_FILE if result.output else ''}"
    )
    for line in failures(result.table, limit=5):
        messages.status(f"  {line}")
    if not result.all_finished:
        messages.status(
            f"{result.unfinished + result.crashed} of {result.variants} variants have no result of their own "
            "(lost to the cluster, or crashing their worker); run the same command again to retry the lost ones"
            + (", with --retry-failed the crashed ones" if result.crashed else "")
        )
        raise typer.Exit(ExitCode.INCOMPLETE)


class _Progress:
    """The bar over variants (rich), started once the workers are ready; plain lines when not a terminal."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.bar: Any = None
        self.task: Any = None
        self.total = 0
        self.finished = 0
        self.failed = 0
        self.started = False  # the workers are ready, the variants running
        self.told = 0  # the cluster's incidents reported so far

    def start(self, total: int, done: int, cluster: Any) -> None:
        self.total, self.finished, self.started = total, done, True
        if cluster is not None:
            dashboard = f"; dashboard: {cluster.dashboard}" if cluster.dashboard else ""
            workers = f"{cluster.workers} worker{'s' * (cluster.workers != 1)}"
            messages.status(
                f"Dask: {workers} ({cluster.slots} slot{'s' * (cluster.slots != 1)}) ready in "
                f"{cluster.startup_s:.1f} s, kernels warm in {cluster.warmup_s:.1f} s{dashboard}"
            )
            self.incidents(cluster)
        if done:
            messages.status(f"resuming: {done} of {total} variants already finished, {total - done} to run")
        if self.quiet or not sys.stderr.isatty():
            return
        from rich.console import Console
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        columns = (
            TextColumn("variants"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[failed]} failed"),
            TimeRemainingColumn(),
        )
        self.bar = Progress(*columns, console=Console(stderr=True, highlight=False), transient=True)
        self.bar.start()
        self.task = self.bar.add_task("sweep", total=total, completed=done, failed=0)

    def incidents(self, cluster: Any) -> None:
        """A line for each worker the cluster lost while the sweep started or as it joined, not yet told."""
        if cluster is None:
            return
        for line in cluster.incidents[self.told :]:
            messages.status(f"Dask: {line}")
        self.told = len(cluster.incidents)

    def advance(self, rows: list[dict[str, Any]]) -> None:
        self.finished += len(rows)
        self.failed += sum(1 for r in rows if r.get("status") != "completed")
        if self.bar is not None:
            self.bar.update(self.task, completed=self.finished, failed=self.failed)

    def stop(self) -> None:
        if self.bar is not None:
            self.bar.stop()
            self.bar = None


@contextlib.contextmanager
def _terminate_as_interrupt() -> Iterator[list[int]]:
    """SIGTERM and SIGHUP stop the sweep as Ctrl-C does (finished batches kept), in the main thread;
    yields the list the signals that arrived are appended to (empty for Ctrl-C: Python's own handler)."""
    previous: dict[int, Any] = {}
    received: list[int] = []

    def interrupt(signum: int, frame: Any) -> None:
        received.append(int(signum))
        raise KeyboardInterrupt

    if threading.current_thread() is threading.main_thread():
        for name in ("SIGTERM", "SIGHUP"):
            if hasattr(signal, name):
                number = getattr(signal, name)
                previous[number] = signal.signal(number, interrupt)
    try:
        yield received
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
