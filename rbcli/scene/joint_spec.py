"""The scene's `joints:` list, validated into JointSpec (docs/joints.md).

The schema has checked the keys each type takes, the types and the ranges; this adds what it cannot
say: a body name that is not a body, a joint from a body to itself or between two `world` ends, a zero
axis, limits with lower > upper, duplicate joint names, a ball joint's cone whose half-angles are not in
(0, pi), whose twist range is not ordered within (-pi, pi), whose reference has no direction across its axis
or that limits nothing. What needs the compiled bodies (anchors that
disagree with the initial poses, a joint whose both ends are static) is checked by
scene/compile_joints.py. Every problem is located at the key at fault.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rbcli.scene.issues import IssueCollector, did_you_mean
from rbcli.scene.spec import SourceLocation
from rbcli.scene.yaml_located import YamlPath

# the name a joint's end uses for the fixed world frame
WORLD_NAME = "world"

JOINT_TYPES = ("ball", "hinge", "fixed", "slider", "distance")

# a joint axis shorter than this [1] has no direction: the scene gives it as a direction, so any length
# well above round-off is meant, and 1e-12 is far below any length a person writes
MIN_AXIS_LENGTH = 1e-12


@dataclass(frozen=True)
class JointMotor:
    """A velocity motor: drives the joint rate to `speed` [rad/s or m/s] with at most `cap` [N m or N]."""

    speed: float
    cap: float


@dataclass(frozen=True)
class JointCone:
    """A ball joint's swing cone and twist range (physics/joints/cone.py), carried by the second body (the
    world where a joint names it): axis and reference are world directions at the initial poses (unit,
    reference across the axis); swing the half-angles [rad] toward the reference and toward axis x
    reference (None: the swing is free); twist (lower, upper) [rad] about the axis (None: free)."""

    axis: np.ndarray
    reference: np.ndarray
    swing: tuple[float, float] | None = None
    twist: tuple[float, float] | None = None


@dataclass(frozen=True)
class JointSpec:
    """One joint between bodies[0] and bodies[1] (either may be WORLD_NAME, not both).

    anchor: one world point [m] at the initial poses, or None when `anchors` gives one point per end,
    each in that end's own (user particle) frame, a world point for the world [m], shape (2, 3).
    axis: hinge / slider axis, world frame at the initial poses [1] (unit), or None when `axes` gives one
    per end's frame, shape (2, 3), unit rows. length: distance joint's rod [m] (None: the anchors'
    initial distance). limits [rad or m] (lower, upper) from the initial configuration; damping
    [N m s/rad or N s/m]; motor; cone: a ball joint's swing and twist limits. locations: where each given
    key is, for compile's located errors.
    """

    name: str
    kind: str
    bodies: tuple[str, str]
    anchor: np.ndarray | None = None
    anchors: np.ndarray | None = None
    axis: np.ndarray | None = None
    axes: np.ndarray | None = None
    length: float | None = None
    limits: tuple[float, float] | None = None
    damping: float = 0.0
    motor: JointMotor | None = None
    cone: JointCone | None = None
    collide: bool = False
    location: SourceLocation | None = None
    locations: dict[str, SourceLocation] = field(default_factory=dict, compare=False, repr=False)


def _frozen(value: Any, shape: tuple[int, ...]) -> np.ndarray:
    out = np.asarray(value, dtype=np.float64).reshape(shape)
    out.flags.writeable = False
    return out


def _unit(value: Any, path: YamlPath, issues: IssueCollector) -> np.ndarray | None:
    """The direction of an axis (normalised); None with a located error for a zero one."""
    v = np.asarray(value, dtype=np.float64)
    length = float(np.linalg.norm(v))
    if not length > MIN_AXIS_LENGTH:
        issues.error(path, f"a zero axis ({length:.3g}) has no direction", "a non-zero vector")
        return None
    return v / length


def joints_from_list(
    entries: Sequence[Any],
    body_names: Sequence[str],
    issues: IssueCollector,
    clean: Any,
    taken: dict[str, YamlPath] | None = None,
) -> tuple[JointSpec, ...]:
    """JointSpecs of the `joints:` entries that passed the schema (`clean(path)`); errors go to `issues`.
    taken: joint names already given (a chain's), each with the path where it is given."""
    known = set(body_names)
    joints: list[JointSpec] = []
    first_name: dict[str, YamlPath] = dict(taken or {})
    for i, entry in enumerate(entries):
        path: YamlPath = ("joints", i)
        if not clean(path):
            continue
        joint = _joint(entry, i, path, known, issues)
        if joint is None:
            continue
        if joint.name in first_name:
            line = issues.locate(first_name[joint.name]).line
            issues.error(
                (*path, "name"),
                f"duplicate joint name '{joint.name}' (first at line {line})",
                "a unique name per joint",
            )
            continue
        first_name[joint.name] = (*path, "name") if "name" in entry else path
        joints.append(joint)
    return tuple(joints)


def _joint(
    entry: dict[str, Any], index: int, path: YamlPath, known: set[str], issues: IssueCollector
) -> JointSpec | None:
    before = issues.error_count
    kind = str(entry["type"])
    name = str(entry.get("name", f"joint{index}"))
    a, b = (str(n) for n in entry["bodies"])
    if WORLD_NAME in known and WORLD_NAME in (a, b):
        issues.error(
            (*path, "bodies"),
            f"a body is named '{WORLD_NAME}', so `{WORLD_NAME}` here is ambiguous",
            f"rename the body: '{WORLD_NAME}' names the fixed world frame in joints",
        )
    for k, body in enumerate((a, b)):
        if body != WORLD_NAME and body not in known:
            hint = did_you_mean(body, [*known, WORLD_NAME])
            guess = f" (did you mean '{hint}'?)" if hint else ""
            issues.error((*path, "bodies", k), f"no body named '{body}'{guess}", f"a body name or '{WORLD_NAME}'")
    if a == b:
        what = "both ends are the world" if a == WORLD_NAME else f"body '{a}' is jointed to itself"
        issues.error(
            (*path, "bodies"),
            f"{what}: a joint connects two different bodies",
            f"two different bodies, or one body and '{WORLD_NAME}'",
        )
    options = joint_options(entry, path, issues)
    if options is None or issues.error_count > before:
        return None
    locations = {key: issues.locate((*path, key)) for key in entry}
    return JointSpec(
        name=name,
        kind=kind,
        bodies=(a, b),
        anchor=_frozen(entry["anchor"], (3,)) if "anchor" in entry else None,
        anchors=_frozen(entry["anchors"], (2, 3)) if "anchors" in entry else None,
        length=float(entry["length"]) if "length" in entry else None,
        location=issues.locate(path),
        locations=locations,
        **options,
    )


def joint_options(entry: dict[str, Any], path: YamlPath, issues: IssueCollector) -> dict[str, Any] | None:
    """JointSpec's axis, axes, limits, damping, motor, cone and collide from a schema-valid joint mapping at `path`
    (a `joints:` entry, or a chain's `joint:`, whose options every joint of the chain takes); None with a
    located error for a zero axis, limits with lower > upper or a cone that cannot be (`_cone`)."""
    before = issues.error_count
    axis = axes = None
    if "axis" in entry:
        axis = _unit(entry["axis"], (*path, "axis"), issues)
    if "axes" in entry:
        units = [_unit(v, (*path, "axes", k), issues) for k, v in enumerate(entry["axes"])]
        axes = None if any(u is None for u in units) else np.array(units)
    limits = None
    if "limits" in entry:
        lower, upper = (float(v) for v in entry["limits"])
        if lower > upper:
            issues.error(
                (*path, "limits"),
                f"lower limit {lower:g} is above upper limit {upper:g}",
                "limits: [lower, upper] with lower <= upper",
            )
        limits = (lower, upper)
    motor = None
    if "motor" in entry:
        value = entry["motor"]
        cap = value.get("max_torque", value.get("max_force"))
        motor = JointMotor(float(value["speed"]), float(cap))
    cone = _cone(entry["cone"], (*path, "cone"), issues) if "cone" in entry else None
    if issues.error_count > before:
        return None
    return dict(
        cone=cone,
        axis=None if axis is None else _frozen(axis, (3,)),
        axes=None if axes is None else _frozen(axes, (2, 3)),
        limits=limits,
        damping=float(entry.get("damping", 0.0)),
        motor=motor,
        collide=bool(entry.get("collide", False)),
    )


def _reference(axis: np.ndarray) -> np.ndarray:
    """The default reference of a cone about `axis` (unit): the first of the world's x, y, z least parallel
    to the axis, made perpendicular to it (Gram-Schmidt)."""
    e = np.eye(3)[int(np.argmin(np.abs(axis)))]
    across = e - (e @ axis) * axis
    return across / np.linalg.norm(across)


def _cone(value: dict[str, Any], path: YamlPath, issues: IssueCollector) -> JointCone | None:
    """A ball joint's `cone:` mapping (schema-valid) as a JointCone; None with located errors for a zero
    axis, a reference along the axis, half-angles outside (0, pi), a twist range not ordered within
    (-pi, pi), or a cone that gives neither swing nor twist."""
    before = issues.error_count
    axis = _unit(value["axis"], (*path, "axis"), issues)
    reference = None
    if axis is not None:
        reference = _reference(axis)
        if "reference" in value:
            given = np.asarray(value["reference"], dtype=np.float64)
            across = given - (given @ axis) * axis
            size = float(np.linalg.norm(given))
            if not float(np.linalg.norm(across)) > 1e-9 * size or not size > MIN_AXIS_LENGTH:
                issues.error(
                    (*path, "reference"),
                    "the reference has no direction across the axis",
                    "a non-zero vector not parallel to the axis (its part across the axis is used)",
                )
            else:
                reference = across / np.linalg.norm(across)
    swing = None
    if "swing" in value:
        raw = value["swing"]
        angles = [float(raw)] * 2 if isinstance(raw, int | float) else [float(v) for v in raw]
        for k, angle in enumerate(angles):
            if not 0.0 < angle < np.pi:
                where = (*path, "swing") if isinstance(raw, int | float) else (*path, "swing", k)
                issues.error(where, f"swing half-angle {angle:g} rad is not in (0, pi)",
                             "a half-angle between 0 and pi (exclusive): a cone that closes neither to its axis "
                             "nor past a half-space")  # fmt: skip
        swing = (angles[0], angles[1])
    twist = None
    if "twist" in value:
        lower, upper = (float(v) for v in value["twist"])
        for k, angle in enumerate((lower, upper)):
            if not -np.pi < angle < np.pi:
                issues.error(
                    (*path, "twist", k),
                    f"twist limit {angle:g} rad is not in (-pi, pi)",
                    "twist limits strictly between -pi and pi (the twist angle is measured in [-pi, pi])",
                )
        if lower > upper:
            issues.error((*path, "twist"), f"lower twist limit {lower:g} is above upper twist limit {upper:g}",
                         "twist: [lower, upper] with lower <= upper")  # fmt: skip
        twist = (lower, upper)
    if swing is None and twist is None:
        issues.error(
            path,
            "the cone gives neither `swing` nor `twist`: it limits nothing",
            "swing: a half-angle or [toward the reference, across it], and/or twist: [lower, upper]",
        )
    if issues.error_count > before or axis is None or reference is None:
        return None
    return JointCone(_frozen(axis, (3,)), _frozen(reference, (3,)), swing, twist)


LOOP_EXPECTED = "a loop on a maximal integrator (split2 with RATTLE holds loops), or a tree"


def tree_refusals(bodies: Sequence[Any], joints: Sequence[JointSpec]) -> list[tuple[int, str, str, str | None]]:
    """Why the joints cannot run in joint coordinates (scene/compile_trees.py), from the scene's names:
    (joint index, the key at fault, the reason, what is expected instead or None for the default advice),
    empty where they form trees. First a distance joint or a kinematic body at either end; where there is
    none, each joint that closes a loop (static bodies and the world are one vertex, the ground: two joints
    to it close one), found by union-find in the joints' order. bodies: BodySpec (name, static, kinematic)."""
    ground = {WORLD_NAME} | {b.name for b in bodies if b.static}
    kinematic = {b.name for b in bodies if b.kinematic}
    refusals: list[tuple[int, str, str, str | None]] = []
    for j, joint in enumerate(joints):
        if joint.kind == "distance":
            refusals.append((j, "type", "a distance joint is a constraint between two links, not a tree's joint", None))
        elif kinematic.intersection(joint.bodies):
            refusals.append((j, "bodies", "a kinematic body in a tree is not modelled yet", None))
    if refusals:
        return refusals
    root = {b.name: b.name for b in bodies}
    root[WORLD_NAME] = WORLD_NAME

    def find(name: str) -> str:
        name = WORLD_NAME if name in ground else name
        while root[name] != name:
            root[name] = root[root[name]]
            name = root[name]
        return name

    for j, joint in enumerate(joints):
        a, b = find(joint.bodies[0]), find(joint.bodies[1])
        if a == b:
            grounded = bool(ground.intersection(joint.bodies)) or find(WORLD_NAME) == a
            through = "the ground (two joints to the world or static bodies)" if grounded else "its bodies"
            reason = f"it closes a loop through {through}: a tree has one path from each body to its root"
            refusals.append((j, "bodies", reason, LOOP_EXPECTED))
            continue
        root[a] = b
    return refusals


def joints_form_trees(bodies: Sequence[Any], joints: Sequence[JointSpec], limit_rows: int) -> bool:
    """Whether the scene's joints can run in joint coordinates: no `tree_refusals`, and at most
    `limit_rows` limit and motor rows (counted two per joint that has limits, a cone or a motor: a bound
    above the table's). Decided on the scene's names alone, before compiling, where welds are not merged
    yet: a loop of welds alone (one body when compiled) counts as a loop, so a scene this accepts always
    compiles to trees."""
    rows = sum(2 for joint in joints if joint.limits is not None or joint.motor is not None or joint.cone is not None)
    return rows <= limit_rows and not tree_refusals(bodies, joints)
