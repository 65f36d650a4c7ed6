"""What flows from the runner to the sinks: a run header once, then blocks of recorded frames.

Sinks implement `Sink` (open / write / close). Arrays are float64, SI units, world frame; quaternions
are (w, x, y, z) world-from-body in the user's body frame (the frame the scene's particles were given
in), so outputs read exactly as the scene was written. Convert to (x, y, z, w) only inside a sink.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

# the layout of rbsim's recordings (.mcap channels and metadata, .rrd entities and properties), written as
# `format_version` with `rbsim_version` in every file: bumped when an older reader would misread a newer file
RECORDING_FORMAT_VERSION = 1


@dataclass(frozen=True)
class RunHeader:
    """Everything about a run that does not change per step.

    body_particle_offset: per body, particle positions relative to the centre of mass [m], shape
    (n_i, 3), in the user's body frame (so a static point cloud under the body transform is right).
    """

    scene_name: str
    scene_text: str
    scene_path: str | None
    scene_sha256: str
    body_names: tuple[str, ...]
    body_mass: np.ndarray  # [kg], shape (body_count,)
    body_particle_offset: tuple[np.ndarray, ...]
    integrator: str
    dt: float  # [s]
    duration: float  # [s]
    record_every: int
    streams: tuple[str, ...]
    rbsim_version: str
    seed: int = 0
    invariant_names: tuple[str, ...] = ()
    joint_names: tuple[str, ...] = ()  # the joints whose reactions are recorded (the joint_forces stream)
    tolerance: float | None = None  # [-] adaptive runs' error budget (None: fixed step)
    units: str = "SI (m, kg, s, rad)"
    quaternion_order: str = "wxyz"

    def parameters(self) -> dict[str, str]:
        """Run parameters as strings for a file's metadata (floats as repr and lists as JSON, so they read
        back exactly); the sinks add what is specific to their format."""
        return {
            "format_version": str(RECORDING_FORMAT_VERSION),
            "rbsim_version": self.rbsim_version,
            "scene_name": self.scene_name,
            "scene_path": self.scene_path or "",
            "scene_sha256": self.scene_sha256,
            "integrator": self.integrator,
            "dt": repr(float(self.dt)),
            "duration": repr(float(self.duration)),
            "record_every": str(int(self.record_every)),
            "seed": str(int(self.seed)),
            "units": self.units,
            "quaternion_order": self.quaternion_order,
            "streams": json.dumps(list(self.streams)),
            "body_count": str(len(self.body_names)),
            "body_names": json.dumps(list(self.body_names)),
            "body_mass": json.dumps([float(m) for m in np.asarray(self.body_mass, dtype=np.float64)]),
            "invariant_names": json.dumps(list(self.invariant_names)),
            "joint_names": json.dumps(list(self.joint_names)),
            "tolerance": "" if self.tolerance is None else repr(float(self.tolerance)),
        }


@dataclass(frozen=True)
class Checkpoint:
    """Everything a run carries from one step to the next, at one step: what continues it bit for bit.

    arrays: name -> array (Data.carried: the state in the internal principal frame, the integrator's and
    the contact stage's carried work, the adaptive controller); copies, taken between chunks. Recorded in
    .mcap logs (docs/robustness.md "Resume") and read by `rbsim run --resume`.
    """

    step: int
    t: float  # [s]
    arrays: dict[str, np.ndarray]


@dataclass
class FrameBlock:
    """K consecutive recorded frames of all N bodies.

    step: (K,) int64 step index; t: (K,) [s]; x: (K, N, 3) centre of mass [m]; q: (K, N, 4) wxyz;
    v: (K, N, 3) [m/s]; omega: (K, N, 3) world angular velocity [rad/s]; P: (K, N, 3) [kg m/s];
    L: (K, N, 3) world angular momentum [kg m^2/s].
    invariants: name -> (K,) time series (energies [J], momentum components, norms).
    particle_position: (K, particle_count, 3) world [m], present only when the particles stream is on.
    contact_point, contact_force: per frame, the (n_k, 3) contact points [m, world] and the (n_k,)
    normal force magnitudes [N] there (physics/contact/points.py), present only with the contacts stream.
    joint_force: (K, J, 12) each joint's reaction over the (sub-)step that ended at the frame, world
    frame: [0:3] force [N] and [3:6] torque about the centre of mass [N m] on its first body, [6:12] on
    its second (zeros for the world); NaN where no step led to the frame (a run's first frame); present
    only with the joint_forces stream (Simulation.joint_reactions' values, docs/joints.md).
    """

    step: np.ndarray
    t: np.ndarray
    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    P: np.ndarray
    L: np.ndarray
    invariants: dict[str, np.ndarray] = field(default_factory=dict)
    particle_position: np.ndarray | None = None
    contact_point: list[np.ndarray] | None = None
    contact_force: list[np.ndarray] | None = None
    joint_force: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True)
class RunSummary:
    """How a run ended. status: "completed", "diverged" or "interrupted"."""

    status: str
    steps: int
    frames: int
    t_end: float
    message: str = ""
    steps_accepted: int | None = None  # adaptive runs: error-controlled steps taken ...
    steps_rejected: int | None = None  # ... and attempts rejected (None for fixed-step runs)
    # scenes with contact: contacts whose tangential history found no free slot (docs/contact.md), and
    # the body of the first of them ("" when none)
    contact_history_overflow: int | None = None
    contact_overflow_body: str = ""
    # reduced-implicit: contacts past its solve's capacity, which kept their explicit force (None: not such a run)
    implicit_contact_overflow: int | None = None

    def fields(self, frames_written: int) -> dict[str, str]:
        """How the run ended, as strings for a file's summary record (t_end as repr, so it reads back
        exactly); frames_written: the frames this sink actually wrote."""
        return {
            "status": self.status,
            "steps": str(int(self.steps)),
            "frames": str(int(self.frames)),
            "frames_written": str(int(frames_written)),
            "t_end": repr(float(self.t_end)),
            "message": self.message,
        }


class Sink(Protocol):
    """A recorder: open with the header, write blocks in order, close with the summary.

    close() must leave a complete, readable file whatever the status (diverged runs included).
    """

    def open(self, header: RunHeader) -> None: ...

    def write(self, block: FrameBlock) -> None: ...

    def close(self, summary: RunSummary) -> None: ...


class CheckpointSink(Protocol):
    """A sink that also stores checkpoints (the MCAP sink): `write_checkpoint` follows the block whose
    frames precede the checkpoint's step, in the same thread and order as `write`."""

    def write_checkpoint(self, checkpoint: Checkpoint) -> None: ...
