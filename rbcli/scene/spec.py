"""Typed, validated scene specification: what `scene/load.py` produces and `scene/compile.py` consumes.

Everything here is already checked and resolved to numbers (shapes sampled to particles, orientations
to unit quaternions); no raw YAML reaches the physics. Units are SI throughout: m, kg, s, rad.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

# the scene file format this rbsim reads (a scene's optional `version:`; the schema's maximum): bumped when
# a scene written for a newer rbsim could mean something this one would misread
SCENE_FORMAT_VERSION = 1


@dataclass(frozen=True)
class SourceLocation:
    """A place in a scene file, 1-based line and column (as editors show them)."""

    file: str
    line: int
    column: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.column}"


@dataclass(frozen=True)
class SceneIssue:
    """One problem found in a scene: where, what is wrong, and what was expected."""

    location: SourceLocation | None
    message: str
    expected: str = ""
    severity: str = "error"  # "error" or "warning"

    def __str__(self) -> str:
        where = str(self.location) if self.location else "<scene>"
        tail = f" — expected {self.expected}" if self.expected else ""
        return f"{where}: {self.severity}: {self.message}{tail}"

    def order(self) -> tuple[int, int]:
        """Sort key: by position in the file, unlocated issues first."""
        return (self.location.line, self.location.column) if self.location else (0, 0)


class SceneError(Exception):
    """A scene that cannot be run; carries every issue found, each with its location."""

    def __init__(self, issues: list[SceneIssue]):
        self.issues = list(issues)
        super().__init__("\n".join(str(i) for i in self.issues))


@dataclass(frozen=True)
class RecordSpec:
    """What the recorder writes: every `every`-th step, which streams, and the MCAP chunk compression."""

    every: int = 1
    streams: tuple[str, ...] = ("bodies", "invariants")  # also "particles", "contacts", "joint_forces"
    compression: str = "zstd"  # MCAP chunks: "zstd", "lz4" or "none"


@dataclass(frozen=True)
class SimulationSpec:
    """Time stepping: step `dt` [s] over `duration` [s] with the named integrator."""

    dt: float
    duration: float
    integrator: str = "euler-matrix"
    tolerance: float | None = None  # adaptive error control instead of a fixed dt (integrators issue)
    # "maximal" (x, q, P, L of every body) or "reduced" (articulated trees in joint coordinates: only the
    # reduced integrators run it; docs/trees.md)
    coordinates: str = "maximal"
    record: RecordSpec = field(default_factory=RecordSpec)
    output: str | None = None  # output path; format from the extension (.mcap or .rrd)
    seed: int = 0
    # of its `dt`: where a run's length and cost are told (not part of what the settings are: compare=False)
    location: SourceLocation | None = field(default=None, compare=False)


@dataclass(frozen=True)
class MaterialSpec:
    """Contact material (docs/contact.md); None: the scene's `contact.material`, then the defaults.

    stiffness [N/m] of one contact sphere's contact (None: derived from the body's weight and sphere
    radius, physics/contact/parameters.py), restitution [1] in [0.01, 1], friction [1] (Coulomb mu).
    """

    stiffness: float | None = None
    restitution: float | None = None
    friction: float | None = None

    def over(self, base: MaterialSpec) -> MaterialSpec:
        """This material's values where given, base's elsewhere."""
        return MaterialSpec(
            self.stiffness if self.stiffness is not None else base.stiffness,
            self.restitution if self.restitution is not None else base.restitution,
            self.friction if self.friction is not None else base.friction,
        )


@dataclass(frozen=True)
class PlaneSpec:
    """A static half-space: `point` [m] on its surface, unit `normal` pointing out of the solid (world)."""

    point: np.ndarray
    normal: np.ndarray
    material: MaterialSpec = field(default_factory=MaterialSpec)  # stiffness unused: a plane takes the body's
    location: SourceLocation | None = None


@dataclass(frozen=True)
class KinematicSpec:
    """A kinematic body's prescribed motion (`kinematic: {velocity, angular_velocity, pivot, schedule}`,
    physics/kinematic.py): it moves at s(t) velocity [m/s] and turns at s(t) angular_velocity
    [rad/s] (both world frame) about `pivot` [m] (a world point at t = 0 that moves with the body's
    translation; None: its centre of mass), s(t) the schedule (force_specs.Schedule; None: s = 1)."""

    velocity: np.ndarray
    angular_velocity: np.ndarray
    pivot: np.ndarray | None = None
    schedule: Any = None


@dataclass(frozen=True)
class ContactSpec:
    """The scene's `contact:` section: world planes (ground, walls, container), the default material,
    and contact sub-stepping (None: `auto`, chosen from the stable step at the dt that runs)."""

    planes: tuple[PlaneSpec, ...] = ()
    material: MaterialSpec = field(default_factory=MaterialSpec)
    substeps: int | None = 1
    location: SourceLocation | None = None
    # shape bodies (box, capsule) touch planes as their exact primitive (docs/contact.md); False: as their
    # lattice spheres, as before primitives existed
    primitives: bool = True


@dataclass(frozen=True)
class BodySpec:
    """One rigid body as a particle cloud with its initial state.

    particle_position: [m], shape (n, 3), the body's own (user) frame, any origin.
    particle_mass: [kg], shape (n,).
    position: world position of the centre of mass [m], shape (3,).
    orientation_wxyz: unit quaternion, world-from-body rotation, scalar first.
    Exactly one of velocity [m/s] / momentum [kg m/s] may be given (None: at rest), and at most one of
    angular_momentum [kg m^2/s, world] / angular_velocity [rad/s, frame in angular_velocity_frame].
    """

    name: str
    particle_position: np.ndarray
    particle_mass: np.ndarray
    position: np.ndarray
    orientation_wxyz: np.ndarray
    particle_radius: np.ndarray | None = None
    velocity: np.ndarray | None = None
    momentum: np.ndarray | None = None
    angular_momentum: np.ndarray | None = None
    angular_velocity: np.ndarray | None = None
    angular_velocity_frame: str = "world"  # "world" or "body"
    location: SourceLocation | None = None
    # contact (used only when the scene has a `contact:` section)
    material: MaterialSpec = field(default_factory=MaterialSpec)
    static: bool = False  # never moves; other bodies collide with it
    # moves at its initial velocity and spins at its initial angular velocity whatever hits it (a conveyor,
    # a turning paddle): infinite mass for contact, no force acts on it
    kinematic: bool = False
    # kinematic with a prescribed motion (`kinematic: {...}`); None with `kinematic: true` (its initial velocity
    # and angular velocity, constant)
    kinematic_motion: KinematicSpec | None = None
    collide: bool = True  # False: the body passes through everything
    # where its contact spheres come from: "particles" (every particle, with its radius), "sphere" (one
    # sphere of radius contact_size at the body origin: a sphere shape's exact surface), "lattice" (the
    # surface particles of a lattice of spacing contact_size)
    contact_geometry: str = "particles"
    contact_size: float = 0.0
    # explicit contact spheres (centres [m] (k, 3) in the body's own frame, radii [m] (k,)), used instead of
    # contact_geometry: a welded body's parts keep their own spheres (scene/welds.py); None from the loader
    contact_spheres: tuple[np.ndarray, np.ndarray] | None = None
    # a box or capsule shape's exact surface, against planes in place of its lattice spheres (docs/contact.md
    # "Primitive contact"): (kind, size) in the body's own frame about its origin, kind "box" (size: half
    # extents) or "capsule" (size: radius, half-length, axis 0 / 1 / 2); None for other bodies
    contact_primitive: tuple[str, tuple[float, float, float]] | None = None


@dataclass(frozen=True)
class ForceSpec:
    """Base of the force terms declared in a scene's `forces:` list (forces issue)."""

    kind: str
    location: SourceLocation | None = None


@dataclass(frozen=True)
class SceneSpec:
    """A whole scene, validated: simulation settings, bodies, uniform gravity and force terms."""

    name: str
    simulation: SimulationSpec
    bodies: tuple[BodySpec, ...]
    gravity: np.ndarray | None = None  # [m/s^2], shape (3,), world frame
    forces: tuple[ForceSpec, ...] = ()
    contact: ContactSpec | None = None  # None: no contact stage at all
    joints: tuple[Any, ...] = ()  # scene/joint_spec.py JointSpec, one per `joints:` entry (docs/joints.md)
    source_path: str | None = None
    source_text: str = ""
    warnings: tuple[SceneIssue, ...] = ()  # non-fatal issues found while loading (e.g. a normalised quaternion)
    # the model compiled while loading (scene/compile.py CompiledModel), reused by every compile_scene of
    # this spec: it does not depend on dt or the integrator, so a scene is compiled once however it runs
    compiled_model: Any = field(default=None, compare=False, repr=False)
