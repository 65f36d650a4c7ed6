"""`rbsim info FILE`: what a recording holds and how well the run kept its invariants."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

EXIT_INVALID = 1


def info(
    file: Annotated[Path, typer.Argument(help="A recording (.mcap or .rrd) or a sweep's results (.parquet).")],
) -> None:
    """Print scene, bodies, steps, duration, integrator, dt, status and each invariant's drift (a sweep's
    table: its axes, how many variants finished and how, metric ranges and the failed variants)."""
    from rich.console import Console
    from rich.markup import escape

    from rbcli.record.read import recording_format, summarize

    err = Console(stderr=True, highlight=False, soft_wrap=True)
    if not file.is_file():
        err.print(f"[red]error:[/] recording not found: {escape(str(file))}")
        raise typer.Exit(EXIT_INVALID)
    if file.suffix.lower() == ".parquet":
        _sweep_info(file, err)
        return
    try:
        recording_format(file)
        summary = summarize(file)
    except Exception as exc:  # a corrupt or foreign file: say so, never a traceback
        err.print(f"[red]error:[/] cannot read {escape(str(file))}: {escape(str(exc))}")
        raise typer.Exit(EXIT_INVALID) from None
    typer.echo(str(summary))


def _sweep_info(file: Path, err) -> None:  # noqa: ANN001 - a rich Console
    from rich.markup import escape

    from rbcli.sweeps.report import describe, read_results

    try:
        text = describe(read_results(file), file)
    except Exception as exc:  # a corrupt or foreign file: say so, never a traceback
        err.print(f"[red]error:[/] cannot read {escape(str(file))} as a sweep's results: {escape(str(exc))}")
        raise typer.Exit(EXIT_INVALID) from None
    typer.echo(text)
