"""Reading a complete rbsim MCAP file through its summary and index: its metadata, scene and particle
clouds (`read_mcap_contents`), its frames (`iter_mcap_blocks`) and its invariants alone
(`read_mcap_invariants`); `record.read` wraps them. A file cut short has no summary: `mcap_recovery.py`
reads that one front to back.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from rbcli.record.frame import FrameBlock
from rbcli.record.mcap_layout import SCENE_ATTACHMENT, STATE_FIELDS, TOPIC_INVARIANTS, TOPIC_JOINT_FORCES, TOPIC_STATE
from rbcli.record.mcap_messages import cloud_points, decoder_factory, invariant_field_names


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
                yield block_from_messages(rows, inv_rows, inv_names, inv_fields, joint_rows, joints)
                rows = []
            rows.append(msg)
        if rows:
            yield block_from_messages(rows, inv_rows, inv_names, inv_fields, joint_rows, joints)


def block_from_messages(
    rows: list[Any],
    inv_rows: dict[int, Any],
    names: tuple[str, ...],
    fields: tuple[str, ...],
    joint_rows: dict[int, Any] | None = None,
    joint_names: tuple[str, ...] | None = None,
) -> FrameBlock:
    """A FrameBlock of decoded rbsim.State messages with their steps' invariants and joint reactions (NaN
    where a step has none), taken out of `inv_rows` and `joint_rows`."""
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
