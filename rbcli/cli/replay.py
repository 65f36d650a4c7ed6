"""`rbsim replay FILE`: open a recording in the Rerun viewer, serve it to a browser, or convert it."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Annotated

import typer

EXIT_INVALID = 1
WEB_PORT = 9090


def has_display() -> bool:
    """Whether a native viewer window can open: on Linux that needs DISPLAY or WAYLAND_DISPLAY."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def replay(
    file: Annotated[Path, typer.Argument(help="A recording: .rrd, or .mcap (the Rerun viewer reads both).")],
    web: Annotated[
        bool, typer.Option("--web", help=f"Serve a web viewer on http://127.0.0.1:{WEB_PORT} instead of a window.")
    ] = False,
    save: Annotated[Path | None, typer.Option("--save", help="Write the recording as an .rrd file and exit.")] = None,
) -> None:
    """Open FILE in the Rerun viewer shipped with rerun-sdk; --web serves it locally; --save converts."""
    from rich.console import Console
    from rich.markup import escape

    err = Console(stderr=True, highlight=False, soft_wrap=True)
    file_text = escape(str(file))
    suffix = file.suffix.lower()
    if not file.is_file():
        err.print(f"[red]error:[/] recording not found: {file_text}")
        raise typer.Exit(EXIT_INVALID)
    if suffix not in (".mcap", ".rrd"):
        err.print(f"[red]error:[/] {file_text}: not a recording (expected a .mcap or .rrd file)")
        raise typer.Exit(EXIT_INVALID)

    if save is not None:
        _save(file, save, err)
        return

    from rbcli.record.rerun_sink import open_viewer_command

    if web:
        err.print(
            f"serving {file} at http://127.0.0.1:{WEB_PORT} (bound to 127.0.0.1 only); Ctrl-C to stop",
            markup=False,
        )
        try:
            code = subprocess.call([*open_viewer_command(file, web=True), "--web-viewer-port", str(WEB_PORT)])
        except KeyboardInterrupt:
            code = 0
        if code:
            err.print(f"[red]error:[/] the Rerun web viewer exited with code {code}")
            raise typer.Exit(EXIT_INVALID)
        return

    if not has_display():
        err.print(
            "[red]error:[/] no display (DISPLAY and WAYLAND_DISPLAY are unset), so the Rerun viewer cannot "
            "open a window. Instead:\n"
            f"  rbsim replay {file_text} --web            serve a web viewer on http://127.0.0.1:{WEB_PORT}\n"
            f"  rbsim replay {file_text} --save out.rrd   write an .rrd to open where there is a display"
        )
        raise typer.Exit(EXIT_INVALID)
    process = subprocess.Popen(open_viewer_command(file), start_new_session=True)
    err.print(f"opened {file} in the Rerun viewer (pid {process.pid})", markup=False)


def _save(file: Path, save: Path, err) -> None:  # noqa: ANN001 - a rich Console
    """Convert (MCAP) or copy (RRD) to `save`, which must end in .rrd."""
    from rich.markup import escape

    if save.suffix.lower() != ".rrd":
        err.print(f"[red]error:[/] --save writes an .rrd file; got {escape(str(save))}")
        raise typer.Exit(EXIT_INVALID)
    if save.resolve() == file.resolve():
        err.print(f"[red]error:[/] --save {escape(str(save))} is the input file")
        raise typer.Exit(EXIT_INVALID)
    save.parent.mkdir(parents=True, exist_ok=True)
    if file.suffix.lower() == ".rrd":
        shutil.copyfile(file, save)
        err.print(f"{file} is already an .rrd; copied to {save}", markup=False)
        return
    from rbcli.record.convert import mcap_to_rrd

    try:
        frames = mcap_to_rrd(file, save)
    except Exception as exc:  # a corrupt or foreign file: say so, never a traceback
        err.print(f"[red]error:[/] cannot convert {escape(str(file))}: {escape(str(exc))}")
        raise typer.Exit(EXIT_INVALID) from None
    err.print(f"wrote {save}: {frames} frames from {file}", markup=False)
