"""Where a run's file is written, and how: checked before any work, written under a partial name, renamed
into place when the run ends.

A run to `x.mcap` writes `x.partial.mcap` beside it (`x.partial.rrd` for `x.rrd`: the partial keeps the
real suffix, so `rbsim info` and the readers take it as it is, and rerun's file sink writes it as any
.rrd) and renames it onto `x.mcap` with `os.replace` (atomic within a directory) when the run ends:
completed, interrupted, or diverged (the log then holds every step up to the stop). A failed run
never touches `x.mcap`: an error before the first frame is written removes the partial; a later error
leaves it, readable up to the error (the sinks always close their files). After SIGKILL, a crash or a
power cut the partial stays under its name: a later run to the same target refuses to overwrite a
non-empty partial that no run holds, so that what it holds can be read (or the file deleted) first.

Two runs writing the same target never interleave: a run holds an exclusive `flock` on its partial
for as long as it writes it, and a second run gets `OutputError` at once. The kernel drops the lock
when the process dies, so a killed run leaves no stale lock behind (only its partial file).
"""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # types only: record/ does not import scene/ at run time
    from rbcli.scene.compile import CompiledScene

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: no flock; the partial is then opened with O_EXCL
    fcntl = None  # type: ignore[assignment]

PARTIAL_INFIX = ".partial"
DEFAULT_OUTPUT_DIR = Path("outputs")
DEFAULT_OUTPUT_SUFFIX = ".rrd"
FILE_STEM_MAX = 120  # bytes of a generated file name before the suffix (file systems allow 255)

# Bytes per recorded frame, from runs of randomly tumbling bodies (the least compressible case: a
# body at rest or in free flight compresses much better), rounded up by ~15-30% so the check errs
# towards needing more disk. Measured with 1, 10 and 100 bodies of 5 particles, 500 frames:
#   MCAP per body-frame: zstd 142, lz4 166, none 244 (rbsim.State 152 B raw + a /tf record ~90 B);
#   per particle-frame with the particles stream: 24-29 B; per frame (invariants, message records)
#   60-290 B; fixed: ~10-50 kB (schemas, attachment, static clouds).
#   RRD (float32 transforms): per body-frame 69-73 B; per particle-frame 12 B; per frame up to 425 B
#   with invariants; fixed ~110 kB plus the trajectory strips written at close (at most 4096 float32
#   points per body).
MCAP_BODY_FRAME_BYTES = {"zstd": 170, "lz4": 200, "none": 280}
MCAP_PARTICLE_FRAME_BYTES = 32
MCAP_FRAME_BYTES = 400
MCAP_FIXED_BYTES = 64 * 1024
MCAP_BODY_FIXED_BYTES = 1024
RRD_BODY_FRAME_BYTES = 85
RRD_PARTICLE_FRAME_BYTES = 16
RRD_FRAME_BYTES = 500
RRD_FIXED_BYTES = 256 * 1024
RRD_BODY_FIXED_BYTES = 4096 * 12 + 2048  # the trajectory strip (rerun_sink's trajectory_points) and clouds


class OutputError(ValueError):
    """The output path cannot be written (a one-line message that says why and what to do)."""


def safe_file_stem(name: str) -> str:
    """A scene name as one file name: letters (any script), digits, '.', '_' and '-' kept, other runs
    -> '_', no leading dots, underscores or dashes (so no '..', no hidden file, no option), at most
    FILE_STEM_MAX bytes, 'scene' if empty."""
    stem = re.sub(r"[^\w.-]+", "_", name).lstrip("._-")
    stem = stem.encode()[:FILE_STEM_MAX].decode(errors="ignore").rstrip(".")
    return stem or "scene"


def default_output_path(scene_name: str, directory: Path = DEFAULT_OUTPUT_DIR) -> Path:
    """`outputs/<scene name>.rrd`, the name made safe: it always stays inside `directory`."""
    return directory / f"{safe_file_stem(scene_name)}{DEFAULT_OUTPUT_SUFFIX}"


def partial_path(target: str | Path) -> Path:
    """The name a run writes before it ends: `x.mcap` -> `x.partial.mcap` (same folder, same suffix)."""
    target = Path(target)
    return target.with_name(f"{target.stem}{PARTIAL_INFIX}{target.suffix}")


def expected_output_bytes(
    fmt: str,
    *,
    body_count: int,
    particle_count: int,
    frames: int,
    streams: Sequence[str] = ("bodies", "invariants"),
    compression: str = "zstd",
    scene_bytes: int = 0,
) -> int:
    """A generous estimate of the file size [bytes] of a run ('mcap' or 'rerun'), see the constants."""
    particles = particle_count if "particles" in streams else 0
    if fmt == "mcap":
        body = MCAP_BODY_FRAME_BYTES.get(compression, MCAP_BODY_FRAME_BYTES["none"])
        per_frame = body * body_count + MCAP_PARTICLE_FRAME_BYTES * particles + MCAP_FRAME_BYTES
        fixed = MCAP_FIXED_BYTES + MCAP_BODY_FIXED_BYTES * body_count + 32 * particle_count
    else:
        per_frame = RRD_BODY_FRAME_BYTES * body_count + RRD_PARTICLE_FRAME_BYTES * particles + RRD_FRAME_BYTES
        fixed = RRD_FIXED_BYTES + RRD_BODY_FIXED_BYTES * body_count + 16 * particle_count
    return int(per_frame * max(frames, 1) + fixed + scene_bytes)


def expected_run_bytes(compiled: CompiledScene, target: str | Path) -> int:
    """expected_output_bytes for a compiled scene written to `target` (.mcap, else .rrd)."""
    settings, bodies = compiled.settings, compiled.spec.bodies
    return expected_output_bytes(
        "mcap" if Path(target).suffix.lower() == ".mcap" else "rerun",
        body_count=len(bodies),
        particle_count=sum(len(b.particle_mass) for b in bodies),
        frames=settings.steps // settings.record_every + 2,  # frame 0 and the final state, at most
        streams=settings.streams,
        compression=settings.compression,
        scene_bytes=len(compiled.spec.source_text.encode()),
    )


def _megabytes(n: float) -> str:
    return f"{n / 1e6:,.1f} MB" if n < 1e12 else f"{n / 1e12:,.3g} TB"


def _existing_ancestor(path: Path) -> Path:
    """The nearest folder above `path` that exists (the one the missing folders would be made in)."""
    for parent in path.parents:
        if parent.exists():
            return parent
    return Path(".")  # pragma: no cover - a relative path's parents end in "."


def check_output(target: str | Path, *, expected_bytes: int = 0) -> None:
    """Raise OutputError unless a run can write `target`: not a folder or a special file, a known
    format (.mcap or .rrd), a folder (or the nearest existing folder above it) that accepts a new
    file, no other run writing it, no leftover partial, and at least `expected_bytes` free. Writes
    nothing that stays."""
    from rbcli.record.sinks import output_format

    shown = str(target)
    path = Path(os.path.realpath(target))  # a symbolic link: the file it names is the one replaced
    if path.is_dir() or str(target).endswith(os.sep):
        raise OutputError(f"output {shown!r} is a folder; give a file name such as {shown.rstrip(os.sep)}/run.mcap")
    if path.exists() and not path.is_file():
        raise OutputError(f"output {shown!r} exists and is not a regular file (a device, pipe or socket)")
    try:
        output_format(path)
    except ValueError as exc:
        raise OutputError(str(exc).replace(repr(str(path)), repr(shown))) from None
    folder = _existing_ancestor(path)
    if not folder.is_dir():
        raise OutputError(f"output {shown!r}: {str(folder)!r} is a file, not a folder")
    try:  # the only sure test (permissions, read-only mounts, /proc, root): make a file, then remove it
        fd, probe = tempfile.mkstemp(prefix=".rbsim-probe-", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise OutputError(f"output {shown!r}: cannot create files in {str(folder)!r} ({exc.strerror})") from None
    _check_partial(path, shown)
    if expected_bytes > 0:
        free = shutil.disk_usage(folder).free
        if free < expected_bytes:
            raise OutputError(
                f"output {shown!r}: not enough free disk: the run needs about {_megabytes(expected_bytes)} "
                f"(estimated), {str(folder)!r} has {_megabytes(free)} free; record less often (--record-every), "
                "run shorter or write elsewhere"
            )


def _check_partial(path: Path, shown: str) -> None:
    """OutputError if another run is writing `path` or a killed run left a non-empty partial of it."""
    partial = partial_path(path)
    try:
        fd = os.open(partial, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        return
    except OSError:
        return  # unreadable: OutputFile.open says what is wrong when it opens it for writing
    try:
        _lock(fd, partial, shown)
        if os.fstat(fd).st_size > 0:
            raise OutputError(_leftover_message(partial, shown))
    finally:
        os.close(fd)  # drops the lock


def being_written(path: str | Path) -> bool:
    """True when a running rbsim run holds the lock on `path` (a partial file it is still writing)."""
    if fcntl is None:  # pragma: no cover
        return False
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_CLOEXEC", 0))
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # drops a lock taken here
    return False


def _leftover_message(partial: Path, shown: str) -> str:
    return (
        f"output {shown!r}: {str(partial)!r} is left from an earlier run that did not finish (killed or "
        "crashed) and holds its log up to then; move or delete it, then run again"
    )


def _lock(fd: int, partial: Path, shown: str) -> None:
    """An exclusive, non-blocking flock on the open partial, or OutputError: another run holds it."""
    if fcntl is None:  # pragma: no cover
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        raise OutputError(
            f"output {shown!r}: another rbsim run is writing it ({str(partial)!r} is locked); "
            "wait for that run or choose another output"
        ) from None


class OutputFile:
    """The file of one run: `open()` checks the target, makes missing folders and takes the partial
    (locked); the sink writes `partial`; `commit()` renames it onto the target; `abandon(keep)` leaves
    the target alone and removes the partial unless `keep` (a run that failed after writing frames
    keeps them there: its sink closed the file, readable up to the error).
    """

    def __init__(self, target: str | Path, *, expected_bytes: int = 0) -> None:
        self.shown = str(target)
        self.target = Path(os.path.realpath(target))
        self.partial = partial_path(self.target)
        self.expected_bytes = expected_bytes
        self._fd: int | None = None

    def open(self) -> Path:
        """Check, create the folders, create and lock the partial (emptied); returns its path."""
        check_output(self.shown, expected_bytes=self.expected_bytes)
        try:
            self.target.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise OutputError(f"output {self.shown!r}: cannot create its folder ({exc.strerror})") from None
        while self._fd is None:
            self._fd = self._open_partial()
        return self.partial

    def _open_partial(self) -> int | None:
        """The locked partial's descriptor, or None when it was renamed before the lock (try again)."""
        flags = os.O_RDWR | os.O_CREAT | getattr(os, "O_CLOEXEC", 0) | (os.O_EXCL if fcntl is None else 0)
        try:
            fd = os.open(self.partial, flags, 0o666)
        except FileExistsError:  # pragma: no cover - O_EXCL without flock
            raise OutputError(_leftover_message(self.partial, self.shown)) from None
        except OSError as exc:
            raise OutputError(f"output {self.shown!r}: cannot create {str(self.partial)!r} ({exc.strerror})") from None
        try:
            _lock(fd, self.partial, self.shown)
            # between open and flock the run that held it may have renamed it onto the target: lock
            # only the file that still has the partial name
            with contextlib.suppress(FileNotFoundError):
                if os.path.samestat(os.fstat(fd), os.stat(self.partial)):
                    if os.fstat(fd).st_size > 0:  # a leftover that appeared after check_output
                        raise OutputError(_leftover_message(self.partial, self.shown))
                    _copy_mode(self.target, fd)
                    return fd
        except BaseException:
            os.close(fd)
            raise
        os.close(fd)
        return None

    def commit(self) -> None:
        """Make the partial the target: flushed to disk, then renamed over it in one step."""
        assert self._fd is not None, "commit() before open()"
        try:
            try:
                os.fsync(self._fd)  # the data before the name: after a power cut the target is old or new
            except OSError as exc:  # a full disk can surface only here (delayed allocation)
                raise OutputError(
                    f"output {self.shown!r}: cannot write {str(self.partial)!r} to disk ({exc.strerror}); "
                    "it may be incomplete and the output is unchanged"
                ) from None
            try:
                os.replace(self.partial, self.target)
            except OSError as exc:
                raise OutputError(
                    f"output {self.shown!r}: cannot rename {str(self.partial)!r} onto it ({exc.strerror}); "
                    "the complete log stays in the partial file"
                ) from None
            _fsync_folder(self.target.parent)
        finally:
            self._release()

    def abandon(self, *, keep: bool) -> None:
        """Leave the target as it was; remove the partial unless `keep`."""
        try:
            if not keep:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(self.partial)
        finally:
            self._release()

    def _release(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None


def _copy_mode(target: Path, fd: int) -> None:
    """Give the new file the permission bits of the file it will replace (a rename would drop them)."""
    try:
        os.fchmod(fd, stat.S_IMODE(os.stat(target).st_mode))
    except (OSError, AttributeError):  # no target yet (the umask applies), or no fchmod (Windows)
        pass


def _fsync_folder(folder: Path) -> None:
    """Make a rename durable (POSIX); a no-op where folders cannot be opened."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
