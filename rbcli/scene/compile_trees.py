"""The articulated trees of a scene run in joint coordinates (a reduced integrator, docs/trees.md): the
compiled JointTable's joints and the dynamic bodies become a TreeTable (physics/tree/table.py), with
located errors for what the trees do not hold.

Every dynamic body is a link. The joints' graph over the dynamic bodies (static bodies and the world one
vertex, "the ground") splits into components:
- a component with one joint to the ground is a tree rooted there (its root link's joint is that one);
- a component with none floats: its heaviest body is the root, on a free joint (6 rates: its pose);
- a body no joint holds is a one-link tree on a free joint.
A component with more joints than a tree has (a loop, or two joints to the ground) is refused at the
joint that closes the loop: loops stay with the maximal integrators (split2 and RATTLE). So are what the
trees do not model yet: distance joints, kinematic bodies in a tree. A joint's damper
becomes a damper on each of its rates (integrate.py); its limits, cone and motor become rows on its
coordinate (physics/tree/limits.py, `_limit_rows`). Links are numbered breadth
first from each root, so parents come first.

Joint frames. A joint joins body_a and body_b of the JointTable at anchor_a, anchor_b (principal frames
about the centres of mass; a world point for the world). The child is the end farther from the root:
its anchor and axis are anchor_child and axis (an axis given in body_a's frame is turned into body_b's
at the initial poses where b is the child: a hinge's axis is fixed in both), the parent's anchor is
anchor_parent (a static parent's turned into a world point). rest_q = q_parent0^* q_child0, so every
coordinate is zero at the initial poses (angles and travels measured from there, as the maximal
joints' limits are); the child's anchor is moved by the anchors' initial offset (zero but for a slider's
initial travel and round-off), so the initial poses are exactly the trees' zero.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

import numpy as np

from rbcli.physics.joints.tables import (
    JOINT_BALL,
    JOINT_FIXED,
    JOINT_HINGE,
    JOINT_SLIDER,
    WORLD,
    JointTable,
)
from rbcli.physics.model import Model
from rbcli.physics.rotation import quat_conjugate, quat_multiply, quat_to_matrix
from rbcli.physics.state import State
from rbcli.physics.tree.table import (
    LIMIT_COORD,
    LIMIT_SWING,
    LIMIT_TWIST,
    MAX_LIMIT_ROWS,
    MOTOR,
    TREE_DOFS,
    TREE_FREE,
    TreeTable,
    tree_table,
)
from rbcli.scene.joint_spec import JointSpec, tree_refusals
from rbcli.scene.spec import BodySpec, SceneError, SceneIssue, SourceLocation

GROUND = -1  # the world and every static body: one vertex of the joints' graph
REDUCED = "reduced-euler, reduced-rk4, reduced-implicit"
MAXIMAL = "a maximal integrator (split2) for this scene, or the joint without it"


def compile_trees(
    model: Model,
    state: State,
    bodies: Sequence[BodySpec],
    joints: Sequence[JointSpec],
) -> TreeTable:
    """The TreeTable of the scene compiled as `model` (its JointTable, None without joints), at its initial
    state; `bodies` and `joints` are the simulated scene's (welds merged), in the model's order, for the
    errors' locations. SceneError lists every joint refused."""
    table = model.joint
    static = np.array([b.static for b in bodies], dtype=bool)
    kinematic = np.array([b.kinematic for b in bodies], dtype=bool)
    issues: list[SceneIssue] = []

    def refuse(j: int, key: str, reason: str, expected: str = MAXIMAL) -> None:
        spec = joints[j]
        where: SourceLocation | None = spec.locations.get(key, spec.location)
        issues.append(SceneIssue(where, f"joint '{spec.name}': {reason} (in joint coordinates, {REDUCED})",
                                 expected))  # fmt: skip

    # what the trees do not hold (joint_spec.tree_refusals: the same rules the loader's default applies)
    for j, key, reason, expected in tree_refusals(bodies, joints):
        refuse(j, key, reason, expected or MAXIMAL)
    if issues:
        raise SceneError(issues)
    n_bodies = model.body_count

    def vertex(body: int) -> int:
        return GROUND if body == WORLD or static[body] else body

    adjacency: dict[int, list[tuple[int, int]]] = {v: [] for v in [GROUND, *range(n_bodies)]}
    for j in range(0 if table is None else table.kind.shape[0]):
        assert table is not None
        a, b = vertex(int(table.body_a[j])), vertex(int(table.body_b[j]))
        adjacency[a].append((b, j))
        adjacency[b].append((a, j))

    # breadth first from the ground, then from each floating component's heaviest body
    order: list[tuple[int, int, int]] = []  # (body, parent body or GROUND, joint or -1 for a free root)
    seen = {GROUND}
    queue: deque[int] = deque([GROUND])
    dynamic = [v for v in range(n_bodies) if not (static[v] or kinematic[v])]

    def sweep() -> None:
        while queue:
            v = queue.popleft()
            for w, j in sorted(adjacency[v], key=lambda edge: edge[1]):
                if w not in seen:
                    seen.add(w)
                    order.append((w, v, j))
                    queue.append(w)

    sweep()
    # the floating components (no joint to the ground): each dynamic body not reached, labelled by a walk
    component: dict[int, int] = {}
    for v in dynamic:
        if v in seen or v in component:
            continue
        component[v], stack = v, [v]
        while stack:
            for w, _ in adjacency[stack.pop()]:
                if w != GROUND and w not in component:
                    component[w] = v
                    stack.append(w)
    components: dict[int, list[int]] = {}
    for v in dynamic:
        if v not in seen:
            components.setdefault(component[v], []).append(v)
    for members in sorted(components.values(), key=lambda m: min(m)):
        heaviest = max(members, key=lambda v: (float(model.body_mass[v]), -v))
        seen.add(heaviest)
        order.append((heaviest, GROUND, -1))
        queue.append(heaviest)
        sweep()

    link_of = {body: i for i, (body, _, _) in enumerate(order)}
    n = len(order)
    R0 = quat_to_matrix(state.q)
    parent = np.full(n, -1, dtype=np.int64)
    link_kind = np.zeros(n, dtype=np.int64)
    anchor_parent, anchor_child, axis = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, 3))
    rest_q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    for i, (child, parent_vertex, j) in enumerate(order):
        if j < 0:
            link_kind[i] = TREE_FREE
            continue
        assert table is not None
        link_kind[i] = int(table.kind[j])
        a, b = int(table.body_a[j]), int(table.body_b[j])
        child_anchor, other_anchor = (
            (table.anchor_a[j], table.anchor_b[j]) if child == a else (table.anchor_b[j], table.anchor_a[j])
        )
        other = b if child == a else a
        if link_kind[i] in (JOINT_HINGE, JOINT_SLIDER):  # the axis in the child's principal frame
            axis[i] = table.axis_a[j] if child == a else R0[b].T @ (R0[a] @ table.axis_a[j])
        if parent_vertex == GROUND:
            parent[i] = -1
            # a world point (static bodies never move); rest_q from the world's frame
            world_anchor = other_anchor if other == WORLD else state.x[other] + R0[other] @ other_anchor
            anchor_parent[i] = world_anchor
            rest_q[i] = state.q[child]
            parent_point = world_anchor
        else:
            parent[i] = link_of[parent_vertex]
            anchor_parent[i] = other_anchor
            rest_q[i] = quat_multiply(quat_conjugate(state.q[parent_vertex]), state.q[child])
            parent_point = state.x[parent_vertex] + R0[parent_vertex] @ other_anchor
        # the child's anchor moved onto the parent's at the initial poses (a slider's initial travel)
        offset = state.x[child] + R0[child] @ child_anchor - parent_point
        anchor_child[i] = child_anchor - R0[child].T @ offset
        assert link_kind[i] in (JOINT_HINGE, JOINT_SLIDER, JOINT_BALL, JOINT_FIXED)
    body = np.array([v for v, _, _ in order], dtype=np.int64)
    joint = np.array([j for _, _, j in order], dtype=np.int64)
    side = np.array([0 if j < 0 or table is None else (1 if int(table.body_a[j]) == v else -1) for v, _, j in order],
                    dtype=np.int64)  # fmt: skip
    # a joint's damper on each of its rates (a ball's on its relative spin: the same c on all three)
    damping = np.concatenate([
        np.full(TREE_DOFS[int(k)], float(table.damping[j]) if j >= 0 and table is not None else 0.0)
        for k, j in zip(link_kind.tolist(), joint.tolist(), strict=True)
    ]) if n else np.zeros(0)  # fmt: skip
    limit_index, limit_data = _limit_rows(table, state, static, order, side, rest_q)
    if len(limit_index) > MAX_LIMIT_ROWS:
        assert table is not None
        refuse(int(order[limit_index[MAX_LIMIT_ROWS][0]][2]), "limits",
               f"more than {MAX_LIMIT_ROWS} limits and motors in one scene's trees")  # fmt: skip
        raise SceneError(issues)
    return tree_table(parent, link_kind, anchor_parent, anchor_child, axis, rest_q, model.body_mass[body],
                      model.body_inertia[body], body=body, joint=joint, damping=damping, joint_side=side,
                      limit_index=limit_index, limit_data=limit_data)  # fmt: skip


def _limit_rows(
    table: JointTable | None,
    state: State,
    static: np.ndarray,
    order: list[tuple[int, int, int]],
    side: np.ndarray,
    rest_q: np.ndarray,
) -> tuple[list[list[int]], list[np.ndarray]]:
    """The trees' limit and motor rows (physics/tree/limits.py) of each link's joint: a hinge's or
    slider's limits and motor in the tree's sign of its coordinate (negated where the link is body_b),
    a ball joint's twist limits and cone with the constant quaternions A, B of Q = A u B (side +1) or
    A u^* B (side -1): with f_a, f_b the joint frames on body_a and body_b and K the orientation of the
    joint's other end where it is the ground (a static body's; 1 for the world or a parent link),
    A = (K f_b)^* rest_q, B = f_a (side +1), A = f_b^*, B = rest_q^* K f_a (side -1)."""
    index: list[list[int]] = []
    data: list[np.ndarray] = []
    if table is None:
        return index, data
    identity = np.array([1.0, 0.0, 0.0, 0.0])

    def row(link: int, sign: float, row_kind: int, low: float, high: float, cap: float = np.inf,
            A: np.ndarray = identity, B: np.ndarray = identity, half_angles: tuple[float, float] = (0.0, 0.0),
            ) -> None:  # fmt: skip
        index.append([link, row_kind])
        data.append(np.concatenate([[low, high, cap], A, B, half_angles, [sign]]))

    for i, (_, parent_vertex, j) in enumerate(order):
        if j < 0:
            continue
        kind, sign = int(table.kind[j]), float(side[i])
        lower, upper = float(table.limit_lower[j]), float(table.limit_upper[j])

        if kind in (JOINT_HINGE, JOINT_SLIDER):
            if np.isfinite(lower) or np.isfinite(upper):
                row(i, sign, LIMIT_COORD, lower, upper) if sign > 0 else row(i, sign, LIMIT_COORD, -upper, -lower)
            if table.motor_cap[j] != 0.0:
                speed = sign * float(table.motor_speed[j])
                row(i, sign, MOTOR, speed, speed, float(table.motor_cap[j]))
        elif kind == JOINT_BALL and (np.isfinite(lower) or np.isfinite(upper) or np.any(table.cone[j, 8:10])):
            f_a, f_b = table.cone[j, 0:4], table.cone[j, 4:8]
            other = int(table.body_b[j]) if sign > 0 else int(table.body_a[j])
            K = state.q[other] if parent_vertex == GROUND and other != WORLD and static[other] else identity
            if sign > 0:
                A, B = quat_multiply(quat_conjugate(quat_multiply(K, f_b)), rest_q[i]), f_a
            else:
                A, B = quat_conjugate(f_b), quat_multiply(quat_conjugate(rest_q[i]), quat_multiply(K, f_a))
            if np.isfinite(lower) or np.isfinite(upper):
                row(i, sign, LIMIT_TWIST, lower, upper, A=A, B=B)
            if np.any(table.cone[j, 8:10]):
                half_angles = (float(table.cone[j, 8]), float(table.cone[j, 9]))
                row(i, sign, LIMIT_SWING, -np.inf, 1.0, A=A, B=B, half_angles=half_angles)
    return index, data
