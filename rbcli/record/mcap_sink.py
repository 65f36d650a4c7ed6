"""The MCAP sink: a run recorded as protobuf messages in zstd chunks, readable by Foxglove and by the
Rerun viewer.

The layout (topics, metadata records, the scene attachment) is `mcap_layout.py`; the messages are built
by `mcap_messages.py` (protobuf) and, the per-step ones, by `mcap_encoders.py` (wire format); the file
is written by `mcap_writer.py`. The readers of the files it writes live here too (`read_mcap_contents`,
`iter_mcap_blocks`, `read_mcap_invariants`); `record.read` wraps them.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from rbcli.record.frame import Checkpoint, FrameBlock, RunHeader, RunSummary
from rbcli.record.mcap_encoders import InvariantsEncoder, StateEncoder, TransformsEncoder, encode_joint_forces, time_ns
from rbcli.record.mcap_layout import (
    FORMAT_VERSION,
    FRAME_TOPICS,
    METADATA_RUN,
    METADATA_SUMMARY,
    SCENE_ATTACHMENT,
    STATE_FIELDS,
    TOPIC_BODY_PARTICLES,
    TOPIC_CHECKPOINT,
    TOPIC_CONTACTS,
    TOPIC_INVARIANTS,
    TOPIC_JOINT_FORCES,
    TOPIC_PARTICLES,
    TOPIC_STATE,
    TOPIC_TF,
    WORLD_FRAME,
    particle_channels_shared,
    particle_topic,
)
from rbcli.record.mcap_messages import (
    POINT_CLOUD_MESSAGE,
    TRANSFORMS_MESSAGE,
    checkpoint_file_proto,
    cloud_points,
    contact_cloud,
    decode_checkpoint,
    decoder_factory,
    encode_checkpoint,
    invariant_field_names,
    invariants_file_proto,
    joint_forces_file_proto,
    point_cloud,
    schema_data,
    schema_name,
    state_file_proto,
)
from rbcli.record.mcap_writer import COMPRESSIONS, ZSTD_LEVEL, McapChunkWriter

# A run's file is fsynced after a chunk when the last fsync is this old [s] (docs/robustness.md "Crashes").
FSYNC_SECONDS = 1.0


# --- the sink --------------------------------------------------------------------------------------


def run_metadata(header: RunHeader) -> dict[str, str]:
    """The `rbsim` metadata record: the run parameters and the MCAP layout's format version."""
    return {"format_version": FORMAT_VERSION, **header.parameters()}


class SinkMcap:
    """Records a run to an MCAP file (see the module docstring for the layout).

    compression: "zstd" (default, at mcap_writer.ZSTD_LEVEL), "lz4" or "none"; chunk_size: uncompressed
    bytes per chunk. The file is written by `mcap_writer.McapChunkWriter` (why: its docstring).

    What a killed run leaves: a chunk is closed when it reaches chunk_size and at the end of every block
    the runner hands over (and after `open`'s records), each written chunk is flushed to the operating
    system at once and the file fsynced at most every FSYNC_SECONDS; so the file holds every block written
    before the kill but the one being written (`read_mcap_prefix` and `rbsim recover` read it back).
    """

    def __init__(self, path: str | Path, *, compression: str = "zstd", chunk_size: int = 4 * 1024 * 1024) -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression {compression!r}: expected one of {', '.join(COMPRESSIONS)}")
        self.path = Path(path)
        self._compression = compression
        self._chunk_size = chunk_size
        self._file: IO[bytes] | None = None
        self._writer: McapChunkWriter | None = None
        self._closed = False
        self._schemas: dict[str, int] = {}
        self.frames_written = 0

    def open(self, header: RunHeader) -> None:
        self._header = header
        self._file = open(self.path, "wb")  # closed in close()
        w = self._writer = McapChunkWriter(
            self._file,
            compression=self._compression,
            chunk_size=self._chunk_size,
            background=True,
            fsync_seconds=FSYNC_SECONDS,
        )
        level = f" level {ZSTD_LEVEL}" if self._compression == "zstd" else ""
        library = f"rbsim/{header.rbsim_version} (rbcli.record.mcap_writer, {self._compression}{level})"
        w.start(profile="", library=library)
        self._state = StateEncoder(len(header.body_names))
        self._tf = TransformsEncoder(header.body_names)
        self._invariant_names = tuple(header.invariant_names)
        self._ch_state = self._channel(TOPIC_STATE, state_file_proto())
        self._ch_tf = self._channel(TOPIC_TF, TRANSFORMS_MESSAGE)
        self._ch_inv: int | None = None
        if self._invariant_names:
            fdp = invariants_file_proto(self._invariant_names)
            self._inv = InvariantsEncoder(self._invariant_names)
            meta = {"invariant_names": json.dumps(list(self._invariant_names))}
            self._ch_inv = self._channel(TOPIC_INVARIANTS, fdp, meta)
        self._ch_particles: int | None = None
        self._ch_contacts: int | None = None
        self._ch_checkpoint: int | None = None
        self._ch_joint_forces: int | None = None
        if header.joint_names:
            meta = {"joint_names": json.dumps(list(header.joint_names))}
            self._ch_joint_forces = self._channel(TOPIC_JOINT_FORCES, joint_forces_file_proto(), meta)
        w.add_metadata(METADATA_RUN, run_metadata(header))
        w.add_attachment(0, 0, SCENE_ATTACHMENT, "application/yaml", header.scene_text.encode())
        shared: int | None = None
        if particle_channels_shared(len(header.body_names)):
            shared = self._channel(TOPIC_BODY_PARTICLES, POINT_CLOUD_MESSAGE)
        for i, (name, offsets) in enumerate(zip(header.body_names, header.body_particle_offset, strict=True)):
            cloud = point_cloud(np.asarray(offsets).reshape(-1, 3), name, 0).SerializeToString()
            if shared is None:
                self._add(self._channel(particle_topic(name), POINT_CLOUD_MESSAGE), 0, cloud)
            else:
                self._add(shared, 0, cloud, sequence=i)  # the body index orders the shared channel's messages
        w.flush_chunk()  # schemas, channels and clouds on disk before the first frame

    def _channel(self, topic: str, schema: Any, metadata: dict[str, str] | None = None) -> int:
        """Register a protobuf schema (a generated class or a FileDescriptorProto) and a channel on it."""
        assert self._writer is not None
        name = schema_name(schema)
        if name not in self._schemas:  # one schema record per message type, however many channels
            self._schemas[name] = self._writer.register_schema(name, "protobuf", schema_data(schema))
        schema_id = self._schemas[name]
        return self._writer.register_channel(topic, "protobuf", schema_id, metadata or {})

    def _add(self, channel: int, ns: int, data: bytes, sequence: int = 0) -> None:
        assert self._writer is not None
        self._writer.add_message(channel, log_time=ns, data=data, publish_time=ns, sequence=sequence)

    def write(self, block: FrameBlock) -> None:
        if self._writer is None or self._closed:
            raise RuntimeError("SinkMcap.write before open() or after close()")
        k_count = len(block)
        states, tfs = self._state.encode(block), self._tf.encode(block)
        ns, steps = time_ns(block.t).tolist(), block.step.tolist()
        inv = self._inv.encode(block) if self._ch_inv is not None else None
        particles = block.particle_position
        if particles is not None and self._ch_particles is None:
            self._ch_particles = self._channel(TOPIC_PARTICLES, POINT_CLOUD_MESSAGE)
        contacts, forces = block.contact_point, block.contact_force
        if contacts is not None and self._ch_contacts is None:
            self._ch_contacts = self._channel(TOPIC_CONTACTS, POINT_CLOUD_MESSAGE)
        joints = (
            encode_joint_forces(block) if block.joint_force is not None and self._ch_joint_forces is not None else None
        )
        for k in range(k_count):
            seq = steps[k] & 0xFFFFFFFF
            self._add(self._ch_state, ns[k], states[k], seq)
            self._add(self._ch_tf, ns[k], tfs[k], seq)
            if inv is not None and self._ch_inv is not None:
                self._add(self._ch_inv, ns[k], inv[k], seq)
            if particles is not None and self._ch_particles is not None:
                cloud = point_cloud(particles[k], WORLD_FRAME, ns[k]).SerializeToString()
                self._add(self._ch_particles, ns[k], cloud, seq)
            if contacts is not None and forces is not None and self._ch_contacts is not None:
                cloud = contact_cloud(contacts[k], forces[k], ns[k]).SerializeToString()
                self._add(self._ch_contacts, ns[k], cloud, seq)
            if joints is not None and self._ch_joint_forces is not None:
                self._add(self._ch_joint_forces, ns[k], joints[k], seq)
        self._writer.flush_chunk()  # no frame waits in the open chunk for the next block
        self.frames_written += k_count

    def write_checkpoint(self, checkpoint: Checkpoint) -> None:
        """Store a checkpoint on /rbsim/checkpoint, in a chunk of its own right after the block it follows
        (so a killed run keeps every checkpoint written before the kill)."""
        if self._writer is None or self._closed:
            raise RuntimeError("SinkMcap.write_checkpoint before open() or after close()")
        if self._ch_checkpoint is None:
            self._ch_checkpoint = self._channel(TOPIC_CHECKPOINT, checkpoint_file_proto())
        ns = int(time_ns(np.array([checkpoint.t]))[0])
        self._add(self._ch_checkpoint, ns, encode_checkpoint(checkpoint), checkpoint.step & 0xFFFFFFFF)
        self._writer.flush_chunk()

    def close(self, summary: RunSummary) -> None:
        """Write the summary metadata, the index and the footer; safe to call more than once."""
        if self._closed or self._writer is None:
            self._closed = True
            return
        self._closed = True
        try:
            self._writer.add_metadata(METADATA_SUMMARY, summary.fields(self.frames_written))
            self._writer.finish()
        finally:
            assert self._file is not None
            self._file.close()


# --- reading ---------------------------------------------------------------------------------------


@dataclass
class McapContents:
    """What an rbsim MCAP file holds besides the per-step arrays."""

    metadata: dict[str, dict[str, str]]  # record name -> key/value
    scene_text: str
    message_counts: dict[str, int]  # topic -> messages
    particle_offset: dict[str, np.ndarray] = field(default_factory=dict)  # body -> (n_i, 3) body frame [m]
    invariant_names: tuple[str, ...] = ()
    library: str = ""


def _reader(f: IO[bytes]) -> Any:  # noqa: ANN401 - mcap's McapReader
    """An MCAP reader of `f` that decodes protobuf messages."""
    from mcap.reader import make_reader

    return make_reader(f, decoder_factories=[decoder_factory()])


def _invariant_names(summary: Any) -> tuple[str, ...]:
    """The invariant names a file's /rbsim/invariants channel carries in its metadata."""
    for ch in summary.channels.values() if summary else ():
        if ch.topic == TOPIC_INVARIANTS:
            return tuple(json.loads(ch.metadata.get("invariant_names", "[]")))
    return ()


def read_mcap_contents(path: str | Path) -> McapContents:
    """Metadata, scene attachment, message counts and the t = 0 particle clouds of an rbsim MCAP file."""
    with open(path, "rb") as f:
        reader = _reader(f)
        try:
            header, summary = reader.get_header(), reader.get_summary()
        except Exception as exc:  # the mcap library raises several types for a damaged file
            raise ValueError(
                f"not a complete MCAP file, was it cut short? ({exc}); `rbsim info` tells how much it holds and "
                "`rbsim recover FILE -o FIXED.mcap` rewrites it as a complete file"
            ) from exc
        if summary is None:
            raise ValueError(
                "the MCAP file has no summary section (was the recording cut short?); "
                "`rbsim recover FILE -o FIXED.mcap` rewrites it as a complete file"
            )
        if summary.statistics is None:
            raise ValueError("the MCAP file has no statistics record (message counts); was it written without them?")
        topics = {ch.id: ch.topic for ch in summary.channels.values()}
        counts = {topics[cid]: int(n) for cid, n in summary.statistics.channel_message_counts.items()}
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        scene = next((a.data.decode() for a in reader.iter_attachments() if a.name == SCENE_ATTACHMENT), "")
        inv_names = _invariant_names(summary)
        # one topic per body, or all on TOPIC_BODY_PARTICLES (which the pattern also matches): keyed by
        # frame_id, so read in file order. A set, not a list: the reader tests `topic in topics` for every
        # message, which for a list of one topic per body was quadratic (65,531 bodies: 22 s, now 1.7 s).
        clouds = {t for t in counts if t.startswith("/bodies/") and t.endswith("/particles")}
        offsets: dict[str, np.ndarray] = {}
        for _, _, _, cloud in reader.iter_decoded_messages(topics=clouds, log_time_order=False):
            offsets[cloud.frame_id] = cloud_points(cloud)
    return McapContents(metadata, scene, counts, offsets, inv_names, header.library)


def joint_names_of(summary: Any) -> tuple[str, ...] | None:
    """The joint names a file's /rbsim/joint_forces channel carries in its metadata; None without it."""
    for ch in summary.channels.values() if summary else ():
        if ch.topic == TOPIC_JOINT_FORCES:
            return tuple(json.loads(ch.metadata.get("joint_names", "[]")))
    return None


def iter_mcap_blocks(path: str | Path, block_frames: int = 256) -> Iterator[FrameBlock]:
    """FrameBlocks decoded from /rbsim/state, /rbsim/invariants and /rbsim/joint_forces with the file's
    own schemas (joint_force None in a file without the joint_forces stream)."""
    with open(path, "rb") as f:
        reader = _reader(f)
        summary = reader.get_summary()
        inv_names = _invariant_names(summary)
        inv_fields = invariant_field_names(inv_names)
        joints = joint_names_of(summary)
        rows: list[Any] = []
        inv_rows: dict[int, Any] = {}
        joint_rows: dict[int, Any] | None = {} if joints is not None else None
        for _, channel, _, msg in reader.iter_decoded_messages(
            topics=[TOPIC_STATE, TOPIC_INVARIANTS, TOPIC_JOINT_FORCES], log_time_order=False
        ):
            if channel.topic == TOPIC_INVARIANTS:
                inv_rows[msg.step] = msg
                continue
            if channel.topic == TOPIC_JOINT_FORCES:
                if joint_rows is not None:
                    joint_rows[msg.step] = msg
                continue
            # a step's invariants follow its state, so a full block is emitted only at the next state
            if len(rows) == block_frames:
                yield _block_from_messages(rows, inv_rows, inv_names, inv_fields, joint_rows, joints)
                rows = []
            rows.append(msg)
        if rows:
            yield _block_from_messages(rows, inv_rows, inv_names, inv_fields, joint_rows, joints)


def _block_from_messages(
    rows: list[Any],
    inv_rows: dict[int, Any],
    names: tuple[str, ...],
    fields: tuple[str, ...],
    joint_rows: dict[int, Any] | None = None,
    joint_names: tuple[str, ...] | None = None,
) -> FrameBlock:
    k_count, n = len(rows), len(rows[0].position) // 3
    arrays = {}
    for attr, name, _, width in STATE_FIELDS:
        flat = np.array([np.asarray(getattr(m, name), dtype=np.float64) for m in rows])
        arrays[attr] = flat.reshape(k_count, n, width)
    steps = np.array([m.step for m in rows], dtype=np.int64)
    invariants = {
        name: np.array([getattr(inv_rows[s], f) if s in inv_rows else math.nan for s in steps.tolist()])
        for name, f in zip(names, fields, strict=True)
    }
    for s in steps.tolist():
        inv_rows.pop(s, None)
    t = np.array([m.time for m in rows], dtype=np.float64)
    a = arrays
    block = FrameBlock(steps, t, a["x"], a["q"], a["v"], a["omega"], a["P"], a["L"], invariants=invariants)
    if joint_rows is not None and joint_names is not None:
        reaction = np.full((k_count, len(joint_names), 12), math.nan)
        for k, s in enumerate(steps.tolist()):
            msg = joint_rows.pop(s, None)
            if msg is not None:
                reaction[k] = np.asarray(msg.reaction, dtype=np.float64).reshape(len(joint_names), 12)
        block.joint_force = reaction
    return block


def read_mcap_invariants(path: str | Path) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(t [s], step, name -> series) from /rbsim/invariants alone: cheap, whatever the body count."""
    with open(path, "rb") as f:
        reader = _reader(f)
        names = _invariant_names(reader.get_summary())
        fields = invariant_field_names(names)
        rows = [msg for _, _, _, msg in reader.iter_decoded_messages(topics=[TOPIC_INVARIANTS], log_time_order=False)]
    t = np.array([m.time for m in rows], dtype=np.float64)
    step = np.array([m.step for m in rows], dtype=np.int64)
    return (
        t,
        step,
        {n: np.array([getattr(m, f) for m in rows], dtype=np.float64) for n, f in zip(names, fields, strict=True)},
    )


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

    from rbcli.record.mcap_writer import MAGIC

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
            yield _block_from_messages(
                rows, inv_rows, inv_names, invariant_field_names(inv_names), joint_rows, joint_names
            )
            rows = []
        rows.append(msg)
    if rows:
        yield _block_from_messages(rows, inv_rows, inv_names, invariant_field_names(inv_names), joint_rows, joint_names)
