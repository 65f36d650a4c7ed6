"""`rbsim sweep SWEEP.yaml`: run every variant of a sweep on Dask and gather one Parquet table.

Exit status: 0 when every variant has a row (variants that diverged or failed are rows too, with their
status and message), 1 for an invalid sweep file, an output folder that cannot take it or a scheduler
that cannot be reached, 130 when interrupted (the finished batches are kept: run the same command again
to resume).
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import typer

EXIT_INVALID = 1
EXIT_INTERRUPTED = 130


def sweep(
    file: Path = typer.Argument(..., help="Sweep file (YAML): a base scene and the axes to vary (docs/sweeps.md)."),
    scheduler: str | None = typer.Option(
        None, "--scheduler", help="Address of a running Dask scheduler (tcp://host:8786) (default: a local cluster)."
    ),
    workers: int | None = typer.Option(
        None, "--workers", "-w", min=1, help="Worker processes of the local cluster (default: one per CPU)."
    ),
    serial: bool = typer.Option(False, "--serial", help="Run the variants one by one in this process (no Dask)."),
    batch: int | None = typer.Option(
        None, "--batch", min=1, help="Variants per task (default: the file's batch, else about 0.5 s of work)."
    ),
    output: Path | None = typer.Option(None, "--output", "-o", help="Results folder (default: outputs/<name>)."),
    fresh: bool = typer.Option(False, "--fresh", help="Discard the folder's earlier results instead of resuming."),
    logs: bool | None = typer.Option(
        None, "--logs/--no-logs", help="Write each variant's recording to <folder>/logs (default: the file's)."
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
) -> None:
    """Run a sweep (a base scene over a grid, a list or random samples of its values); resumes by default."""
    from rich.console import Console
    from rich.markup import escape

    from rbcli.sweeps.load import analyse_sweep
    from rbcli.sweeps.run import SERIAL, SweepOutputError, run_sweep

    err = Console(stderr=True, highlight=False, soft_wrap=True)
    if not file.is_file():
        err.print(f"[red]error:[/] sweep file not found: {escape(str(file))}")
        raise typer.Exit(EXIT_INVALID)
    spec, issues = analyse_sweep(file)
    for issue in issues:
        err.print(str(issue), markup=False)
    if spec is None:
        raise typer.Exit(EXIT_INVALID)
    err.print(
        f"sweep {spec.name}: {spec.variant_count} variants of {spec.scene_path} "
        f"({len(spec.axes)} ax{'is' if len(spec.axes) == 1 else 'es'}, {spec.combine})",
        markup=False,
    )
    progress = _Progress(err, quiet)
    try:
        with _terminate_as_interrupt():
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
            )
    except SweepOutputError as exc:
        progress.stop()
        err.print(f"[red]error:[/] {escape(str(exc))}")
        raise typer.Exit(EXIT_INVALID) from None
    except (OSError, TimeoutError) as exc:  # no scheduler at that address, or no workers joined it
        progress.stop()
        where = f"the Dask scheduler at {scheduler}" if scheduler else "the local Dask cluster"
        err.print(f"[red]error:[/] cannot run on {escape(where)}: {escape(f'{type(exc).__name__}: {exc}')}")
        err.print("the variants finished so far are kept; run the same command again to resume", markup=False)
        raise typer.Exit(EXIT_INVALID) from None
    except KeyboardInterrupt:
        progress.stop()
        err.print(
            f"[yellow]interrupted[/]: {progress.finished} of {progress.total} variants finished and kept; "
            "run the same command again to resume"
        )
        raise typer.Exit(EXIT_INTERRUPTED) from None
    progress.stop()
    from rbcli.sweeps.report import failures, status_counts
    from rbcli.sweeps.table import RESULTS_FILE

    counts = status_counts(result.table)
    rate = f"{result.ran} variants in {result.wall_s:.2f} s" if result.ran else "nothing left to run"
    err.print(
        f"{result.variants} variants: " + ", ".join(f"{n} {s}" for s, n in counts.most_common()) + f" ({rate}) "
        f"-> {result.output / RESULTS_FILE if result.output else ''}",
        markup=False,
    )
    for line in failures(result.table, limit=5):
        err.print(f"  {line}", markup=False)


class _Progress:
    """The bar over variants (rich), started once the workers are ready; plain lines when not a terminal."""

    def __init__(self, err: Any, quiet: bool) -> None:
        self.err, self.quiet = err, quiet
        self.bar: Any = None
        self.task: Any = None
        self.total = 0
        self.finished = 0
        self.failed = 0

    def start(self, total: int, done: int, cluster: Any) -> None:
        self.total, self.finished = total, done
        if cluster is not None:
            dashboard = f"; dashboard: {cluster.dashboard}" if cluster.dashboard else ""
            self.err.print(
                f"Dask: {cluster.workers} worker{'s' * (cluster.workers != 1)} ({cluster.slots} slots) ready in "
                f"{cluster.startup_s:.1f} s, kernels warm in {cluster.warmup_s:.1f} s{dashboard}",
                markup=False,
            )
        if done:
            self.err.print(
                f"resuming: {done} of {total} variants already finished, {total - done} to run", markup=False
            )
        if self.quiet or not self.err.is_terminal:
            return
        from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

        columns = (
            TextColumn("variants"),
            BarColumn(),
            MofNCompleteColumn(),
            TextColumn("{task.fields[failed]} failed"),
            TimeRemainingColumn(),
        )
        self.bar = Progress(*columns, console=self.err, transient=True)
        self.bar.start()
        self.task = self.bar.add_task("sweep", total=total, completed=done, failed=0)

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
def _terminate_as_interrupt() -> Iterator[None]:
    """SIGTERM and SIGHUP stop the sweep as Ctrl-C does (finished batches kept), in the main thread."""
    previous: dict[int, Any] = {}

    def interrupt(signum: int, frame: Any) -> None:
        raise KeyboardInterrupt

    if threading.current_thread() is threading.main_thread():
        for name in ("SIGTERM", "SIGHUP"):
            if hasattr(signal, name):
                number = getattr(signal, name)
                previous[number] = signal.signal(number, interrupt)
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
