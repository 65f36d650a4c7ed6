"""The `rbsim` command line: a Typer app that only parses arguments and delegates.

Each command lives in its own module (`rbcli/cli/<command>.py`) as a plain function with Typer
annotations; heavy libraries (numba, rerun, mcap) are imported inside those functions so that
`rbsim --help` stays instant.
"""

from __future__ import annotations

import typer

from rbcli._version import __version__
from rbcli.cli import info as _info
from rbcli.cli import integrators as _integrators
from rbcli.cli import replay as _replay
from rbcli.cli import run as _run
from rbcli.cli import schema as _schema
from rbcli.cli import study as _study
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
app.command("integrators")(_integrators.integrators)
app.command("schema")(_schema.schema)
app.command("study")(_study.study)


def main() -> None:
    """Console-script entry point."""
    app()
