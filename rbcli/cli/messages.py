"""Every error, warning and note `rbsim` prints, in one format, on stderr:

    path:line:col: error: what; expected what        (a located issue, as compilers and linters print)
    error: what; expected what                       (nothing to locate)

One message is one line, never wrapped (editors, CI annotators and `grep` parse `path:line:col`), plain
text when stderr is not a terminal and coloured only on a terminal (not with NO_COLOR or TERM=dumb;
FORCE_COLOR forces it). Text is written as it is: no markup language is interpreted, so nothing such as
`[red]` can ever appear, and brackets in paths and units print as typed. Status lines (a run's summary, "wrote
FILE") go through `status`, on stderr too, so stdout carries only what a command produces; a line that
rewrites itself as work goes on (`live_status`: numba compiling) only where `can_rewrite_status`. A list of
issues prints its first MAX_SHOWN_ISSUES and a note with the count of the rest.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Literal, Protocol, TextIO

from rbcli.cli.exit_codes import ExitCode

if TYPE_CHECKING:
    import typer

Severity = Literal["error", "warning", "note"]

# ANSI SGR codes, as gcc and clang colour their diagnostics: bold location, bold red/magenta/cyan labels
_BOLD, _RESET = "\x1b[1m", "\x1b[0m"
_ERASE_TO_END = "\x1b[K"  # ANSI EL: erase from the cursor to the end of the line
_LABEL_COLOUR = {"error": "\x1b[1;31m", "warning": "\x1b[1;35m", "note": "\x1b[1;36m"}
# a file with thousands of errors (a generated scene with one slip repeated) prints this many and a count:
# the first ones locate the slip, and a screen of the same message hides the verdict
MAX_SHOWN_ISSUES = 50


class _Located(Protocol):
    """What a located issue offers (scene and sweep issues: `rbcli.scene.spec.SceneIssue`)."""

    @property
    def location(self) -> object | None: ...
    @property
    def message(self) -> str: ...
    @property
    def expected(self) -> str: ...
    @property
    def severity(self) -> str: ...


def use_colour(stream: TextIO) -> bool:
    """Colour only on a terminal: never with NO_COLOR (no-color.org) or TERM=dumb; FORCE_COLOR forces it."""
    if os.environ.get("NO_COLOR"):
        return False
    if os.environ.get("FORCE_COLOR"):
        return True
    if os.environ.get("TERM") == "dumb":
        return False
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


def one_line(text: str) -> str:
    """`text` on one line: line breaks (a library's multi-line message) become "; "."""
    parts = [part.strip() for part in str(text).splitlines()]
    return "; ".join(part for part in parts if part)


def format_message(
    severity: Severity | str,
    what: str,
    *,
    expected: str = "",
    where: object | None = None,
    colour: bool = False,
) -> str:
    """`where: severity: what; expected expected` (each part only when given), on one line."""
    text = one_line(what)
    if expected:
        text += f"; expected {one_line(expected)}"
    label = f"{severity}:"
    if colour:
        label = f"{_LABEL_COLOUR.get(str(severity), _BOLD)}{label}{_RESET}"
    if where is None or str(where) == "":
        return f"{label} {text}"
    located = f"{where}:"
    return f"{_BOLD}{located}{_RESET} {label} {text}" if colour else f"{located} {label} {text}"


def emit(
    severity: Severity | str,
    what: str,
    *,
    expected: str = "",
    where: object | None = None,
    stream: TextIO | None = None,
) -> None:
    """Print one message on stderr (or `stream`) and flush: a message is never lost to a later crash."""
    out = stream if stream is not None else sys.stderr
    out.write(format_message(severity, what, expected=expected, where=where, colour=use_colour(out)) + "\n")
    out.flush()


def error(what: str, *, expected: str = "", where: object | None = None) -> None:
    emit("error", what, expected=expected, where=where)


def warning(what: str, *, expected: str = "", where: object | None = None) -> None:
    emit("warning", what, expected=expected, where=where)


def note(what: str, *, expected: str = "", where: object | None = None) -> None:
    emit("note", what, expected=expected, where=where)


def fail(what: str, *, expected: str = "", where: object | None = None, code: int = ExitCode.INVALID) -> typer.Exit:
    """Print the error and return the typer.Exit to raise: `raise fail("scene file not found: x")`."""
    import typer

    error(what, expected=expected, where=where)
    return typer.Exit(int(code))


def issue(found: _Located, file: object | None = None) -> None:
    """A scene's or sweep's issue (`SceneIssue`), located at its line and column, or at `file` when
    the issue has no location."""
    where = found.location if found.location is not None else file
    emit(found.severity, found.message, expected=found.expected, where=where)


def issues(found: Iterable[_Located], file: object | None = None) -> None:
    """The first MAX_SHOWN_ISSUES issues, in the order given (file order), then one note with how many
    more there are and how many errors and warnings in all."""
    found = list(found)
    for each in found[:MAX_SHOWN_ISSUES]:
        issue(each, file)
    rest = len(found) - MAX_SHOWN_ISSUES
    if rest > 0:
        errors = sum(each.severity == "error" for each in found)
        warnings = len(found) - errors
        counts = f"{errors:,} error{'s' * (errors != 1)}" + (
            f" and {warnings:,} warning{'s' * (warnings != 1)}" if warnings else ""
        )
        emit("note", f"{rest:,} more issue{'s' * (rest != 1)} not shown ({counts} in all)", where=file)


def status(text: str) -> None:
    """A line that is not a diagnostic (a run's summary, "wrote FILE"): stderr, one line, never wrapped."""
    sys.stderr.write(one_line(text) + "\n")
    sys.stderr.flush()


def can_rewrite_status() -> bool:
    """Whether stderr shows `live_status` lines: a terminal that erases a line (not TERM=dumb); elsewhere
    (a pipe, a log file, CI) a line written is there for good, so say things once with `status`."""
    isatty = getattr(sys.stderr, "isatty", None)
    return bool(isatty and isatty()) and os.environ.get("TERM") != "dumb"


def live_status(text: str) -> None:
    """A status line on a terminal that the next live_status, or end_live_status, replaces in place: cut
    to the terminal's width (a wrapped line would leave its first rows behind on every rewrite)."""
    import shutil

    width = shutil.get_terminal_size().columns
    sys.stderr.write("\r" + one_line(text)[: max(1, width - 1)] + _ERASE_TO_END)
    sys.stderr.flush()


def end_live_status() -> None:
    """Erase the live_status line, leaving the cursor at its start for the next line."""
    sys.stderr.write("\r" + _ERASE_TO_END)
    sys.stderr.flush()


def did_you_mean(word: str, choices: Iterable[str]) -> str | None:
    """The closest of `choices` to `word` when it is a likely typo (the scene keys' own rule)."""
    from rbcli.scene.issues import did_you_mean as closest

    return closest(word, choices)


def suffix_guess(path: Path, suffixes: Sequence[str]) -> str:
    """ " (did you mean x.mcap?)" when the file name's extension is a likely typo of one of `suffixes`."""
    suffix = path.suffix.lower()
    hint = did_you_mean(suffix, suffixes) if suffix else None
    return f" (did you mean {path.with_suffix(hint)}?)" if hint else ""


def fail_unknown(option: str, value: str, choices: Sequence[str], kind: str) -> typer.Exit:
    """Print the error for a value outside a closed set, with a "did you mean" when one is close, and
    return the typer.Exit (status 1) to raise: `--integrator 'rk5': unknown integrator (did you mean
    'rk4'?); expected one of euler-matrix, ...`."""
    hint = did_you_mean(value, choices)
    guess = f" (did you mean {hint!r}?)" if hint else ""
    return fail(f"{option} {value!r}: unknown {kind}{guess}", expected="one of " + ", ".join(choices))
