"""The per-step messages of an rbsim MCAP file in protobuf wire format: rbsim.State, rbsim.Invariants,
rbsim.JointForces and foxglove.FrameTransforms for every frame of a FrameBlock at once.

One protobuf object per body per step costs microseconds each (1000 bodies: milliseconds per frame),
so the per-step messages are written straight in protobuf wire format with numpy structured arrays: a
packed `repeated double` is key, byte length, raw little-endian float64; a message field is key,
length, payload. The tests decode every message with the real classes (`mcap_messages.py`) and compare.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from rbcli.record.frame import FrameBlock
from rbcli.record.mcap_layout import STATE_FIELDS, WORLD_FRAME


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


def time_ns(t: np.ndarray) -> np.ndarray:
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
        ts = _timestamp_payloads(time_ns(block.t))
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
