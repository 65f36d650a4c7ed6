"""`rbsim recover BROKEN.mcap -o FIXED.mcap`: rewrite the readable part of an MCAP file cut short (the
`x.partial.mcap` a killed or crashed run leaves: no summary, no index) as a complete file that every
reader opens (the mcap library's indexed reader, Foxglove, `rbcli.read_recording`, `rbsim info`).

Every chunk written before the cut is self-contained, so each is read back; the messages of the last
frame are kept only if all of them made it (a frame's state, transforms and invariants), so the file
ends at a complete frame. The file gets a summary section, an index and, when the run's own summary
record is missing, an `rbsim.summary` record with status "truncated" that says up to which step it holds.
The input is only read (never changed or removed); FIXED is written beside itself under a temporary name
and renamed when complete. Exit status: 0 written, 1 invalid input (as the other commands), 2 usage.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path
from typing import Annotated

import typer

from rbcli.cli import messages

COMPRESSIONS = ("zstd", "lz4", "none")


def recover(
    file: Annotated[
        Path,
        typer.Argument(metavar="FILE", help="An .mcap cut short, such as the x.partial.mcap a killed run leaves."),
    ],
    output: Annotated[
        Path,
        typer.Option(
            "--output",
            "-o",
            metavar="FIXED.mcap",
            help="The complete .mcap to write (a new name: FILE is never changed)",
        ),
    ],
    compression: Annotated[
        str, typer.Option("--compression", metavar="NAME", help="Chunk compression of the new file: zstd, lz4 or none")
    ] = "zstd",
) -> None:
    """Rewrite what FILE holds (every complete frame) as a complete MCAP with a summary and index."""
    from rbcli.record.mcap_recovery import recover_mcap
    from rbcli.record.output_file import being_written

    fail = messages.fail

    if not file.is_file():
        raise fail(f"recording not found: {file}" if not file.exists() else f"{file} is not a file")
    if file.suffix.lower() != ".mcap":
        raise fail(
            f"{file}: recover rewrites .mcap files; an .rrd cut short reads as it is (`rbsim info {file}`)"
            if file.suffix.lower() == ".rrd"
            else f"{file}: not an .mcap file"
        )
    if compression not in COMPRESSIONS:
        raise messages.fail_unknown("--compression", compression, COMPRESSIONS, "compression")
    target = Path(os.path.realpath(output))
    if output.is_dir() or str(output).endswith(os.sep):
        raise fail(f"output {str(output)!r} is a folder; give a file name such as {output}/fixed.mcap")
    if target.suffix.lower() != ".mcap":
        guess = messages.suffix_guess(output, (".mcap",))
        raise fail(f"output {str(output)!r}: recover writes an .mcap file{guess}", expected="a name ending in .mcap")
    if target == Path(os.path.realpath(file)) or (target.exists() and os.path.samefile(target, file)):
        raise fail(f"output {str(output)!r} is the input file; recover never overwrites its input: give another name")
    if being_written(file):
        raise fail(f"{file} is being written by a running rbsim run (it holds the file's lock); wait for it or stop it")
    if not target.parent.is_dir():
        raise fail(f"output {str(output)!r}: folder {str(target.parent)!r} does not exist")

    temporary = None
    try:
        fd, name = tempfile.mkstemp(prefix=f".{target.stem}.", suffix=".recover.mcap", dir=target.parent)
        temporary = Path(name)
        with os.fdopen(fd, "wb") as stream:
            prefix = recover_mcap(file, stream, compression=compression)
            stream.flush()
            os.fsync(stream.fileno())
        with contextlib.suppress(OSError):
            os.chmod(temporary, 0o666 & ~_umask())
        os.replace(temporary, target)
        temporary = None
    except ValueError as exc:  # not an MCAP file, or undecodable
        raise fail(f"cannot recover {file}: {exc}") from None
    except OSError as exc:
        raise fail(f"cannot write {output}: {exc.strerror or exc}") from None
    finally:
        if temporary is not None:
            with contextlib.suppress(OSError):
                temporary.unlink()

    if prefix.frames and prefix.last_step is not None and prefix.last_time is not None:
        held = f"{prefix.frames} frames up to step {prefix.last_step} (t = {prefix.last_time:.6g} s)"
    else:
        held = "no complete frame (the run parameters and scene only)"
    if prefix.complete:
        how = "the file was complete (nothing was cut)"
    else:
        how = f"{prefix.readable_bytes:,} of {prefix.size:,} bytes readable: {prefix.problem}"
    messages.status(f"recovered {held} from {file} ({how}) -> {output}")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
