"""The MCAP layout of an rbsim recording: its topics, metadata records and attachment, the state's
fields, and how many channels a file can hold. The sink (`mcap_sink.py`), the readers (`mcap_read.py`)
and crash recovery (`mcap_recovery.py`) all name the file's parts from here.

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
and `rbsim.summary` (how the run ended, written at close). The messages themselves: `mcap_messages.py`.
"""

from __future__ import annotations

from rbcli.record.frame import RECORDING_FORMAT_VERSION
from rbcli.record.mcap_writer import MAX_ID

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


# Topics with one message per recorded frame: a frame is complete when each of those present has it
# (what crash recovery keeps of a file cut short).
FRAME_TOPICS = (TOPIC_STATE, TOPIC_TF, TOPIC_INVARIANTS, TOPIC_PARTICLES, TOPIC_JOINT_FORCES)
