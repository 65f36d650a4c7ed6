"""MCAP recording: protobuf messages in zstd chunks, readable by Foxglove and by the Rerun viewer.

Topics; log_time = publish_time = simulated time [ns], so identical runs give byte-identical files:

    /rbsim/state               rbsim.State per recorded step: the exact float64 record
    /tf                        foxglove.FrameTransforms per recorded step: "world" -> each body
    /bodies/<name>/particles   foxglove.PointCloud once at t = 0, in the body's frame (frame_id = name)
    /rbsim/invariants          rbsim.Invariants per recorded step (only when the run has invariants)
    /particles                 foxglove.PointCloud of all particles, world frame (only with that stream)
    /contacts                  foxglove.PointCloud of the frame's contact points, world frame, fields
                               x, y, z [m] and normal_force [N] (only with that stream)
    /rbsim/checkpoint          rbsim.Checkpoint: what the run carries between steps, at most every
                               10 s of wall time and when it stops (`rbsim run --resume`)

Channel ids are 16-bit in MCAP, so a file holds at most 65,535 channels. A scene with more bodies than
fit beside the fixed channels (BODY_CHANNELS_MAX) puts every body's cloud on one channel instead,
`/bodies/particles`: the same messages (one PointCloud per body at t = 0, frame_id = the body's name,
sequence = body index), so the clouds still follow the transforms; in Foxglove give that topic a decay
time to see them all at once (a panel otherwise keeps one message per topic). The readers accept both.

plus the attachment `scene.yaml` and the metadata records `rbsim` (run parameters, written at open)
and `rbsim.summary` (how the run ended, written at close). The .proto text of the project messages
lives in schemas/; here their descriptors are built at run time, so there is no protoc step.

This is the only module that imports mcap, mcap_protobuf and foxglove_schemas_protobuf, so the
readers of the files it writes live here too (`read_mcap_contents`, `iter_mcap_blocks`,
`read_mcap_invariants`); `record.read` wraps them.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap_protobuf.schema import build_file_descriptor_set

from rbcli.record.frame import RECORDING_FORMAT_VERSION, Checkpoint, FrameBlock, RunHeader, RunSummary
from rbcli.record.mcap_writer import COMPRESSIONS, MAX_ID, ZSTD_LEVEL, McapChunkWriter

# A run's file is fsynced after a chunk when the last fsync is this old [s] (docs/robustness.md "Crashes").
FSYNC_SECONDS = 1.0

TOPIC_STATE = "/rbsim/state"
TOPIC_TF = "/tf"
TOPIC_INVARIANTS = "/rbsim/invariants"
TOPIC_PARTICLES = "/particles"
TOPIC_CONTACTS = "/contacts"
TOPIC_CHECKPOINT = "/rbsim/checkpoint"
TOPIC_JOINT_FORCES = "/rbsim/joint_forces"
TOPIC_BODY_PARTICLES = "/bodies/particles"  # every body's cloud, when one channel per body would not fit
WORLD_FRAME = "world"
METADATA_RUN = "rbsim"
METADATA_SUMMARY = "rbsim.summary"
SCENE_ATTACHMENT = "scene.yaml"
FORMAT_VERSION = str(RECORDING_FORMAT_VERSION)

# (FrameBlock attribute, rbsim.State field name, field number, components per body)
STATE_FIELDS = (
    ("x", "position", 3, 3),
    ("q", "orientation", 4, 4),
    ("v", "linear_velocity", 5, 3),
    ("omega", "angular_velocity", 6, 3),
    ("P", "momentum", 7, 3),
    ("L", "angular_momentum", 8, 3),
)


# Channels besides the per-body clouds: /rbsim/state, /tf, /rbsim/invariants, /particles, /contacts,
# /rbsim/checkpoint, /rbsim/joint_forces.
FIXED_CHANNELS = 7
BODY_CHANNELS_MAX = MAX_ID - FIXED_CHANNELS  # 65,529 bodies still get a channel each


def particle_topic(body_name: str) -> str:
    """The topic of a body's static particle cloud (in a file of at most BODY_CHANNELS_MAX bodies)."""
    return f"/bodies/{body_name}/particles"


def particle_channels_shared(body_count: int) -> bool:
    """True when the bodies' clouds share TOPIC_BODY_PARTICLES: one channel each would not fit in MCAP."""
    return body_count > BODY_CHANNELS_MAX


def _decoder_factory() -> Any:  # noqa: ANN401 - mcap_protobuf's DecoderFactory
    """The protobuf decoder of the readers (imported here: writing a run needs no reader, ~0.02 s)."""
    from mcap_protobuf.decoder import DecoderFactory

    return DecoderFactory()


def _reader(f: IO[bytes]) -> Any:  # noqa: ANN401 - mcap's McapReader
    """An MCAP reader of `f` that decodes protobuf messages."""
    from mcap.reader import make_reader

    return make_reader(f, decoder_factories=[_decoder_factory()])


# --- project message descriptors, built at run time (their text is schemas/rbsim_*.proto) ----------


_FDP = descriptor_pb2.FieldDescriptorProto


def invariant_field_names(names: Sequence[str]) -> tuple[str, ...]:
    """Protobuf field names for invariant names: [A-Za-z0-9_] kept, others -> '_', a leading digit
    prefixed with 'f_'; ValueError on a clash or on 'step' / 'time'."""
    fields = []
    for name in names:
        f = re.sub(r"[^A-Za-z0-9_]", "_", name)
        fields.append(f if f and (f[0].isalpha() or f[0] == "_") else f"f_{f}")
    taken = {"step", "time"}
    for f in fields:
        if f in taken:
            raise ValueError(f"invariant names {list(names)!r} give the protobuf field {f!r} twice")
        taken.add(f)
    return tuple(fields)


def _file_proto(file_name: str, message: str, fields: Sequence[tuple[str, int, int, int]]):
    """A proto3 FileDescriptorProto in package rbsim with one message; fields: (name, number, type, label)."""
    fdp = descriptor_pb2.FileDescriptorProto(name=file_name, package="rbsim", syntax="proto3")
    msg = fdp.message_type.add(name=message)
    for name, number, ftype, label in fields:
        msg.field.add(name=name, number=number, type=ftype, label=label, json_name=_json_name(name))
    return fdp


def _json_name(name: str) -> str:
    head, *rest = name.split("_")
    return head + "".join(p[:1].upper() + p[1:] for p in rest)


def state_file_proto() -> descriptor_pb2.FileDescriptorProto:
    """rbsim/state.proto as a descriptor (text: schemas/rbsim_state.proto)."""
    fields = [("step", 1, _FDP.TYPE_UINT64, _FDP.LABEL_OPTIONAL), ("time", 2, _FDP.TYPE_DOUBLE, _FDP.LABEL_OPTIONAL)]
    fields += [(name, num, _FDP.TYPE_DOUBLE, _FDP.LABEL_REPEATED) for _, name, num, _ in STATE_FIELDS]
    return _file_proto("rbsim/state.proto", "State", fields)


def checkpoint_file_proto() -> descriptor_pb2.FileDescriptorProto:
    """rbsim/checkpoint.proto as a descriptor (text: schemas/rbsim_checkpoint.proto)."""
    fields = [("step", 1, _FDP.TYPE_UINT64, _FDP.LABEL_OPTIONAL), ("time", 2, _FDP.TYPE_DOUBLE, _FDP.LABEL_OPTIONAL)]
    lists = ("names", "dtypes", "shapes")
    fields += [(name, 3 + i, _FDP.TYPE_STRING, _FDP.LABEL_REPEATED) for i, name in enumerate(lists)]
    fields += [("data", 6, _FDP.TYPE_BYTES, _FDP.LABEL_REPEATED)]
    return _file_proto("rbsim/checkpoint.proto", "Checkpoint", fields)


def encode_checkpoint(checkpoint: Checkpoint) -> bytes:
    """A Checkpoint as an rbsim.Checkpoint message (arrays little endian, C order)."""
    message = message_class(checkpoint_file_proto())(step=int(checkpoint.step), time=float(checkpoint.t))
    for name, array in checkpoint.arrays.items():
        a = np.ascontiguousarray(array)
        a = a.astype(a.dtype.newbyteorder("<"), copy=False)
        message.names.append(name)
        message.dtypes.append(a.dtype.str)
        message.shapes.append(json.dumps(list(a.shape)))
        message.data.append(a.tobytes())
    return message.SerializeToString()


def decode_checkpoint(message: Any) -> Checkpoint:
    """A decoded rbsim.Checkpoint message back as a Checkpoint (writable copies)."""
    arrays = {}
    for name, dtype, shape, data in zip(message.names, message.dtypes, message.shapes, message.data, strict=True):
        arrays[name] = np.frombuffer(data, dtype=np.dtype(dtype)).reshape(json.loads(shape)).copy()
    return Checkpoint(step=int(message.step), t=float(message.time), arrays=arrays)


def invariants_file_proto(invariant_names: Sequence[str]) -> descriptor_pb2.FileDescriptorProto:
    """rbsim/invariants.proto for this run's invariants (text: schemas/rbsim_invariants.proto)."""
    fields = [("step", 1, _FDP.TYPE_UINT64, _FDP.LABEL_OPTIONAL), ("time", 2, _FDP.TYPE_DOUBLE, _FDP.LABEL_OPTIONAL)]
    fields += [
        (f, 3 + i, _FDP.TYPE_DOUBLE, _FDP.LABEL_OPTIONAL) for i, f in enumerate(invariant_field_names(invariant_names))
    ]
    return _file_proto("rbsim/invariants.proto", "Invariants", fields)


def joint_forces_file_proto() -> descriptor_pb2.FileDescriptorProto:
    """rbsim/joint_forces.proto as a descriptor (text: schemas/rbsim_joint_forces.proto)."""
    fields = [("step", 1, _FDP.TYPE_UINT64, _FDP.LABEL_OPTIONAL), ("time", 2, _FDP.TYPE_DOUBLE, _FDP.LABEL_OPTIONAL)]
    fields += [("reaction", 3, _FDP.TYPE_DOUBLE, _FDP.LABEL_REPEATED)]
    return _file_proto("rbsim/joint_forces.proto", "JointForces", fields)


def message_class(fdp: descriptor_pb2.FileDescriptorProto) -> Any:
    """The generated class of the file's first message, in a private pool (runs may differ in schema)."""
    pool = descriptor_pool.DescriptorPool()
    pool.Add(fdp)
    return message_factory.GetMessageClass(pool.FindMessageTypeByName(f"rbsim.{fdp.message_type[0].name}"))


# --- wire-format encoders --------------------------------------------------------------------------
# One protobuf object per body per step costs microseconds each (1000 bodies: milliseconds per frame),
# so the two per-step messages are written straight in protobuf wire format with numpy structured
# arrays: a packed `repeated double` is key, byte length, raw little-endian float64; a message field is
# key, length, payload. The tests decode every message with the real classes and compare.


def _varint(value: int) -> bytes:
    out = bytearray()
    while value >= 0x80:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _key(number: int, wire_type: int) -> bytes:
    return _varint(number << 3 | wire_type)


def _u1(data: bytes) -> np.ndarray:
    return np.frombuffer(data, dtype=np.uint8)


def _time_ns(t: np.ndarray) -> np.ndarray:
    """Simulated time [s] -> integer ns, rounded (t = k dt is rarely an exact float)."""
    return np.rint(np.asarray(t, dtype=np.float64) * 1e9).astype(np.int64)


def _varints(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Protobuf varints of non-negative integers, vectorised: (bytes (K, 10) uint8, lengths (K,))."""
    v = np.asarray(values, dtype=np.uint64)
    groups = ((v[:, None] >> (np.arange(10, dtype=np.uint64) * np.uint64(7))) & np.uint64(0x7F)).astype(np.uint8)
    lengths = np.maximum(1, (np.ceil(np.log2(v.astype(np.float64) + 1.0) / 7.0)).astype(np.int64))
    # float log2 can be off by one right at 2**(7m): fix with the exact test "value >> 7 * length == 0"
    lengths += (v >> (lengths.astype(np.uint64) * np.uint64(7))) != 0
    lengths -= (lengths > 1) & ((v >> ((lengths - 1).astype(np.uint64) * np.uint64(7))) == 0)
    more = np.arange(10)[None, :] < (lengths[:, None] - 1)
    groups[more] |= 0x80
    return groups, lengths


def _step_time_heads(step: np.ndarray, t: np.ndarray) -> list[bytes]:
    """Per frame, fields 1 (uint64 step) and 2 (double time), each omitted when zero as proto3
    serializers do (+0.0 only: -0.0 has bits set and is written)."""
    k_count = len(step)
    digits, lengths = _varints(step)
    buf = np.zeros((k_count, 20), dtype=np.uint8)
    buf[:, 0] = 0x08
    buf[:, 1:11] = digits
    rows = np.arange(k_count)[:, None]
    time_at = 1 + lengths[:, None] + np.arange(9)[None, :]  # key byte then 8 bytes, after the varint
    tb = np.asarray(t, dtype="<f8").reshape(k_count, 1).view(np.uint8)
    buf[rows, time_at] = np.concatenate([np.full((k_count, 1), 0x11, np.uint8), tb], axis=1)
    start = np.where(np.asarray(step) == 0, 1 + lengths, 0)  # step 0: skip its "08 00"
    end = 1 + lengths + np.where(tb.any(axis=1), 9, 0)  # time +0.0: nothing after the varint
    return [buf[k, start[k] : end[k]].tobytes() for k in range(k_count)]


class StateEncoder:
    """rbsim.State bytes for every frame of a block, identical to the canonical SerializeToString."""

    def __init__(self, body_count: int) -> None:
        n = body_count
        spec: list[tuple[str, Any, tuple[int, ...]]] = []
        self._keys = {}
        for attr, _, number, width in STATE_FIELDS if n else ():
            key = _key(number, 2) + _varint(8 * width * n)
            spec += [(f"k_{attr}", np.uint8, (len(key),)), (attr, "<f8", (n * width,))]
            self._keys[attr] = _u1(key)
        self.dtype = np.dtype(spec)

    def encode(self, block: FrameBlock) -> list[bytes]:
        k_count = len(block)
        rec = np.empty(k_count, dtype=self.dtype)
        for attr, key in self._keys.items():
            rec[f"k_{attr}"] = key
            rec[attr] = np.asarray(getattr(block, attr), dtype=np.float64).reshape(k_count, -1)
        heads = _step_time_heads(block.step, block.t)
        return [heads[k] + rec[k].tobytes() for k in range(k_count)]


class InvariantsEncoder:
    """rbsim.Invariants bytes for every frame of a block: step and time as canonical proto3 (omitted
    when zero), then every invariant as a double field, zeros included (valid proto3 that decodes to
    the same values; a fixed layout, so numpy writes all frames at once)."""

    def __init__(self, invariant_names: Sequence[str]) -> None:
        self.names = tuple(invariant_names)
        spec = []
        for i, _ in enumerate(self.names):
            spec += [(f"k{i}", np.uint8, (len(_key(3 + i, 1)),)), (f"v{i}", "<f8")]
        self.dtype = np.dtype(spec)
        self._keys = [_u1(_key(3 + i, 1)) for i in range(len(self.names))]

    def encode(self, block: FrameBlock) -> list[bytes]:
        k_count = len(block)
        rec = np.empty(k_count, dtype=self.dtype)
        for i, name in enumerate(self.names):
            rec[f"k{i}"] = self._keys[i]
            rec[f"v{i}"] = np.asarray(block.invariants[name], dtype=np.float64)
        heads = _step_time_heads(block.step, block.t)
        return [heads[k] + rec[k].tobytes() for k in range(k_count)]


def encode_joint_forces(block: FrameBlock) -> list[bytes]:
    """rbsim.JointForces bytes for every frame of a block (block.joint_force (K, J, 12)): step and time
    as canonical proto3, then `reaction` packed (key, byte length, raw little-endian float64)."""
    assert block.joint_force is not None
    k_count = len(block)
    flat = np.ascontiguousarray(block.joint_force, dtype="<f8").reshape(k_count, -1)
    head = (_key(3, 2) + _varint(8 * flat.shape[1])) if flat.shape[1] else b""
    heads = _step_time_heads(block.step, block.t)
    return [heads[k] + head + flat[k].tobytes() for k in range(k_count)]


def _timestamp_payloads(ns: np.ndarray) -> list[bytes]:
    """google.protobuf.Timestamp payloads (seconds = 1, nanos = 2; zero fields omitted), vectorised."""
    sec, nanos = np.divmod(np.asarray(ns, dtype=np.int64), 1_000_000_000)
    (sd, sl), (nd, nl) = _varints(sec), _varints(nanos)
    k_count = len(sec)
    buf = np.zeros((k_count, 22), dtype=np.uint8)
    rows = np.arange(k_count)[:, None]
    buf[:, 0] = 0x08
    buf[:, 1:11] = sd
    has_sec = sec != 0
    at = np.where(has_sec, 1 + sl, 0)[:, None] + np.arange(11)[None, :]
    buf[rows, at] = np.concatenate([np.full((k_count, 1), 0x10, np.uint8), nd], axis=1)
    end = at[:, 0] + np.where(nanos != 0, 1 + nl, 0)
    return [buf[k, : end[k]].tobytes() for k in range(k_count)]


class TransformsEncoder:
    """foxglove.FrameTransforms bytes (world -> each body) for every frame of a block.

    Each FrameTransform is written as: timestamp, parent_frame_id, child_frame_id, translation
    (x, y, z), rotation (x, y, z, w), with every double present even when zero (valid proto3; it keeps
    the layout fixed). A record's length then depends only on its frame ids and on the timestamp, which
    is the same for all bodies of a frame; transforms are grouped by the byte length of their ids (body
    order within a group), so within a frame each group is a run of equal-size records that numpy fills
    with strided views. Consumers key transforms by child_frame_id, so the order is free.
    """

    # A record is: head (0x0a, length, 0x0a, ts length), ts, ids, then this fixed 67-byte tail:
    # 0x22 0x1b (Vector3, 27 bytes) 0x09 x 0x11 y 0x19 z, 0x2a 0x24 (Quaternion, 36 bytes) 0x09 qx 0x11 qy
    # 0x19 qz 0x21 qw. Doubles sit 9 bytes apart (key byte + 8).
    _TAIL = b"\x22\x1b\x09" + bytes(8) + b"\x11" + bytes(8) + b"\x19" + bytes(8)
    _TAIL += b"\x2a\x24\x09" + bytes(8) + b"\x11" + bytes(8) + b"\x19" + bytes(8) + b"\x21" + bytes(8)
    _TAIL_X, _TAIL_QX = 3, 32

    def __init__(self, body_names: Sequence[str], parent: str = WORLD_FRAME) -> None:
        pb = parent.encode()
        ids = [
            b"\x12" + _varint(len(pb)) + pb + b"\x1a" + _varint(len(nb)) + nb for nb in (s.encode() for s in body_names)
        ]
        by_length: dict[int, list[int]] = {}
        for i, b in enumerate(ids):
            by_length.setdefault(len(b), []).append(i)
        # (bodies: a slice when contiguous, else an index array; their id bytes)
        self._runs: list[tuple[slice | np.ndarray, list[bytes]]] = []
        for _, idx in sorted(by_length.items()):
            contiguous = idx == list(range(idx[0], idx[0] + len(idx)))
            self._runs.append((slice(idx[0], idx[-1] + 1) if contiguous else np.array(idx), [ids[i] for i in idx]))
        self._layouts: dict[int, tuple[np.ndarray, list[tuple[int, int, int, int]]]] = {}

    def _layout(self, ts_len: int) -> tuple[np.ndarray, list[tuple[int, int, int, int]]]:
        """A frame's constant bytes and, per run: (offset, record count, record size, ts offset)."""
        if ts_len not in self._layouts:
            parts, runs, offset = [], [], 0
            for _, id_list in self._runs:
                payload = 2 + ts_len + len(id_list[0]) + len(self._TAIL)
                head = b"\x0a" + _varint(payload) + b"\x0a" + _varint(ts_len)
                size = len(head) + payload - 2
                parts += [head + bytes(ts_len) + ids + self._TAIL for ids in id_list]
                runs.append((offset, len(id_list), size, len(head)))
                offset += size * len(id_list)
            self._layouts[ts_len] = (_u1(b"".join(parts)), runs)
        return self._layouts[ts_len]

    def encode(self, block: FrameBlock) -> list[bytes]:
        k_count = len(block)
        ts = _timestamp_payloads(_time_ns(block.t))
        x, q = np.asarray(block.x, dtype=np.float64), np.asarray(block.q, dtype=np.float64)
        out: list[bytes] = [b""] * k_count
        ts_lens = np.array([len(s) for s in ts])
        for ts_len in np.unique(ts_lens).tolist():
            frames = np.flatnonzero(ts_lens == ts_len)
            rows = slice(None) if len(frames) == k_count else frames
            template, runs = self._layout(ts_len)
            g, size = len(frames), template.size
            buf = np.empty((g, size), dtype=np.uint8)
            buf[...] = template
            ts_arr = _u1(b"".join(ts[f] for f in frames.tolist())).reshape(g, ts_len)
            for (bodies, _), (offset, count, rec, ts_off) in zip(self._runs, runs, strict=True):
                # each field of this run is a strided view: frames apart by `size`, records by `rec`
                tail = offset + rec - len(self._TAIL)
                if ts_len:
                    _strided(buf, offset + ts_off, (g, count, ts_len), "u1", (size, rec, 1))[...] = ts_arr[:, None, :]
                _strided(buf, tail + self._TAIL_X, (g, count, 3), "<f8", (size, rec, 9))[...] = x[rows][:, bodies]
                rot = _strided(buf, tail + self._TAIL_QX, (g, count, 4), "<f8", (size, rec, 9))
                qs = q[rows][:, bodies]
                rot[..., :3], rot[..., 3] = qs[..., 1:], qs[..., 0]
            for row, f in enumerate(frames.tolist()):
                out[f] = buf[row].tobytes()
        return out


def _strided(buf: np.ndarray, offset: int, shape: tuple[int, ...], dtype: str, strides: tuple[int, ...]) -> np.ndarray:
    """A writable view into a contiguous byte buffer (unaligned doubles are fine for numpy)."""
    return np.ndarray(shape, dtype, buffer=buf, offset=offset, strides=strides)


def _point_cloud(points: np.ndarray, frame_id: str, ns: int) -> PointCloud:
    """A foxglove.PointCloud of float64 x, y, z (exact) with an identity pose."""
    cloud = PointCloud(frame_id=frame_id, point_stride=24, data=np.ascontiguousarray(points, "<f8").tobytes())
    cloud.timestamp.FromNanoseconds(int(ns))
    # the pose written out in full: protobuf omits an unset submessage, and an absent position is not (0, 0, 0)
    # to every reader (Rerun's MCAP loader leaves its InstancePoses3D translation null, which `rerun rrd
    # verify` rejects); SetInParent writes the empty Vector3, which Foxglove's schema reads as zeros
    cloud.pose.position.SetInParent()
    cloud.pose.orientation.w = 1.0  # an all-zero quaternion would be invalid
    for i, axis in enumerate("xyz"):
        cloud.fields.add(name=axis, offset=8 * i, type=PackedElementField.FLOAT64)
    return cloud


def _contact_cloud(points: np.ndarray, force: np.ndarray, ns: int) -> PointCloud:
    """A foxglove.PointCloud of contact points: float64 x, y, z [m] and normal_force [N], world frame."""
    packed = np.empty((len(points), 4), "<f8")
    packed[:, :3], packed[:, 3] = points, force
    cloud = _point_cloud(np.zeros((0, 3)), WORLD_FRAME, ns)
    cloud.point_stride, cloud.data = 32, packed.tobytes()
    cloud.fields.add(name="normal_force", offset=24, type=PackedElementField.FLOAT64)
    return cloud


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
        self._ch_tf = self._channel(TOPIC_TF, FrameTransforms)
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
            shared = self._channel(TOPIC_BODY_PARTICLES, PointCloud)
        for i, (name, offsets) in enumerate(zip(header.body_names, header.body_particle_offset, strict=True)):
            cloud = _point_cloud(np.asarray(offsets).reshape(-1, 3), name, 0).SerializeToString()
            if shared is None:
                self._add(self._channel(particle_topic(name), PointCloud), 0, cloud)
            else:
                self._add(shared, 0, cloud, sequence=i)  # the body index orders the shared channel's messages
        w.flush_chunk()  # schemas, channels and clouds on disk before the first frame

    def _channel(self, topic: str, schema: Any, metadata: dict[str, str] | None = None) -> int:
        """Register a protobuf schema (a generated class or a FileDescriptorProto) and a channel on it."""
        assert self._writer is not None
        is_file = isinstance(schema, descriptor_pb2.FileDescriptorProto)
        name = f"rbsim.{schema.message_type[0].name}" if is_file else schema.DESCRIPTOR.full_name
        if name not in self._schemas:  # one schema record per message type, however many channels
            fds = descriptor_pb2.FileDescriptorSet(file=[schema]) if is_file else build_file_descriptor_set(schema)
            self._schemas[name] = self._writer.register_schema(name, "protobuf", fds.SerializeToString())
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
        ns, steps = _time_ns(block.t).tolist(), block.step.tolist()
        inv = self._inv.encode(block) if self._ch_inv is not None else None
        particles = block.particle_position
        if particles is not None and self._ch_particles is None:
            self._ch_particles = self._channel(TOPIC_PARTICLES, PointCloud)
        contacts, forces = block.contact_point, block.contact_force
        if contacts is not None and self._ch_contacts is None:
            self._ch_contacts = self._channel(TOPIC_CONTACTS, PointCloud)
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
                cloud = _point_cloud(particles[k], WORLD_FRAME, ns[k]).SerializeToString()
                self._add(self._ch_particles, ns[k], cloud, seq)
            if contacts is not None and forces is not None and self._ch_contacts is not None:
                cloud = _contact_cloud(contacts[k], forces[k], ns[k]).SerializeToString()
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
        ns = int(_time_ns(np.array([checkpoint.t]))[0])
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
            offsets[cloud.frame_id] = _cloud_points(cloud)
    return McapContents(metadata, scene, counts, offsets, inv_names, header.library)


def _cloud_points(cloud: Any) -> np.ndarray:
    """(n, 3) float64 x, y, z of a foxglove.PointCloud written by this module or by any float writer."""
    types = {PackedElementField.FLOAT64: "<f8", PackedElementField.FLOAT32: "<f4"}
    offs = {f.name: (f.offset, types[f.type]) for f in cloud.fields if f.name in ("x", "y", "z") and f.type in types}
    raw = np.frombuffer(cloud.data, dtype=np.uint8).reshape(-1, cloud.point_stride)
    cols = [raw[:, o : o + np.dtype(t).itemsize].copy().view(t)[:, 0] for o, t in (offs[a] for a in "xyz")]
    return np.stack(cols, axis=1).astype(np.float64) if cols[0].size else np.zeros((0, 3))


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


# --- reading a file cut short (a run killed before its summary and index were written) ---------------

# Topics with one message per recorded frame: a frame is complete when each of those present has it.
FRAME_TOPICS = (TOPIC_STATE, TOPIC_TF, TOPIC_INVARIANTS, TOPIC_PARTICLES, TOPIC_JOINT_FORCES)


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
    factory = _decoder_factory()
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
        decode = _decoder_factory().decoder_for(channel.message_encoding, schemas.get(channel.schema_id))
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
    factory = _decoder_factory()
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
