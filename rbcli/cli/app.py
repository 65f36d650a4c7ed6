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
import warnings
from typing import TextIO

import typer

from rbcli._version import __version__
from rbcli.cli import coercion, messages
from rbcli.cli import info as _info
from rbcli.cli import integrators as _integrators
from rbcli.cli import recover as _recover
from rbcli.cli import replay as _replay
from rbcli.cli import run as _run
from rbcli.cli import schema as _schema
from rbcli.cli import study as _study
from rbcli.cli import sweep as _sweep
from rbcli.cli import validate as _validate
from rbcli.cli import warm as _warm
from rbcli.cli.exit_codes import ExitCode, exit_code_lines

coercion.install()  # plain parameters' values converted without pydantic (cli/coercion.py)

PROG_NAME = "rbsim"  # also under `python -m rbcli`: usage lines, completion (_RBSIM_COMPLETE) say rbsim

# Help is plain text (no Rich markup mode): what a help string says is what prints, brackets included
# ("[s]", "[default: ...]"), and flags show no value placeholder.
app = typer.Typer(
    name=PROG_NAME,
    help="Rigid-body dynamics from YAML scenes, recorded to MCAP or Rerun.",
    epilog="\b\nExit status:\n" + "\n".join(exit_code_lines()),
    add_completion=True,
    rich_markup_mode=None,
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


# the one-line summaries `rbsim --help` lists (a command's docstring is its own --help)
app.command("run", short_help="Integrate a scene and record every step to .mcap or .rrd")(_run.run)
app.command("validate", short_help="Check scene and sweep files; simulate nothing")(_validate.validate)
app.command("replay", short_help="Open a recording in the Rerun viewer, serve it (--web) or convert it")(_replay.replay)
app.command("info", short_help="Summarise a recording or a sweep's results (--json for scripts)")(_info.info)
app.command("recover", short_help="Rewrite an .mcap cut short as a complete file")(_recover.recover)
app.command("integrators", short_help="List the integrators (--measure: time them here)")(_integrators.integrators)
app.command("schema", short_help="Print the scene JSON Schema (for editors)")(_schema.schema)
app.command("study", short_help="Work-precision study of the integrators on a scene")(_study.study)
app.command("sweep", short_help="Run every variant of a sweep on Dask into one Parquet table")(_sweep.sweep)
app.command("warm", short_help="Compile the kernels of each kind of scene (or SCENEs) ahead of runs")(_warm.warm)


# Commands that end the process without the interpreter's teardown (`_exit_now`): after a run has
# loaded numba's kernels, freeing its LLVM modules and type tables at exit costs ~0.2 s (a quarter of a
# short run's whole process, docs/performance.md "Start-up"). A run leaves no file open: its output is
# closed and renamed (or left as it was) before the command returns, whatever the exit status.
EXIT_WITHOUT_TEARDOWN = frozenset({"run"})


def main() -> None:
    """Console-script entry point (also `python -m rbcli`): no arguments prints the help (exit 0)."""
    warnings.showwarning = show_warning
    code = run_app(sys.argv[1:] or ["--help"])
    if sys.argv[1:2] and sys.argv[1] in EXIT_WITHOUT_TEARDOWN:
        _exit_now(code)
    sys.exit(code)


def show_warning(  # warnings.showwarning's signature
    message: Warning | str,
    category: type[Warning],
    filename: str,
    lineno: int,
    file: TextIO | None = None,
    line: str | None = None,
) -> None:
    """A Python warning (from rbsim or a library) as one `warning:` line of the shared format, its source
    line in parentheses at the end (the location slot is for the user's files)."""
    messages.warning(f"{message} ({category.__name__}, {os.path.basename(filename)}:{lineno})")


def run_app(args: list[str]) -> int:
    """Run the command line `args` and return its exit status (exit_codes.ExitCode). Click's own errors
    (an unknown option, a missing argument, a value of the wrong type) are printed by the shared
    formatter, as one line with the usage expected, exit 2."""
    try:
        result = app(args=args, prog_name=PROG_NAME, standalone_mode=False)
    except typer.TyperException as exc:  # Click's usage errors (exit 2) and its other errors (exit 1)
        context = getattr(exc, "ctx", None)
        usage = context.get_usage().removeprefix("Usage: ") if context is not None else ""
        more = f" (`{context.command_path} --help`)" if context is not None else ""
        messages.error(exc.format_message().rstrip("."), expected=f"{usage}{more}" if usage else "")
        return int(getattr(exc, "exit_code", ExitCode.USAGE))
    except typer.Abort:  # Click turns an end of input in a prompt into Abort; rbsim has no prompts
        messages.error("aborted")
        return int(ExitCode.INVALID)
    except SystemExit as exc:  # a command that calls sys.exit itself
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else int(ExitCode.INVALID))
    # standalone_mode=False: a typer.Exit gives its code; a command that ends normally gives None
    return result if isinstance(result, int) else int(ExitCode.OK)


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
