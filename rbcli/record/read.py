"""Read rbsim recordings back (.mcap or .rrd) for `rbsim info`, `rbsim replay`, `rbcli.read_recording`
and the tests.

The file formats are owned beside their sinks: the MCAP readers live in `record/mcap_read.py` (a file cut
short: `record/mcap_recovery.py`) and the RRD reader in `record/rerun_sink.py` (each third-party library is
imported only by its owners, docs/architecture.md). This module imports them lazily and turns what they
find into one shape, `RecordedRun`, into the public `Trajectory` (`read_trajectory`, which is
`rbcli.read_recording`), and into the summary `rbsim info` prints, `RunInfo`.
"""

from __future__ import annotations

import errno
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rbcli.record.frame import RECORDING_FORMAT_VERSION, RunSummary
from rbcli.record.memory_sink import Trajectory, header_from_parameters

# |f(0)| below this (SI units) makes a relative drift meaningless: the value is zero up to rounding,
# as for a momentum component that starts at zero.
RELATIVE_DRIFT_FLOOR = 1e-12


@dataclass
class RecordedRun:
    """A recording read back. Arrays are per recorded step, bodies in `body_names` order.

    t: (T,) [s]; step: (T,); x: (T, N, 3) centre of mass [m]; q: (T, N, 4) (w, x, y, z);
    v, omega, P, L: (T, N, 3) [m/s, rad/s, kg m/s, kg m^2/s], exact float64 from MCAP; None from an .rrd,
    which holds transforms only (as float32). invariants: name -> (T,).
    """

    path: Path
    format: str  # "mcap" or "rrd"
    metadata: dict[str, str]  # run parameters, as written by the sink
    summary: dict[str, str]  # how the run ended: status, steps, frames, t_end, message
    scene_text: str
    body_names: tuple[str, ...]
    t: np.ndarray
    step: np.ndarray
    x: np.ndarray
    q: np.ndarray
    v: np.ndarray | None = None
    omega: np.ndarray | None = None
    P: np.ndarray | None = None
    L: np.ndarray | None = None
    invariants: dict[str, np.ndarray] = field(default_factory=dict)
    particle_offset: tuple[np.ndarray, ...] = ()  # per body (n_i, 3) [m], body frame
    message_counts: dict[str, int] = field(default_factory=dict)  # MCAP topic -> messages
    entity_paths: tuple[str, ...] = ()  # RRD entities
    # MCAP with the joint_forces stream: (T, J, 12) reactions (FrameBlock.joint_force) and the joints' names
    joint_force: np.ndarray | None = None
    joint_names: tuple[str, ...] = ()

    @property
    def frames(self) -> int:
        return int(self.t.shape[0])


def recording_format(path: str | Path) -> str:
    """'mcap' or 'rrd' from the file extension; ValueError otherwise."""
    suffix = Path(path).suffix.lower()
    if suffix not in (".mcap", ".rrd"):
        raise ValueError(f"{str(path)!r}: not a recording (expected a .mcap or .rrd file)")
    return suffix[1:]


class RecordingTooNew(ValueError):
    """A recording in a newer format than this rbsim reads (its `format_version` is above ours)."""


def check_format_version(path: str | Path, meta: dict[str, str]) -> None:
    """RecordingTooNew when the run parameters `meta` say the file is in a newer recording format; a file
    without `format_version` (older than the key, or not rbsim's) is left to the other checks."""
    text = meta.get("format_version")
    if text is None:
        return
    try:
        version = int(text)
    except ValueError:
        raise RecordingTooNew(f"{str(path)!r}: unknown recording format version {text!r}") from None
    if version > RECORDING_FORMAT_VERSION:
        writer = meta.get("rbsim_version", "?")
        raise RecordingTooNew(
            f"{str(path)!r} is in recording format version {version} (written by rbsim {writer}), newer than "
            f"this rbsim understands (it reads up to version {RECORDING_FORMAT_VERSION}): upgrade rbsim"
        )


def refuse_newer_recording(path: str | Path) -> None:
    """RecordingTooNew when a recording's run parameters say it is in a newer format (what `rbsim replay`
    checks before handing the file to the viewer); a file whose parameters cannot be read passes here."""
    try:
        if recording_format(path) == "mcap":
            from rbcli.record.mcap_layout import METADATA_RUN
            from rbcli.record.mcap_read import read_mcap_contents

            meta = read_mcap_contents(path).metadata.get(METADATA_RUN, {})
        else:
            from rbcli.record.rerun_sink import read_rrd_properties

            meta = read_rrd_properties(path).get("rbsim", {})
    except Exception:  # noqa: BLE001 - damaged or foreign: the viewer (or the converter) says what it finds
        return
    check_format_version(path, meta)


def _json_list(value: str | None) -> list:
    return json.loads(value) if value else []


def read_mcap(path: str | Path) -> RecordedRun:
    """Everything an rbsim MCAP file holds, decoded with the schemas embedded in the file."""
    from rbcli.record.mcap_layout import METADATA_RUN, METADATA_SUMMARY
    from rbcli.record.mcap_read import iter_mcap_blocks, read_mcap_contents

    contents = read_mcap_contents(path)
    meta = contents.metadata.get(METADATA_RUN, {})
    check_format_version(path, meta)
    names = tuple(_json_list(meta.get("body_names")))
    blocks = list(iter_mcap_blocks(path))

    def cat(attr: str, width: int) -> np.ndarray:
        if not blocks:
            return np.zeros((0, len(names), width))
        return np.concatenate([getattr(b, attr) for b in blocks], axis=0)

    inv_names = contents.invariant_names
    joints = blocks[0].joint_force is not None if blocks else False
    joint_names = tuple(_json_list(meta.get("joint_names")))
    return RecordedRun(
        path=Path(path),
        format="mcap",
        metadata=meta,
        summary=contents.metadata.get(METADATA_SUMMARY, {}),
        scene_text=contents.scene_text,
        body_names=names,
        t=np.concatenate([b.t for b in blocks]) if blocks else np.zeros(0),
        step=np.concatenate([b.step for b in blocks]) if blocks else np.zeros(0, dtype=np.int64),
        x=cat("x", 3),
        q=cat("q", 4),
        v=cat("v", 3),
        omega=cat("omega", 3),
        P=cat("P", 3),
        L=cat("L", 3),
        invariants={n: np.concatenate([b.invariants[n] for b in blocks]) if blocks else np.zeros(0) for n in inv_names},
        particle_offset=tuple(contents.particle_offset.get(n, np.zeros((0, 3))) for n in names),
        message_counts=contents.message_counts,
        joint_force=np.concatenate([b.joint_force for b in blocks]) if joints else None,
        joint_names=joint_names if joints else (),
    )


def read_rrd(path: str | Path, *, bodies: bool = True) -> RecordedRun:
    """An rbsim .rrd read with rerun's own reader: transforms per body (float32 -> float64), invariants.

    Either layout of `record.rerun_sink` (an entity per body, or all bodies in one). bodies=False skips
    the body transforms (x and q come back with no bodies).
    """
    from rbcli.record.rerun_sink import body_entity, read_rrd_file

    contents = read_rrd_file(path, bodies=bodies)
    meta = contents.properties.get("rbsim", {})
    check_format_version(path, meta)
    names = tuple(_json_list(meta.get("body_names")))
    entities = ["/" + body_entity(n) for n in names]
    recorded = [e for e in entities if e in contents.body_translation]
    offsets = tuple(contents.particle_offset.get(e, np.zeros((0, 3))) for e in entities)
    if contents.bodies_particle_offset is not None:
        offsets = contents.bodies_particle_offset
    if bodies and contents.bodies is not None:
        # the one-entity layout: every body in each row, in header order
        t, step, x, q = (
            contents.bodies.time,
            contents.bodies.step,
            contents.bodies.translation,
            contents.bodies.quaternion,
        )
        if x.shape[1] != len(names):
            raise ValueError(f"{path}: {x.shape[1]} bodies per row in the one-entity layout, {len(names)} named")
    elif bodies and recorded:
        steps = [contents.body_step[e] for e in recorded]
        if len(recorded) < len(entities) or any(not np.array_equal(s, steps[0]) for s in steps):
            missing = sorted(set(entities) - set(recorded))
            raise ValueError(f"{path}: bodies without transforms {missing} or with differing steps")
        x = np.stack([contents.body_translation[e] for e in entities], axis=1)
        q = np.stack([contents.body_quaternion[e] for e in entities], axis=1)
        t, step = contents.body_time[entities[0]], steps[0]
    else:
        # no body transforms read (bodies=False, or no frame recorded): times from the invariants
        first = next(iter(contents.invariant_time), None)
        t = contents.invariant_time[first] if first else np.zeros(0)
        step = np.zeros(0, dtype=np.int64)
        width = len(names) if bodies else 0
        x, q = np.zeros((len(t), width, 3)), np.zeros((len(t), width, 4))
    return RecordedRun(
        path=Path(path),
        format="rrd",
        metadata=meta,
        summary=contents.properties.get("rbsim.summary", {}),
        scene_text=contents.scene_text,
        body_names=names,
        t=t,
        step=step,
        x=x,
        q=q,
        invariants=contents.invariants,
        particle_offset=offsets,
        entity_paths=tuple(contents.entity_paths),
    )


def read_recording(path: str | Path) -> RecordedRun:
    """read_mcap or read_rrd by extension (the internal shape; the public API returns a Trajectory:
    `read_trajectory`)."""
    return read_mcap(path) if recording_format(path) == "mcap" else read_rrd(path)


# --- the public reader: a recording as the Trajectory `rbcli.simulate` returns ------------------------

# what a Trajectory holds that an .rrd does not (it stores transforms only)
_DYNAMICS = ("v", "omega", "P", "L")


def read_trajectory(path: str | Path) -> Trajectory:
    """A recording written by `rbsim run` / `rbcli.run_to_file` (.mcap or .rrd) as a `Trajectory`: the
    object `rbcli.simulate` returns, so the same code reads either. Public as `rbcli.read_recording`.

    Both formats hold, per recorded frame (every `record_every`-th step): the time t [s], the step index,
    each body's centre of mass x [m] and orientation q (w, x, y, z; world-from-body, in the scene's body
    frame), the invariants (energies [J], momentum components and norms; float64), and once: the run
    parameters (`header`: scene text, body names and masses, particle offsets, integrator, dt, ...) and
    how the run ended (`summary`, `status`).

    - .mcap: every array exactly as simulated (float64), including v [m/s], omega [rad/s] (world),
      P [kg m/s] and L [kg m^2/s] (world).
    - .rrd: x and q are stored as float32 (each value the float64 one rounded to nearest: relative
      error <= 2^-24, about 6e-8), and t as whole nanoseconds (|error| <= 0.5 ns). Velocities and
      momenta are not stored: v, omega, P and L come back NaN-filled and are named in `not_recorded`.
      Particle offsets in `header` are float32 too, except in the one-entity layout (> 10,000 bodies).

    Neither gives back `particle_position` (None; world particles are x + R(q) offset, from
    `header.body_particle_offset`), nor, for an adaptive run, the accepted/rejected step counts. A file
    without the run's summary record reads as far as it goes, with `summary` None and `status` "unknown";
    an .mcap cut off before its summary section (a killed process) is not readable (ValueError):
    `rbsim recover` rewrites what it holds as a complete file (`record.mcap_recovery.recover_mcap`).
    Invariants appear only if the "invariants" stream was recorded.

    Raises FileNotFoundError for a missing file and ValueError (the file named) for another extension
    or a file that is not a readable rbsim recording.
    """
    path = Path(path)
    fmt = recording_format(path)
    if not path.is_file():
        reason = "is a directory, not a recording" if path.is_dir() else "no such recording"
        raise FileNotFoundError(errno.ENOENT, reason, str(path))
    try:
        run = read_recording(path)
    except (OSError, ImportError, RecordingTooNew):
        raise
    except Exception as exc:  # the readers raise several types for damaged or foreign files
        raise ValueError(f"{str(path)!r}: not a readable rbsim .{fmt} recording ({exc})") from exc
    try:
        return trajectory_from_run(run)
    except ValueError:
        raise
    except Exception as exc:  # found by fuzzing: a damaged .mcap decoded into invariants of the wrong type
        raise ValueError(f"{str(path)!r}: not a readable rbsim .{fmt} recording ({type(exc).__name__}: {exc})") from exc


def trajectory_from_run(run: RecordedRun) -> Trajectory:
    """A RecordedRun as a Trajectory (see `read_trajectory` for what each format gives back)."""
    if "body_names" not in run.metadata:
        raise ValueError(f"{str(run.path)!r}: no rbsim run parameters in the file (not written by rbsim?)")
    frames, bodies = run.x.shape[0], len(run.body_names)
    if run.x.shape[1] != bodies or run.t.shape[0] != frames:
        raise ValueError(
            f"{str(run.path)!r}: {run.x.shape[1]} bodies per frame for {bodies} names, "
            f"{run.t.shape[0]} times for {frames} frames"
        )
    for name, series in run.invariants.items():
        if series.shape[0] != frames:
            raise ValueError(f"{str(run.path)!r}: invariant {name!r} has {series.shape[0]} samples, {frames} frames")
    missing = tuple(name for name in _DYNAMICS if getattr(run, name) is None)

    def dynamics(values: np.ndarray | None) -> np.ndarray:
        return np.full((frames, bodies, 3), np.nan) if values is None else np.asarray(values, dtype=np.float64)

    header = header_from_parameters(run.metadata, run.scene_text, run.particle_offset)
    return Trajectory(
        body_names=run.body_names,
        t=np.asarray(run.t, dtype=np.float64),
        step=np.asarray(run.step, dtype=np.int64),
        x=np.asarray(run.x, dtype=np.float64),
        q=np.asarray(run.q, dtype=np.float64),
        v=dynamics(run.v),
        omega=dynamics(run.omega),
        P=dynamics(run.P),
        L=dynamics(run.L),
        invariants={name: np.asarray(s, dtype=np.float64) for name, s in run.invariants.items()},
        header=header,
        summary=_run_summary(run.summary),
        not_recorded=missing,
        joint_force=run.joint_force,
        joint_names=run.joint_names,
    )


def _run_summary(fields: dict[str, str]) -> RunSummary | None:
    """The RunSummary a file's summary record holds (None when the run was cut short before writing it)."""
    if "status" not in fields:
        return None
    return RunSummary(
        status=fields["status"],
        steps=int(fields.get("steps", "-1")),
        frames=int(fields.get("frames", "-1")),
        t_end=float(fields.get("t_end", "nan")),
        message=fields.get("message", ""),
    )


# --- the summary `rbsim info` prints ---------------------------------------------------------------


@dataclass(frozen=True)
class InvariantDrift:
    """How far an invariant strayed: max over the run of |f(t) - f(0)|, and that over |f(0)|.

    relative is None where |f(0)| <= RELATIVE_DRIFT_FLOOR (a quantity that starts at zero). Non-finite
    samples (a diverged run) are left out of the maxima and counted.
    """

    name: str
    initial: float
    final: float
    max_abs: float
    relative: float | None
    nonfinite: int = 0


def invariant_drift(name: str, series: np.ndarray) -> InvariantDrift:
    """The drift of one invariant time series."""
    f = np.asarray(series, dtype=np.float64)
    finite = np.isfinite(f)
    if not finite.any():
        return InvariantDrift(name, math.nan, math.nan, math.nan, None, int(f.size))
    values = f[finite]
    f0 = float(values[0])
    max_abs = float(np.max(np.abs(values - f0)))
    relative = max_abs / abs(f0) if abs(f0) > RELATIVE_DRIFT_FLOOR else None
    return InvariantDrift(name, f0, float(values[-1]), max_abs, relative, int(f.size - finite.sum()))


@dataclass
class RunInfo:
    """What `rbsim info` reports about a recording."""

    path: Path
    format: str
    scene_name: str
    body_names: tuple[str, ...]
    integrator: str
    dt: float
    duration: float
    record_every: int
    frames: int
    steps: int
    t_end: float
    status: str
    message: str
    rbsim_version: str
    drifts: list[InvariantDrift]

    def __str__(self) -> str:
        shown = ", ".join(self.body_names[:8]) + (
            f", ... ({len(self.body_names)} in all)" if len(self.body_names) > 8 else ""
        )
        lines = [
            f"file         {self.path} ({self.format})",
            f"scene        {self.scene_name}",
            f"bodies       {len(self.body_names)}: {shown}",
            f"integrator   {self.integrator}, dt = {self.dt:g} s",
            f"duration     {self.t_end:g} s of {self.duration:g} s simulated; "
            + (f"{self.steps} steps, " if self.steps >= 0 else "steps unknown, ")
            + f"{self.frames} frames recorded (every {self.record_every})",
            f"status       {self.status}" + (f": {self.message}" if self.message else ""),
            f"written by   rbsim {self.rbsim_version}",
        ]
        if self.drifts:
            width = max(len(d.name) for d in self.drifts)
            lines += ["", f"{'invariant':<{width}}  {'f(0)':>14}  {'max|f-f(0)|':>12}  {'relative':>10}"]
            for d in self.drifts:
                rel = f"{d.relative:10.3e}" if d.relative is not None else f"{'-':>10}"
                extra = f"  ({d.nonfinite} non-finite)" if d.nonfinite else ""
                lines.append(f"{d.name:<{width}}  {d.initial:14.6e}  {d.max_abs:12.3e}  {rel}{extra}")
        return "\n".join(lines)


def summarize(path: str | Path) -> RunInfo:
    """The `rbsim info` summary of a .mcap or .rrd; reads metadata and invariants, not body states.

    A file cut short (the partial a killed run leaves: no MCAP summary and index, an .rrd without its
    end marker) is summarised from what it holds, with status "truncated" and how far it goes."""
    fmt = recording_format(path)
    if fmt == "mcap":
        from rbcli.record.mcap_layout import METADATA_RUN, METADATA_SUMMARY
        from rbcli.record.mcap_read import read_mcap_contents, read_mcap_invariants

        try:
            contents = read_mcap_contents(path)
        except ValueError as exc:  # no summary or index: read it front to back
            return _summarize_mcap_prefix(path, exc)
        meta, ending = contents.metadata.get(METADATA_RUN, {}), contents.metadata.get(METADATA_SUMMARY, {})
        check_format_version(path, meta)
        t, _, invariants = read_mcap_invariants(path)
        frames = contents.message_counts.get("/rbsim/state", 0)
    else:
        cut = rrd_cut(path)
        if cut is not None:
            return _summarize_rrd_prefix(path, *cut)
        run = read_rrd(path, bodies=False)
        meta, ending, t, invariants = run.metadata, run.summary, run.t, run.invariants
        frames = int(ending.get("frames_written", len(t)))
    return _run_info(path, fmt, meta, ending, t, invariants, frames)


def _run_info(
    path: str | Path,
    fmt: str,
    meta: dict[str, str],
    ending: dict[str, str],
    t: np.ndarray,
    invariants: dict[str, np.ndarray],
    frames: int,
) -> RunInfo:
    check_format_version(path, meta)
    dt = float(meta.get("dt", "nan"))
    t_end = float(ending.get("t_end", t[-1] if len(t) else "nan"))
    # without the run's summary record, the steps follow from the last recorded time (t = step dt)
    steps = int(ending["steps"]) if "steps" in ending else (round(t_end / dt) if math.isfinite(t_end / dt) else -1)
    return RunInfo(
        path=Path(path),
        format=fmt,
        scene_name=meta.get("scene_name", "?"),
        body_names=tuple(_json_list(meta.get("body_names"))),
        integrator=meta.get("integrator", "?"),
        dt=dt,
        duration=float(meta.get("duration", "nan")),
        record_every=int(meta.get("record_every", "1")),
        frames=frames,
        steps=steps,
        t_end=t_end,
        status=ending.get("status", "unknown (no summary record: was the recording cut short?)"),
        message=ending.get("message", ""),
        rbsim_version=meta.get("rbsim_version", "?"),
        drifts=[invariant_drift(n, s) for n, s in invariants.items()],
    )


def _truncated_note(path: str | Path, frames: int, steps: int | None, t_end: float | None, recover: bool) -> str:
    if not frames or t_end is None:
        held = "no complete frame is readable"
    else:
        upto = f"step {steps} (t = {t_end:.6g} s)" if steps is not None else f"t = {t_end:.6g} s"
        held = f"{frames} complete frames up to {upto} are readable"
    tail = f"; `rbsim recover {path} -o FIXED.mcap` writes them as a complete file" if recover and frames else ""
    return f"{held}{tail}"


def _summarize_mcap_prefix(path: str | Path, error: Exception) -> RunInfo:
    """A .mcap without a readable summary, read front to back (record.mcap_recovery.read_mcap_prefix)."""
    from rbcli.record.mcap_layout import METADATA_RUN, METADATA_SUMMARY
    from rbcli.record.mcap_recovery import read_mcap_prefix

    try:
        prefix = read_mcap_prefix(path)
    except ValueError:  # not an MCAP file at all: the indexed reader's error says more
        raise error from None
    meta = prefix.metadata.get(METADATA_RUN, {})
    ending = dict(prefix.metadata.get(METADATA_SUMMARY, {}))
    t = prefix.invariant_time
    what = "truncated" if not prefix.complete else "unindexed"
    why = (
        f"{prefix.problem} (a run killed or crashed before writing its summary and index)"
        if not prefix.complete
        else f"its summary section is unreadable ({error})"
    )
    ending.update(
        status=what,
        message=f"{why}; " + _truncated_note(path, prefix.frames, prefix.last_step, prefix.last_time, True),
    )
    if prefix.last_step is not None and prefix.last_time is not None:
        ending.update(steps=str(prefix.last_step), t_end=repr(prefix.last_time))
    else:
        ending.update(steps="0", t_end="0.0")
    return _run_info(path, "mcap", meta, ending, t, prefix.invariants, prefix.frames)


# An .rrd file: a 12-byte header (b"RRF2", version, options), then messages of a u64 kind and a u64
# payload length, little-endian; kind 0 ends the stream (its payload is the footer, rerun's manifest),
# written when the recording stream is closed. A killed run's file has no end and is often cut inside
# a message, which rerun's reader refuses ("Message payload ... exceeds file size").
_RRD_HEADER = 12
_RRD_MESSAGE_HEAD = 16


def rrd_cut(path: str | Path) -> tuple[int, int, str] | None:
    """None for an .rrd that ends as rerun ends its files; else (bytes in the file, bytes of whole
    messages, why it is cut) for one cut short (a killed run). ValueError when it is not an .rrd."""
    import struct

    with open(path, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        if f.read(4) != b"RRF2":
            raise ValueError("not an .rrd file (it does not start with 'RRF2')")
        position = _RRD_HEADER
        f.seek(position)
        while True:
            head = f.read(_RRD_MESSAGE_HEAD)
            if len(head) < _RRD_MESSAGE_HEAD:
                return size, position, f"the file ends after {position:,} bytes without rerun's end marker"
            kind, length = struct.unpack("<QQ", head)
            if kind == 0:
                return None  # the end marker: a complete file
            if position + _RRD_MESSAGE_HEAD + length > size:
                return (
                    size,
                    position,
                    (
                        f"the message at byte {position:,} is cut short: it needs "
                        f"{_RRD_MESSAGE_HEAD + length:,} bytes, the file ends {size - position:,} bytes into it"
                    ),
                )
            position += _RRD_MESSAGE_HEAD + length
            f.seek(position)


def _summarize_rrd_prefix(path: str | Path, size: int, readable: int, problem: str) -> RunInfo:
    """An .rrd cut short: its whole messages copied to a temporary file that rerun's reader takes. The
    complete frames are those every body entity that reached the file holds (the step timeline says
    which step each is); the run's parameters may be missing (rerun writes them when its batcher
    flushes), and then so are the body names and dt."""
    import tempfile
    import warnings

    from rbcli.record.rerun_sink import read_rrd_file

    with tempfile.TemporaryDirectory(prefix="rbsim-info-") as folder:
        copy = Path(folder) / "prefix.rrd"
        with open(path, "rb") as src, open(copy, "wb") as dst:
            remaining = readable
            while remaining > 0:
                block = src.read(min(remaining, 1 << 22))
                if not block:
                    break
                dst.write(block)
                remaining -= len(block)
        with warnings.catch_warnings():  # "RRD file has no footer/manifest": expected here
            warnings.simplefilter("ignore")
            contents = read_rrd_file(copy)
    meta = contents.properties.get("rbsim", {})
    ending = dict(contents.properties.get("rbsim.summary", {}))
    invariants = contents.invariants
    inv_time = next(iter(contents.invariant_time.values()), np.zeros(0))
    if contents.bodies is not None:  # the one-entity layout: every body in each row
        steps_seen, times = contents.bodies.step, contents.bodies.time
    elif contents.body_step:  # an entity per body: the frames they all hold
        common = min(len(s) for s in contents.body_step.values())
        entity = next(iter(contents.body_step))
        steps_seen, times = contents.body_step[entity][:common], contents.body_time[entity][:common]
    else:
        steps_seen, times = np.zeros(0, dtype=np.int64), inv_time
    frames = len(times)
    t_end = float(times[-1]) if frames else None
    dt = float(meta.get("dt", "nan"))
    if len(steps_seen):
        steps: int | None = int(steps_seen[-1])
    else:
        steps = round(t_end / dt) if t_end is not None and math.isfinite(t_end / dt) else None
    note = _truncated_note(path, frames, steps, t_end, False)
    ending.update(
        status="truncated",
        message=f"{problem} ({readable:,} of {size:,} bytes are whole messages; a run killed or crashed before "
        f"closing its file); {note}",
    )
    if t_end is not None:
        ending.update(t_end=repr(t_end))
    if steps is not None:
        ending.update(steps=str(steps))
    return _run_info(path, "rrd", meta, ending, inv_time, invariants, frames)
