"""The protobuf messages of an rbsim MCAP file: the project messages' descriptors, built at run time
(their text is schemas/rbsim_*.proto, so there is no protoc step), the checkpoint's encoding, the
foxglove.PointCloud messages (written and read back), each channel's schema record, and the readers'
protobuf decoder.

This is the only module that imports protobuf, mcap_protobuf and foxglove_schemas_protobuf; the
per-step messages are written in wire format by `mcap_encoders.py` instead (speed), and the tests
decode those with the classes built here.
"""

from __future__ import annotations

import json
import re
from collections.abc import Sequence
from typing import Any

import numpy as np
from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms
from foxglove_schemas_protobuf.PackedElementField_pb2 import PackedElementField
from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory
from mcap_protobuf.schema import build_file_descriptor_set

from rbcli.record.frame import Checkpoint
from rbcli.record.mcap_layout import STATE_FIELDS, WORLD_FRAME

# The foxglove messages of the layout's channels (the sink registers their schemas by class).
TRANSFORMS_MESSAGE = FrameTransforms
POINT_CLOUD_MESSAGE = PointCloud


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


def schema_name(schema: Any) -> str:  # noqa: ANN401 - a generated class or a FileDescriptorProto
    """The full message name of a schema: a generated class or a FileDescriptorProto (its first message)."""
    if isinstance(schema, descriptor_pb2.FileDescriptorProto):
        return f"rbsim.{schema.message_type[0].name}"
    return str(schema.DESCRIPTOR.full_name)


def schema_data(schema: Any) -> bytes:  # noqa: ANN401 - a generated class or a FileDescriptorProto
    """A protobuf schema record's data: the serialized FileDescriptorSet of the message."""
    is_file = isinstance(schema, descriptor_pb2.FileDescriptorProto)
    fds = descriptor_pb2.FileDescriptorSet(file=[schema]) if is_file else build_file_descriptor_set(schema)
    return fds.SerializeToString()


# --- foxglove.PointCloud ----------------------------------------------------------------------------


def point_cloud(points: np.ndarray, frame_id: str, ns: int) -> PointCloud:
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


def contact_cloud(points: np.ndarray, force: np.ndarray, ns: int) -> PointCloud:
    """A foxglove.PointCloud of contact points: float64 x, y, z [m] and normal_force [N], world frame."""
    packed = np.empty((len(points), 4), "<f8")
    packed[:, :3], packed[:, 3] = points, force
    cloud = point_cloud(np.zeros((0, 3)), WORLD_FRAME, ns)
    cloud.point_stride, cloud.data = 32, packed.tobytes()
    cloud.fields.add(name="normal_force", offset=24, type=PackedElementField.FLOAT64)
    return cloud


# --- reading back ------------------------------------------------------------------------------------


def decoder_factory() -> Any:  # noqa: ANN401 - mcap_protobuf's DecoderFactory
    """The protobuf decoder of the readers (imported here: writing a run needs no reader, ~0.02 s)."""
    from mcap_protobuf.decoder import DecoderFactory

    return DecoderFactory()


def cloud_points(cloud: Any) -> np.ndarray:
    """(n, 3) float64 x, y, z of a foxglove.PointCloud written by this module or by any float writer."""
    types = {PackedElementField.FLOAT64: "<f8", PackedElementField.FLOAT32: "<f4"}
    offs = {f.name: (f.offset, types[f.type]) for f in cloud.fields if f.name in ("x", "y", "z") and f.type in types}
    raw = np.frombuffer(cloud.data, dtype=np.uint8).reshape(-1, cloud.point_stride)
    cols = [raw[:, o : o + np.dtype(t).itemsize].copy().view(t)[:, 0] for o, t in (offs[a] for a in "xyz")]
    return np.stack(cols, axis=1).astype(np.float64) if cols[0].size else np.zeros((0, 3))
