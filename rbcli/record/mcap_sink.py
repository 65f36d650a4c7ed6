"""The MCAP sink: a run recorded as protobuf messages in zstd chunks, readable by Foxglove and by the
Rerun viewer.

The layout (topics, metadata records, the scene attachment) is `mcap_layout.py`; the messages are built
by `mcap_messages.py` (protobuf) and, the per-step ones, by `mcap_encoders.py` (wire format); the file
is written by `mcap_writer.py`. Reading it back: `mcap_read.py`, and a file cut short by a killed run:
`mcap_recovery.py`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import IO, Any

import numpy as np

from rbcli.record.frame import Checkpoint, FrameBlock, RunHeader, RunSummary
from rbcli.record.mcap_encoders import InvariantsEncoder, StateEncoder, TransformsEncoder, encode_joint_forces, time_ns
from rbcli.record.mcap_layout import (
    FORMAT_VERSION,
    METADATA_RUN,
    METADATA_SUMMARY,
    SCENE_ATTACHMENT,
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
    contact_cloud,
    encode_checkpoint,
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


def run_metadata(header: RunHeader) -> dict[str, str]:
    """The `rbsim` metadata record: the run parameters and the MCAP layout's format version."""
    return {"format_version": FORMAT_VERSION, **header.parameters()}


class SinkMcap:
    """Records a run to an MCAP file (its layout: the docstring of mcap_layout.py).

    compression: "zstd" (default, at mcap_writer.ZSTD_LEVEL), "lz4" or "none"; chunk_size: uncompressed
    bytes per chunk. The file is written by `mcap_writer.McapChunkWriter` (why: its docstring).

    What a killed run leaves: a chunk is closed when it reaches chunk_size and at the end of every block
    the runner hands over (and after `open`'s records), each written chunk is flushed to the operating
    system at once and the file fsynced at most every FSYNC_SECONDS; so the file holds every block written
    before the kill but the one being written (`mcap_recovery.read_mcap_prefix` and `rbsim recover` read it
    back).
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
