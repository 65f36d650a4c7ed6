"""The `rbsim` command line: a Typer app that only parses arguments and delegates.

Each command lives in its own module (`rbcli/cli/<command>.py`) as a plain function with Typer
annotations; heavy libraries (numba, rerun, mcap) are imported inside those functions so that
`rbsim --help` stays instant.
"""

from __future__ import annotations

import atexit
import os
import sys
import threading

import typer

from rbcli._version import __version__
from rbcli.cli import info as _info
from rbcli.cli import integrators as _integrators
from rbcli.cli import recover as _recover
from rbcli.cli import replay as _replay
from rbcli.cli import run as _run
from rbcli.cli import schema as _schema
from rbcli.cli import study as _study
from rbcli.cli import sweep as _sweep
from rbcli.cli import validate as _validate

app = typer.Typer(
    name="rbsim",
    help="Rigid-body dynamics from YAML scenes, recorded to MCAP or Rerun.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version_callback(value: bool) -> None:
    if value:
        typer.echo(f"rbsim {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_version_callback, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """rbsim: rigid bodies as particle clouds; accurate integrators; every step recorded."""


app.command("run")(_run.run)
app.command("validate")(_validate.validate)
app.command("replay")(_replay.replay)
app.command("info")(_info.info)
app.command("recover")(_recover.recover)
app.command("integrators")(_integrators.integrators)
app.command("schema")(_schema.schema)
app.command("study")(_study.study)
app.command("sweep")(_sweep.sweep)


# Commands that end the process without the interpreter's teardown (`_exit_now`): after a run has
# loaded numba's kernels, freeing its LLVM modules and type tables at exit costs ~0.2 s (a quarter of a
# short run's whole process, docs/performance.md "Start-up"). A run leaves no file open: its output is
# closed and renamed (or left as it was) before the command returns, whatever the exit status.
EXIT_WITHOUT_TEARDOWN = frozenset({"run"})


def main() -> None:
    """Console-script entry point (also `python -m rbcli`)."""
    try:
        app()
    except SystemExit as exc:
        if sys.argv[1:2] and sys.argv[1] in EXIT_WITHOUT_TEARDOWN and (exc.code is None or isinstance(exc.code, int)):
            _exit_now(exc.code or 0)
        raise


def _exit_now(code: int) -> None:
    """Do what the interpreter's exit does that can be seen (wait for the non-daemon threads, run the
    atexit handlers, flush stdout and stderr), then end the process without tearing the interpreter
    down. Returns, leaving the ordinary exit to happen, when any of that cannot be done."""
    shutdown = getattr(threading, "_shutdown", None)  # CPython's join of the non-daemon threads at exit
    run_exitfuncs = getattr(atexit, "_run_exitfuncs", None)
    if shutdown is None or run_exitfuncs is None or threading.current_thread() is not threading.main_thread():
        return
    shutdown()
    run_exitfuncs()
    try:
        sys.stdout.flush()
        sys.stderr.flush()
    except (OSError, ValueError):  # a closed pipe or stream: let Python's own exit report it
        return
    os._exit(code)
