"""Compile a scene's JointSpecs into the JointTable (physics/joints/tables.py), once, with located errors.

Anchors and axes given in a body's user frame become principal-frame offsets about its centre of mass,
r = E^T (p_user - centre_user), u = E^T u_user (E = user-from-principal, as compile_forces.py does);
given as one world point / world axis at the initial poses they become r = R0^T (p - x0), u = R0^T u
for each end (R0 world-from-principal at t = 0). What only the compiled bodies show is refused here,
located at the key at fault: anchors or axes that disagree with the initial poses (saying by how
much), a joint whose both ends are static (or static and the world), and hinge limits past a half turn.
Contact: the compiled ContactTable skips the pairs of jointed bodies (scene/compile.py `_jointed_pairs`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from rbcli.physics.joints.tables import JOINT_KINDS, WORLD, JointTable, joint_table
from rbcli.physics.model import Model
from rbcli.physics.rotation import matrix_to_quat, quat_conjugate, quat_multiply, quat_to_matrix
from rbcli.physics.state import State
from rbcli.scene.joint_spec import WORLD_NAME, JointSpec
from rbcli.scene.spec import BodySpec, SceneError, SceneIssue, SourceLocation

# anchors that miss each other by more than this fraction of the bodies' size (at least 1 m: a tiny
# body's anchors are still read to ~1e-16 m) were not meant to coincide; 1e-9 leaves room for anchors
# written with 10 significant digits, and is far below any offset a person means
ANCHOR_TOLERANCE = 1e-9
# axes given per body that differ by more than this [rad] at the initial poses were not meant as one
AXIS_TOLERANCE = 1e-9


class _Frames(NamedTuple):
    """Every body's rotations at t = 0, shape (body_count, 3, 3): world-from-principal R and
    user-from-principal E; and its size [m], shape (body_count,) (_body_sizes)."""

    R: np.ndarray
    E: np.ndarray
    size: np.ndarray


class _Invalid(Exception):
    def __init__(self, key: str, message: str, expected: str = ""):
        super().__init__(message)
        self.key, self.expected = key, expected


def compile_joints(
    joints: Sequence[JointSpec],
    bodies: Sequence[BodySpec],
    model: Model,
    centres_user: np.ndarray,
    state: State,
    *,
    has_contact: bool,
) -> JointTable | None:
    """The JointTable of a scene's joints (None without joints); SceneError listing every invalid joint."""
    if not joints:
        return None
    ground = np.array([b.static or b.kinematic for b in bodies], dtype=np.bool_)
    index = {b.name: i for i, b in enumerate(bodies)}
    rows: dict[str, list] = {
        k: []
        for k in ("kind", "body_a", "body_b", "anchor_a", "anchor_b", "axis_a", "normal_b", "end_q", "length",
                  "damping", "motor_speed", "motor_cap", "limit_lower", "limit_upper", "reference_a", "travel0",
                  "cone_frame_a", "cone_frame_b", "swing_limit")
    }  # fmt: skip
    # the joints refused, by (place, reason): a generated chain's joints share their place in the file, and
    # one reason refusing all 5,000 of them is one issue that says how many
    refused: dict[tuple[SourceLocation | None, str, str], list[str]] = {}
    frames = _Frames(quat_to_matrix(state.q), quat_to_matrix(model.body_frame_q), _body_sizes(model))  # once
    for joint in joints:
        try:
            for key, value in _joint_row(joint, index, ground, model, centres_user, state, frames).items():
                rows[key].append(value)
        except _Invalid as exc:
            refused.setdefault((joint.locations.get(exc.key, joint.location), str(exc), exc.expected), []).append(
                joint.name
            )
    end_q = np.array(rows.pop("end_q")).reshape(-1, 2, 4)  # (q_b, q_a) per joint: one product for them all
    rows["relative_q"] = list(quat_multiply(quat_conjugate(end_q[:, 0]), end_q[:, 1]))
    if refused:
        raise SceneError([
            SceneIssue(where, f"joint '{names[0]}': {reason}" + (f" (and {len(names) - 1:,} more joints given "
                       "here)" if len(names) > 1 else ""), expected)
            for (where, reason, expected), names in refused.items()
        ])  # fmt: skip
    return joint_table(**rows, body_ground=ground)


def _unsupported(joint: JointSpec) -> None:
    """Refuse what the joint stages do not hold yet, rather than ignore it (docs/joints.md, next)."""
    if joint.kind == "hinge" and joint.limits is not None and not -np.pi < joint.limits[0] <= joint.limits[1] < np.pi:
        raise _Invalid("limits", f"hinge limits {list(joint.limits)} rad reach past a half turn (the angle is "
                       "measured in (-pi, pi))", "hinge limits strictly between -pi and pi")  # fmt: skip


def _joint_row(
    joint: JointSpec,
    index: dict[str, int],
    ground: np.ndarray,
    model: Model,
    centres: np.ndarray,
    state: State,
    frames: _Frames,
) -> dict[str, object]:
    _unsupported(joint)
    ends = [WORLD if name == WORLD_NAME else index[name] for name in joint.bodies]
    anchors = None if joint.anchors is None else [np.asarray(p, dtype=np.float64) for p in joint.anchors]
    axes = None if joint.axes is None else [np.asarray(u, dtype=np.float64) for u in joint.axes]
    if ends[0] == WORLD:  # body a is never the world: swap the ends (and what is given per end)
        ends.reverse()
        anchors = anchors[::-1] if anchors is not None else None
        axes = axes[::-1] if axes is not None else None
    a, b = ends
    if ground[a] and (b == WORLD or ground[b]):
        what = "the world" if b == WORLD else "a static or kinematic body"
        raise _Invalid(
            "bodies",
            f"both ends are fixed (a static or kinematic body and {what}): the joint holds nothing",
            "at least one end a moving (dynamic) body",
        )
    R, E, sizes = frames

    def to_body(end: int, world_vector: np.ndarray, point: bool) -> np.ndarray:
        if end == WORLD:
            return world_vector
        return R[end].T @ (world_vector - state.x[end]) if point else R[end].T @ world_vector

    def from_user(end: int, user: np.ndarray, point: bool) -> np.ndarray:
        if end == WORLD:
            return user
        return E[end].T @ (user - centres[end]) if point else E[end].T @ user

    def world_point(end: int, r: np.ndarray) -> np.ndarray:
        return r if end == WORLD else state.x[end] + R[end] @ r

    def world_vector(end: int, u: np.ndarray) -> np.ndarray:
        return u if end == WORLD else R[end] @ u

    if joint.anchor is not None:
        anchor_a, anchor_b = to_body(a, joint.anchor, True), to_body(b, joint.anchor, True)
    else:
        assert anchors is not None  # the schema requires anchor or anchors
        anchor_a, anchor_b = from_user(a, anchors[0], True), from_user(b, anchors[1], True)
    p_a, p_b = world_point(a, anchor_a), world_point(b, anchor_b)
    kind = JOINT_KINDS[joint.kind]
    axis_a, normals = np.array([1.0, 0.0, 0.0]), np.zeros((2, 3))
    if joint.kind in ("hinge", "slider"):
        if joint.axis is not None:
            axis_a, axis_b = to_body(a, joint.axis, False), to_body(b, joint.axis, False)
        else:
            assert axes is not None  # the schema requires axis or axes
            axis_a, axis_b = from_user(a, axes[0], False), from_user(b, axes[1], False)
            u_a, u_b = world_vector(a, axis_a), world_vector(b, axis_b)
            angle = float(np.arctan2(np.linalg.norm(_cross(u_a, u_b)), np.dot(u_a, u_b)))
            if angle > AXIS_TOLERANCE:
                raise _Invalid(
                    "axes",
                    f"the axes are {angle:.3g} rad apart at the initial poses",
                    "axes that are the same world direction at the initial poses (or one `axis`)",
                )
        normals = _normals(axis_b)
    offset = p_a - p_b
    if joint.kind == "slider":  # only the offset across the axis must vanish: along it is the slider's travel
        u = world_vector(b, normals[0]), world_vector(b, normals[1])
        offset = np.array([offset @ u[0], offset @ u[1], 0.0])
    size = max(1.0, *(float(sizes[end]) for end in (a, b) if end != WORLD))
    length = 0.0
    if joint.kind == "distance":
        length = float(np.linalg.norm(p_a - p_b))
        if joint.length is not None and abs(joint.length - length) > ANCHOR_TOLERANCE * size:
            raise _Invalid(
                "length",
                f"the anchors are {length:.6g} m apart at the initial poses, the rod is {joint.length:.6g} m",
                "a length equal to the anchors' initial distance (or none)",
            )
        if not length > ANCHOR_TOLERANCE * size:
            raise _Invalid(
                "anchors",
                "the anchors coincide at the initial poses: a rod of length 0 has no direction",
                "anchors apart (a ball joint holds coinciding points)",
            )
    else:
        miss = float(np.linalg.norm(offset))
        if miss > ANCHOR_TOLERANCE * size:
            across = " across the axis" if joint.kind == "slider" else ""
            raise _Invalid(
                "anchors",
                f"anchors are {miss:.3g} m apart{across} at the initial poses",
                "anchors that are the same world point at the initial poses (or one `anchor`)",
            )
    q_b = np.array([1.0, 0.0, 0.0, 0.0]) if b == WORLD else state.q[b]
    motor = joint.motor
    reference = np.zeros(3)
    travel0 = 0.0
    if joint.kind == "hinge":  # n_b1 at the initial poses, in a's frame: the angle's zero
        reference = R[a].T @ world_vector(b, normals[0])
    if joint.kind == "slider":
        travel0 = float((p_a - p_b) @ world_vector(b, _cross(normals[0], normals[1])))
    lower, upper = joint.limits if joint.limits is not None else (-np.inf, np.inf)
    frame_a = frame_b = np.array([1.0, 0.0, 0.0, 0.0])
    swing = (0.0, 0.0)
    if joint.cone is not None:  # the joint frame (axis, reference, axis x reference) in each end's frame
        cone = joint.cone
        F = matrix_to_quat(np.column_stack([cone.axis, cone.reference, _cross(cone.axis, cone.reference)]))
        frame_a = quat_multiply(quat_conjugate(state.q[a]), F)
        frame_b = F if b == WORLD else quat_multiply(quat_conjugate(state.q[b]), F)
        swing = cone.swing if cone.swing is not None else swing
        lower, upper = cone.twist if cone.twist is not None else (lower, upper)
    return dict(
        cone_frame_a=frame_a,
        cone_frame_b=frame_b,
        swing_limit=swing,
        limit_lower=lower,
        limit_upper=upper,
        reference_a=reference,
        travel0=travel0,
        damping=joint.damping,
        motor_speed=0.0 if motor is None else motor.speed,
        motor_cap=0.0 if motor is None else motor.cap,
        kind=kind,
        body_a=a,
        body_b=b,
        anchor_a=anchor_a,
        anchor_b=anchor_b,
        axis_a=axis_a / np.linalg.norm(axis_a),
        normal_b=normals,
        end_q=(q_b, state.q[a]),  # relative_q = q_b^* q_a, computed for every joint at once
        length=length,
    )


def _normals(axis: np.ndarray) -> np.ndarray:
    """Two unit vectors perpendicular to `axis` and to each other (2, 3)."""
    u = axis / np.linalg.norm(axis)
    helper = np.eye(3)[int(np.argmin(np.abs(u)))]  # the basis vector least parallel to u
    n1 = _cross(u, helper)
    n1 /= np.linalg.norm(n1)
    return np.array([n1, _cross(u, n1)])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a x b of two 3-vectors, in np.cross's operations (the same bits) without its ~40 us of axis
    handling per call: a scene compiles a few per joint, and a generated chain has thousands of joints."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _body_sizes(model: Model) -> np.ndarray:
    """Each body's largest particle distance from its centre of mass [m] (its size for tolerances), shape
    (body_count,); 0 for a body without particles."""
    sizes = np.zeros(model.body_particle_count.shape[0])
    filled = model.body_particle_count > 0
    if np.any(filled):
        distance = np.linalg.norm(model.particle_offset, axis=1)
        sizes[filled] = np.maximum.reduceat(distance, model.body_particle_start[filled])
    return sizes


# the dense check of loops builds A = G W G^T densely (R^2 floats, R^3 flops): 3,000 rows is 72 MB, ~1 s
_DENSE_CHECK_ROWS = 3000


def redundant_row_warnings(joints: Sequence[JointSpec], table: JointTable | None, model: Model,
                           state: State) -> list[SceneIssue]:  # fmt: skip
    """A warning per joint that has rows repeating constraints of earlier joints (a loop that holds a
    direction twice, as a planar four-bar of spatial hinges does: 3 rows), found as the solver finds them
    (the zero pivots of A = G W G^T at the initial poses, rows in joint order): they are dropped with
    multiplier 0 each step, and the loop still closes."""
    if table is None or not np.any(table.graph.joint_node < 0):
        return []  # no loop: a tree's rows are independent (each joint's own rows are, by construction)
    if int(table.row_count.sum()) > _DENSE_CHECK_ROWS:
        return []  # too many rows for the dense check; the solver still drops redundant rows each step
    from rbcli.physics.joints.dense_layout import redundant_rows_numpy
    from rbcli.physics.joints.reference import (
        body_weights_numpy,
        joint_rows_numpy,
        rows_matrix_numpy,
        weight_matrix_numpy,
    )

    _, ga, gb = joint_rows_numpy(table, state.x, state.q)
    G = rows_matrix_numpy(table, ga, gb, state.x.shape[0])
    A = G @ weight_matrix_numpy(*body_weights_numpy(model, table, state.q)) @ G.T
    dropped = redundant_rows_numpy(A)
    owner = np.searchsorted(table.row_start, dropped, side="right") - 1
    issues = []
    for j in np.unique(owner):
        rows = [int(r - table.row_start[j]) for r in dropped[owner == j]]
        joint = joints[int(j)]
        others = ", ".join(repr(joints[int(k)].name) for k in range(int(j)))
        listed = ", ".join(map(str, rows))
        issues.append(SceneIssue(
            joint.location,
            f"joint '{joint.name}': {len(rows)} of its {int(table.row_count[j])} rows (rows {listed}) repeat "
            f"constraints of earlier joints ({others}): a loop that holds a "
            "direction twice; they are dropped (multiplier 0) and the loop still closes",
            "a loop whose joints leave its free directions free (e.g. ball joints instead of hinges at one end)",
            severity="warning",
        ))  # fmt: skip
    return issues
