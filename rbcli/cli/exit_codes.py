"""The exit statuses of every `rbsim` command: one table, used by the commands, `rbsim --help` and README.md.

Conventions: 0 success; 1 the input was refused (a scene, a file, an option's value) or could not be read
or written, with an `error:` line on stderr saying why; 2 the command line itself is malformed (Click's
usage errors: an unknown option or command, a missing argument, a value of the wrong type); 3 the
simulation diverged (the log up to there is complete); 4 a sweep ended without a result of its own for
every variant (lost to the cluster, or taking its worker down on every try); 128 + N when signal N
stopped the command (the shell's convention, so `$?` reads the same as for a killed process).
"""

from __future__ import annotations

from enum import IntEnum


class ExitCode(IntEnum):
    """Exit statuses of `rbsim` (see the module docstring)."""

    OK = 0
    INVALID = 1
    USAGE = 2
    DIVERGED = 3
    INCOMPLETE = 4
    # 128 + the POSIX signal number, written out: signal.SIGHUP does not exist on Windows
    SIGHUP = 129  # 128 + 1: the terminal closed
    SIGINT = 130  # 128 + 2: Ctrl-C
    SIGTERM = 143  # 128 + 15: kill, a job scheduler's or a container's stop


MEANING: dict[ExitCode, str] = {
    ExitCode.OK: "success (warnings allowed)",
    ExitCode.INVALID: "invalid input: a scene, file or option value refused, or a file that cannot be read or written",
    ExitCode.USAGE: "usage: unknown option or command, missing argument, value of the wrong type",
    ExitCode.DIVERGED: "the simulation diverged (the log up to that step is complete)",
    ExitCode.INCOMPLETE: "a sweep left variants without a result (lost to the cluster, or crashing their worker); "
    "run it again to retry them",
    ExitCode.SIGHUP: "stopped by SIGHUP (terminal closed); what was finished is kept",
    ExitCode.SIGINT: "stopped by SIGINT (Ctrl-C); what was finished is kept",
    ExitCode.SIGTERM: "stopped by SIGTERM (kill, a scheduler); what was finished is kept",
}


def signal_exit(signum: int) -> int:
    """The exit status for a command stopped by signal `signum`: 128 + signum (130 SIGINT, 143 SIGTERM)."""
    return 128 + int(signum)


def exit_code_lines() -> list[str]:
    """The table as aligned text lines, `code  meaning`, for `--help`."""
    return [f"{int(code):>3}  {MEANING[code]}" for code in ExitCode]


def exit_code_markdown() -> str:
    """The table as Markdown, as README.md shows it (a test checks README.md holds exactly this)."""
    rows = ["| exit status | meaning |", "|---|---|"]
    rows += [f"| {int(code)} | {MEANING[code]} |" for code in ExitCode]
    return "\n".join(rows)
