"""Reading an rbsim MCAP log front to back, without its summary: a complete file, or one cut short by a
killed or crashed run (a `.partial.mcap`). What it holds (`read_mcap_prefix`, for `rbsim info`), the same
rewritten as a complete file (`recover_mcap`, for `rbsim recover`), and where a stopped run continues
(`read_mcap_resume_point`, `iter_mcap_frames_before`, for `rbsim run --resume`). A complete file is read
through its index by `mcap_read.py`.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from rbcli.record.frame import Checkpoint, FrameBlock, RunSummary
from rbcli.record.mcap_layout import (
    FRAME_TOPICS,
    METADATA_SUMMARY,
    SCENE_ATTACHMENT,
    TOPIC_CHECKPOINT,
    TOPIC_INVARIANTS,
    TOPIC_JOINT_FORCES,
    TOPIC_STATE,
)
from rbcli.record.mcap_messages import decode_checkpoint, decoder_factory, invariant_field_names
from rbcli.record.mcap_read import block_from_messages
from rbcli.record.mcap_writer import MAGIC, McapChunkWriter

# --- a file cut short (a run killed before its summary and index were written) ----------------------


@dataclass
class McapPrefix:
    """What a front-to-back read of an MCAP file finds before the first record that does not end inside
    the file (or fails its CRC): the whole data section of a complete file, everything written before
    the cut of a file whose run was killed. Chunks are self-contained, so each one written is readable.

    frames: complete frames (every per-frame topic present has that frame's message); last_step and
    last_time: the step and time [s] of the last complete frame (None without frames); invariant_time
    and invariants: those of the complete frames.
    """

    path: Path
    size: int  # bytes in the file
    readable_bytes: int  # bytes up to the end of the last record read
    complete: bool  # the data section ends as written (DataEnd): nothing was cut
    problem: str  # why the read stopped before the end ("" when complete)
    library: str
    metadata: dict[str, dict[str, str]]
    scene_text: str
    message_counts: dict[str, int]  # topic -> messages read (complete frames or not)
    frames: int
    last_step: int | None
    last_time: float | None
    invariant_names: tuple[str, ...] = ()
    invariant_time: np.ndarray = field(default_factory=lambda: np.zeros(0))
    invariants: dict[str, np.ndarray] = field(default_factory=dict)

    def frame_counts(self) -> dict[str, int]:
        """Messages to keep per topic so that only complete frames remain (other topics: all)."""
        return {t: self.frames for t in FRAME_TOPICS if t in self.message_counts}


@dataclass
class _Cut:
    """Where and why `_prefix_records` stopped."""

    size: int = 0
    readable: int = 0
    complete: bool = False
    problem: str = ""


def _prefix_records(path: str | Path, cut: _Cut) -> Iterator[Any]:
    """The records of an MCAP data section in file order (chunks opened), read front to back without the
    summary: stops at DataEnd (cut.complete), or at the first record that the file does not hold whole,
    that fails its CRC or does not decode (cut.problem says which, cut.readable where it starts).
    ValueError when the file does not start as an MCAP file."""
    import io
    import os
    import struct

    from mcap.exceptions import EndOfFile
    from mcap.opcode import Opcode
    from mcap.records import DataEnd, Footer
    from mcap.stream_reader import StreamReader

    with open(path, "rb") as f:
        cut.size = os.fstat(f.fileno()).st_size
        if f.read(len(MAGIC)) != MAGIC:
            raise ValueError("not an MCAP file (it does not start with the MCAP magic bytes)")
        position = cut.readable = len(MAGIC)
        while True:
            head = f.read(9)
            if not head:
                cut.problem = f"the file ends after {position:,} bytes, before the end of its data section"
                return
            if len(head) < 9 or head[0] == 0:
                what = "zero bytes (space a crash left unwritten)" if head[0] == 0 else "a cut record header"
                cut.problem = f"{what} at byte {position:,} of {cut.size:,}"
                return
            opcode, length = struct.unpack("<BQ", head)
            if position == len(MAGIC) and opcode != Opcode.HEADER:
                raise ValueError("not an MCAP file (its first record is not a header)")
            name = Opcode(opcode).name if opcode in Opcode._value2member_map_ else f"opcode {opcode:#x}"
            if position + 9 + length > cut.size:
                cut.problem = (
                    f"the {name} record at byte {position:,} is cut short: it needs {9 + length:,} bytes, "
                    f"the file ends {cut.size - position:,} bytes into it"
                )
                return
            body = f.read(length)
            reader = StreamReader(io.BytesIO(head + body), skip_magic=True, validate_crcs=True)
            records = []
            try:
                for record in reader.records:
                    records.append(record)
            except EndOfFile:
                pass
            except Exception as exc:  # a damaged chunk: bad CRC, undecodable compression
                cut.problem = f"the {name} record at byte {position:,} is damaged ({type(exc).__name__}: {exc})"
                return
            for record in records:
                if isinstance(record, DataEnd | Footer):
                    cut.complete, cut.readable = True, position + 9 + length
                    return
                yield record
            position = cut.readable = position + 9 + length


def read_mcap_prefix(path: str | Path) -> McapPrefix:
    """Everything readable in an rbsim MCAP file front to back, whether or not it was cut short (see
    McapPrefix). Reads and decompresses every chunk; decodes the invariants and the last two states."""
    from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema

    cut = _Cut()
    library = ""
    metadata: dict[str, dict[str, str]] = {}
    scene = ""
    schemas: dict[int, Schema] = {}
    topics: dict[int, str] = {}
    channels: dict[int, Channel] = {}
    counts: dict[str, int] = {}
    last_states: list[Message] = []  # the last two: the last complete frame is one of them
    inv_rows: list[Any] = []
    decoders: dict[int, Any] = {}
    factory = decoder_factory()
    for record in _prefix_records(path, cut):
        if isinstance(record, Message):
            topic = topics.get(record.channel_id, "")
            counts[topic] = counts.get(topic, 0) + 1
            if topic == TOPIC_STATE:
                last_states = [*last_states[-1:], record]
            elif topic == TOPIC_INVARIANTS:
                if record.channel_id not in decoders:
                    channel = channels[record.channel_id]
                    decoders[record.channel_id] = factory.decoder_for(
                        channel.message_encoding, schemas.get(channel.schema_id)
                    )
                decode = decoders[record.channel_id]
                if decode is not None:
                    inv_rows.append(decode(record.data))
        elif isinstance(record, Channel):
            channels[record.id], topics[record.id] = record, record.topic
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Metadata):
            metadata[record.name] = dict(record.metadata)
        elif isinstance(record, Attachment) and record.name == SCENE_ATTACHMENT:
            scene = record.data.decode(errors="replace")
        elif isinstance(record, Header):
            library = record.library
    present = [t for t in FRAME_TOPICS if t in topics.values()]
    frames = min((counts.get(t, 0) for t in present), default=0)
    last_step = last_time = None
    if frames:
        state_msg = last_states[-1] if counts[TOPIC_STATE] == frames else last_states[0]
        channel = channels[state_msg.channel_id]
        decode = factory.decoder_for(channel.message_encoding, schemas.get(channel.schema_id))
        if decode is None:
            raise ValueError(f"no decoder for {TOPIC_STATE} ({channel.message_encoding})")
        state = decode(state_msg.data)
        last_step, last_time = int(state.step), float(state.time)
    inv_names = next(
        (
            tuple(json.loads(c.metadata.get("invariant_names", "[]")))
            for c in channels.values()
            if c.topic == TOPIC_INVARIANTS
        ),
        (),
    )
    rows = inv_rows[:frames]
    series = {
        n: np.array([getattr(m, f) for m in rows], dtype=np.float64)
        for n, f in zip(inv_names, invariant_field_names(inv_names), strict=True)
    }
    return McapPrefix(
        path=Path(path),
        size=cut.size,
        readable_bytes=cut.readable,
        complete=cut.complete,
        problem=cut.problem,
        library=library,
        metadata=metadata,
        scene_text=scene,
        message_counts=counts,
        frames=frames,
        last_step=last_step,
        last_time=last_time,
        invariant_names=inv_names,
        invariant_time=np.array([m.time for m in rows], dtype=np.float64),
        invariants=series,
    )


def truncated_summary(prefix: McapPrefix, source: str) -> RunSummary:
    """The `rbsim.summary` record a recovered file gets: status "truncated", up to its last complete frame."""
    steps = prefix.last_step if prefix.last_step is not None else 0
    t_end = prefix.last_time if prefix.last_time is not None else 0.0
    return RunSummary(
        status="truncated",
        steps=steps,
        frames=prefix.frames,
        t_end=t_end,
        message=(
            f"the run was cut short (killed or crashed) after step {steps} (t = {t_end:.6g} s); recovered from "
            f"{source}: {prefix.frames} complete frames, {prefix.readable_bytes:,} of {prefix.size:,} bytes readable"
        ),
    )


def recover_mcap(source: str | Path, stream: IO[bytes], *, compression: str = "zstd") -> McapPrefix:
    """Rewrite the readable part of an MCAP file (one cut short by a killed run) to `stream` as a complete
    MCAP file: its header, schemas, channels, attachments, metadata and the messages of every complete
    frame, with a summary section and index, so every reader opens it. A file without a `rbsim.summary`
    record gets one (`truncated_summary`). Returns what was read (two passes over `source`)."""
    from mcap.records import Attachment, Channel, Header, Message, Metadata, Schema

    prefix = read_mcap_prefix(source)
    keep = prefix.frame_counts()
    writer = McapChunkWriter(stream, compression=compression)
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    topics: dict[int, str] = {}
    written: dict[str, int] = {}
    started = False
    for record in _prefix_records(source, _Cut()):
        if isinstance(record, Header):
            writer.start(profile=record.profile, library=record.library)
            started = True
            continue
        if not started:  # an MCAP file starts with its header; write one if it was lost
            writer.start(profile="", library="")
            started = True
        if isinstance(record, Message):
            topic = topics.get(record.channel_id)
            if topic is None or record.channel_id not in channel_ids:
                continue  # a message on a channel never defined: not readable, left out
            if topic in keep:
                if written.get(topic, 0) >= keep[topic]:
                    continue  # part of the last, incomplete frame
                written[topic] = written.get(topic, 0) + 1
            writer.add_message(
                channel_ids[record.channel_id], record.log_time, record.data, record.publish_time, record.sequence
            )
        elif isinstance(record, Schema):
            schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
        elif isinstance(record, Channel):
            topics[record.id] = record.topic
            channel_ids[record.id] = writer.register_channel(
                record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0), dict(record.metadata)
            )
        elif isinstance(record, Metadata):
            writer.add_metadata(record.name, dict(record.metadata))
        elif isinstance(record, Attachment):
            writer.add_attachment(record.create_time, record.log_time, record.name, record.media_type, record.data)
    if not started:
        writer.start(profile="", library="")
    if METADATA_SUMMARY not in prefix.metadata:
        writer.add_metadata(METADATA_SUMMARY, truncated_summary(prefix, Path(source).name).fields(prefix.frames))
    writer.finish()
    return prefix


# --- resuming a run from its log -------------------------------------------------------------------


@dataclass
class McapResumePoint:
    """What `rbsim run --resume` needs from a log, read front to back (a complete file or one cut short):
    the run metadata, the scene text, and the last checkpoint (None when the run wrote none)."""

    metadata: dict[str, dict[str, str]]
    scene_text: str
    checkpoint: Checkpoint | None
    complete: bool
    problem: str


def read_mcap_resume_point(path: str | Path) -> McapResumePoint:
    """The last readable checkpoint of an rbsim MCAP log, with its metadata and scene (see McapResumePoint);
    ValueError when the file is not an MCAP file."""
    from mcap.records import Attachment, Channel, Message, Metadata, Schema

    cut = _Cut()
    metadata: dict[str, dict[str, str]] = {}
    scene = ""
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    last: Message | None = None
    for record in _prefix_records(path, cut):
        if isinstance(record, Message):
            channel = channels.get(record.channel_id)
            if channel is not None and channel.topic == TOPIC_CHECKPOINT:
                last = record
        elif isinstance(record, Channel):
            channels[record.id] = record
        elif isinstance(record, Schema):
            schemas[record.id] = record
        elif isinstance(record, Metadata):
            metadata[record.name] = dict(record.metadata)
        elif isinstance(record, Attachment) and record.name == SCENE_ATTACHMENT:
            scene = record.data.decode(errors="replace")
    checkpoint = None
    if last is not None:
        channel = channels[last.channel_id]
        decode = decoder_factory().decoder_for(channel.message_encoding, schemas.get(channel.schema_id))
        if decode is None:
            raise ValueError(f"no decoder for {TOPIC_CHECKPOINT} ({channel.message_encoding})")
        checkpoint = decode_checkpoint(decode(last.data))
    return McapResumePoint(metadata, scene, checkpoint, cut.complete, cut.problem)


def iter_mcap_frames_before(path: str | Path, step: int, block_frames: int = 256) -> Iterator[FrameBlock]:
    """The recorded frames of an rbsim MCAP log (complete or cut short) with step < `step`, as FrameBlocks
    decoded from /rbsim/state, /rbsim/invariants and /rbsim/joint_forces: bit for bit what was recorded."""
    from mcap.records import Channel, Message, Schema

    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    decoders: dict[int, Any] = {}
    factory = decoder_factory()
    inv_names: tuple[str, ...] = ()
    rows: list[Any] = []
    inv_rows: dict[int, Any] = {}
    joint_names: tuple[str, ...] | None = None
    joint_rows: dict[int, Any] | None = None
    for record in _prefix_records(path, _Cut()):
        if isinstance(record, Channel):
            channels[record.id] = record
            if record.topic == TOPIC_INVARIANTS:
                inv_names = tuple(json.loads(record.metadata.get("invariant_names", "[]")))
            if record.topic == TOPIC_JOINT_FORCES:
                joint_names, joint_rows = tuple(json.loads(record.metadata.get("joint_names", "[]"))), {}
            continue
        if isinstance(record, Schema):
            schemas[record.id] = record
            continue
        if not isinstance(record, Message):
            continue
        channel = channels.get(record.channel_id)
        if channel is None or channel.topic not in (TOPIC_STATE, TOPIC_INVARIANTS, TOPIC_JOINT_FORCES):
            continue
        if record.channel_id not in decoders:
            decoders[record.channel_id] = factory.decoder_for(channel.message_encoding, schemas.get(channel.schema_id))
        msg = decoders[record.channel_id](record.data)
        if msg.step >= step:
            continue  # frames at and after the resume point come from the resumed run
        if channel.topic == TOPIC_INVARIANTS:
            inv_rows[msg.step] = msg
            continue
        if channel.topic == TOPIC_JOINT_FORCES:
            if joint_rows is not None:
                joint_rows[msg.step] = msg
            continue
        if len(rows) == block_frames:  # a step's invariants follow its state: emit at the next state
            yield block_from_messages(
                rows, inv_rows, inv_names, invariant_field_names(inv_names), joint_rows, joint_names
            )
            rows = []
        rows.append(msg)
    if rows:
        yield block_from_messages(rows, inv_rows, inv_names, invariant_field_names(inv_names), joint_rows, joint_names)
