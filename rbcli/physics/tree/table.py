"""The tree table (read-only: the links of articulated trees in joint coordinates) and its work arrays.

A tree is a loop-free set of links, each joined to its parent (or to the world, parent -1) by one joint
(docs/trees.md). Links are numbered in topological order, parent[i] < i, so one sweep up the array
visits every parent before its children and one sweep down every child before its parent. Several trees
may share one table (several roots).

Frames. Link i's frame is its body frame: origin at its centre of mass, axes its principal axes (as
physics/model.py), so its spatial inertia there is diag(I1, I2, I3, m, m, m). Joint i joins parent p and
link i at one point, `anchor_parent` in p's frame (a world point for the world) and `anchor_child` in i's;
`rest_q` is the rotation p-from-i when the joint's coordinate is zero, and `axis` a unit vector in i's
frame. The joint's coordinate (in `coord`, at coord_start[i]) and rate (in `rate`, at dof_start[i]):

    fixed   none              R_rel = R(rest_q)
    hinge   angle [rad]       R_rel = R(rest_q) Rot(axis, angle); rate: d angle / dt
    slider  travel [m]        R_rel = R(rest_q), link i's anchor moved by travel along axis; d travel / dt
    ball    unit quaternion   R_rel = R(rest_q) R(u), u (w, x, y, z); rate: link i's angular velocity
                              relative to p, in i's frame (3), du/dt = u (0, omega) / 2
    free    x (3), q (4)      a root only: link i's world centre of mass and orientation (its body pose);
                              rate (omega, v) (6): its angular velocity and centre-of-mass velocity in its
                              own frame (anchors and rest_q unused)

R_rel is p-from-i; link i's origin lies at r = anchor_parent + R_rel (travel axis - anchor_child) in p's
frame (travel 0 but for the slider). Spatial vectors are Featherstone's, angular part first, at the link's
origin in the link's coordinates; the joint's motion subspace S (motion, (dof_count, 6), one row per
rate) is then constant: hinge (a, c x a), slider (0, a), ball (e_k, c x e_k), free the identity, with a the
axis and c the anchor in i's frame.

Joint kinds share physics/joints/tables.py's codes (a scene's JointTable compiles to a tree table), and
TREE_FREE is the free root's. This module imports numpy only.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rbcli.physics.joints.tables import JOINT_BALL, JOINT_FIXED, JOINT_HINGE, JOINT_SLIDER
from rbcli.physics.table_arrays import frozen_floats, frozen_ints

TREE_FREE = 5
TREE_KINDS = {"fixed": JOINT_FIXED, "hinge": JOINT_HINGE, "slider": JOINT_SLIDER, "ball": JOINT_BALL, "free": TREE_FREE}
TREE_COORDS = {JOINT_FIXED: 0, JOINT_HINGE: 1, JOINT_SLIDER: 1, JOINT_BALL: 4, TREE_FREE: 7}
TREE_DOFS = {JOINT_FIXED: 0, JOINT_HINGE: 1, JOINT_SLIDER: 1, JOINT_BALL: 3, TREE_FREE: 6}
SYM6 = 21  # entries of a symmetric 6 x 6 matrix stored packed (upper triangle, row by row)


def sym6_index(r: int, c: int) -> int:
    """Position of entry (r, c) of a symmetric 6 x 6 matrix in its packed upper triangle."""
    r, c = min(r, c), max(r, c)
    return r * 6 - r * (r - 1) // 2 + c - r


# (6, 6) -> packed index, for the kernels' general (ball, free) paths
SYM6_INDEX = np.array([[sym6_index(r, c) for c in range(6)] for r in range(6)], dtype=np.int64)
SYM6_INDEX.setflags(write=False)


class TreeTable(NamedTuple):
    """The links of articulated trees (see the module docstring); read-only arrays over links n, joint
    coordinates C and rates (degrees of freedom) D."""

    parent: np.ndarray  # int64 (n,): parent link, -1 for the world; parent[i] < i
    kind: np.ndarray  # int64 (n,): JOINT_FIXED, JOINT_HINGE, JOINT_SLIDER, JOINT_BALL or TREE_FREE
    body: np.ndarray  # int64 (n,): the link's row in the state arrays (x, q, P, L, F, tau)
    joint: np.ndarray  # int64 (n,): the scene's joint (JointTable row) that joins the link to its parent; -1: none
    anchor_parent: np.ndarray  # [m] (n, 3): the joint point in the parent's frame (world for -1)
    anchor_child: np.ndarray  # [m] (n, 3): the joint point in the link's frame
    axis: np.ndarray  # [1] (n, 3): unit hinge / slider axis, link frame
    rest_q: np.ndarray  # (n, 4) wxyz: parent-from-link rotation at coordinate 0
    rest_axis_q: np.ndarray  # (n, 4) wxyz: rest_q (0, axis), so a hinge's R_rel = cos(t/2) rest_q + sin(t/2) this
    mass: np.ndarray  # [kg] (n,)
    inertia: np.ndarray  # [kg m^2] (n, 3): principal moments
    coord_start: np.ndarray  # int64 (n + 1,): link i's coordinates are coord[coord_start[i]:coord_start[i + 1]]
    dof_start: np.ndarray  # int64 (n + 1,): link i's rates are rate[dof_start[i]:dof_start[i + 1]]
    dinv_start: np.ndarray  # int64 (n + 1,): link i's D^-1 (k x k, k its rates) in TreeWork.dinv
    motion: np.ndarray  # (D, 6): each rate's column of S, link frame (angular, linear): the reference's
    # [N m s/rad or N s/m] (D,): a damper on each rate, joint force -damping rate (a ball's on each of its 3)
    damping: np.ndarray
    # int64 (n,): +1 where the link is its joint's body_a (the JointTable's first body), -1 where it is
    # body_b, 0 without a joint (a free root): how its reaction maps onto the joint's (J, 12) row
    joint_side: np.ndarray
    # the joints' limits and motors (limits.py); None without any, so a scene without them compiles no
    # limit stage (physics/dispatch.py)
    limits: TreeLimits | None
    # int64: the ball links, and the fixed and free ones; None where the table has none, so ABA's passes
    # for those kinds compile only into the trees that have them (aba.py)
    balls: np.ndarray | None
    others: np.ndarray | None


class TreeLimits(NamedTuple):
    """The joints' limits and motors acting on the coordinates (limits.py), one row each, in the tree's own
    coordinates (a joint whose link is its body_b has its hinge angle and slider travel negated: its
    bounds and motor speed are turned so)."""

    link_kind: np.ndarray  # int64 (m, 2): the row's link and its kind (LIMIT_COORD, LIMIT_TWIST, LIMIT_SWING, MOTOR)
    data: np.ndarray  # (m, LIMIT_COLUMNS): its numbers (the LIMIT_* columns below)


# kinds of limit rows (TreeLimits.link_kind[:, 1]): a hinge's or slider's coordinate between bounds, a
# ball joint's twist angle between bounds and its swing measure below 1 (physics/joints/cone.py), a
# hinge's or slider's velocity motor
LIMIT_COORD, LIMIT_TWIST, LIMIT_SWING, MOTOR = range(4)
# columns of TreeLimits.data: the lower and upper bound [rad, m or 1] (a motor's speed in both, rad/s
# or m/s), the motor's largest torque or force [N m or N] (inf for a limit), a ball joint's relative
# rotation Q = A u B (or A u^* B: side -1) from its coordinate u (limits.py), the cone's half-angles
# [rad], and the side (+1: the link is the joint's body_a)
LIMIT_LOWER, LIMIT_UPPER, LIMIT_CAP, LIMIT_A, LIMIT_B, LIMIT_HALF_ANGLES, LIMIT_SIDE = 0, 1, 2, 3, 7, 11, 13
LIMIT_COLUMNS = 14
# the most limit and motor rows a table holds: their coupling matrix is dense (m x m, LimitWork.delassus)
MAX_LIMIT_ROWS = 1024


class TreeWork(NamedTuple):
    """The tree kernels' mutable arrays, allocated once per run (`make_tree_work`). Spatial quantities are
    link-centred and world-aligned (aba.py): at the link's centre of mass, world axes."""

    rotation: np.ndarray  # (n, 3, 3): world-from-link rotation R
    xpos: np.ndarray  # [m] (n, 3): r, the link's centre of mass from its parent's (world axes; a root's: itself)
    motion: np.ndarray  # (D, 6): each rate's column of S, world-aligned (angular, linear)
    velocity: np.ndarray  # (n, 6): the link's spatial velocity (omega, v_com)
    bias_acc: np.ndarray  # (n, 6): c = v x (S rate), the velocity-product acceleration
    inertia_world: np.ndarray  # [kg m^2] (n, 6): R diag(I) R^T packed (xx, xy, xz, yy, yz, zz)
    inertia_art: np.ndarray  # (n, 21): articulated inertia, packed (SYM6)
    bias_force: np.ndarray  # (n, 6): articulated bias force
    acc: np.ndarray  # (n, 6): the link's spatial acceleration
    U: np.ndarray  # (D, 6): I^A S, one row per rate
    u: np.ndarray  # (D,): tau - S^T p^A
    dinv: np.ndarray  # (dinv_start[n],): (S^T I^A S)^-1 per link, k x k row-major
    # (D,): added to each rate's diagonal of D = S^T I^A S, as a rotor's armature is (Featherstone 7.3): an
    # implicit damper's h c (integrate.py), so ABA solves (M + diag(armature)) qdd = tau - bias
    armature: np.ndarray


class TreeData(NamedTuple):
    """A run's tree state and the tree integrators' arrays (integrate.py), in Data.tree: the state of the
    trees is (coord, rate); the bodies' x, q, P, L are forward kinematics of it."""

    work: TreeWork
    coord: np.ndarray  # (C,): the joint coordinates (table.py's module docstring)
    rate: np.ndarray  # (D,): the rates
    qdd: np.ndarray  # (D,): the rates' derivatives of the last evaluation
    joint_force: np.ndarray  # (D,): forces dual to the rates acting in the joints (none yet: zeros)
    coord0: np.ndarray  # (C,): reduced-rk4's start of the step
    rate0: np.ndarray  # (D,)
    coord_sum: np.ndarray  # (C,): reduced-rk4's weighted sum of the stages' derivatives
    rate_sum: np.ndarray  # (D,)
    dcoord: np.ndarray  # (C,): a stage's d coord / dt
    # (1,): 1 when the state arrays and `work` hold forward kinematics of (coord, rate) (integrate.py)
    fk_state: np.ndarray
    # [N, N m] (n, 12): each link's joint's force and torque over the last step (world, torques about the
    # centres of mass), [0:6] on the link, [6:12] on its parent (0 for a root), the mean over the step's
    # force evaluations (integrate.py joint_wrenches), computed while reactions_on[0] is 1 (the
    # joint_forces stream: ~10 % of a step); wrench (n, 6): their scratch, None in a run that records no
    # reactions, so that its loop compiles none of their stages (reactions.py)
    reaction: np.ndarray
    reactions_on: np.ndarray
    wrench: np.ndarray | None
    response: ResponseWork
    limits: LimitWork | None  # None where the table has no limits


class ResponseWork(NamedTuple):
    """The arrays of M^-1 tau (limits.py tree_response: a limit's or an impulse's velocity change)."""

    tau: np.ndarray  # (D,): a generalized impulse, dual to the rates (J^T lambda, J^T h)
    delta: np.ndarray  # (D,): M^-1 tau
    force: np.ndarray  # (n, 6): the articulated forces
    acc: np.ndarray  # (n, 6): the links' spatial velocity changes of M^-1 tau


class LimitWork(NamedTuple):
    """The limits' and motors' arrays (limits.py), over the table's m rows."""

    value: np.ndarray  # (m,): each row's coordinate at the end of the step (a motor's: its rate)
    row: np.ndarray  # (m, 3): d value / d rate over its link's rates (1 or 3 of them)
    active: np.ndarray  # int64 (m,): the rows a stage solves for (the first `count` of them)
    delassus: np.ndarray  # (m, m): A = J M^-1 J^T over the active rows
    target: np.ndarray  # (m,): what A lambda should be (the rows' rate changes)
    low: np.ndarray  # (m,): the bounds on lambda
    high: np.ndarray
    impulse: np.ndarray  # [N m s or N s] (m,): lambda of the last step, both stages summed
    stage_impulse: np.ndarray  # (m,): one stage's lambda


def make_limit_work(limits: TreeLimits) -> LimitWork:
    m = limits.link_kind.shape[0]
    return LimitWork(
        np.zeros(m), np.zeros((m, 3)), np.zeros(m, dtype=np.int64), np.zeros((m, m)), np.zeros(m), np.zeros(m),
        np.zeros(m), np.zeros(m), np.zeros(m),
    )  # fmt: skip


def make_response_work(tree: TreeTable) -> ResponseWork:
    D, n = tree_dof_count(tree), tree_link_count(tree)
    return ResponseWork(np.zeros(D), np.zeros(D), np.zeros((n, 6)), np.zeros((n, 6)))


def make_tree_data(tree: TreeTable, reactions: bool = False) -> TreeData:
    """Zeroed tree data for `tree` (coordinates at zero_coords; the runner sets them from the state);
    reactions: the run computes the joints' reactions (reactions_on set, their scratch made)."""
    C, D, n = tree_coord_count(tree), tree_dof_count(tree), tree_link_count(tree)
    return TreeData(
        make_tree_work(tree), zero_coords(tree), np.zeros(D), np.zeros(D), np.zeros(D), np.zeros(C), np.zeros(D),
        np.zeros(C), np.zeros(D), np.zeros(C), np.zeros(1), np.full((n, 12), np.nan), np.full(1, float(reactions)),
        np.zeros((n, 6)) if reactions else None,
        make_response_work(tree), None if tree.limits is None else make_limit_work(tree.limits),
    )  # fmt: skip


def tree_table(
    parent,
    kind,
    anchor_parent,
    anchor_child,
    axis,
    rest_q,
    mass,
    inertia,
    body=None,
    joint=None,
    damping=None,
    joint_side=None,
    limit_index=None,
    limit_data=None,
) -> TreeTable:  # noqa: ANN001
    """A TreeTable from per-link sequences (body defaults to the link's index, joint to -1: none; damping,
    per rate, to 0; limit rows to none). Checks
    the order (parent before child), the free joint's place (roots only) and normalises axes and rest
    rotations."""
    parent, kind = frozen_ints(parent), frozen_ints(kind)
    n = parent.shape[0]
    if np.any(parent >= np.arange(n)) or np.any(parent < -1):
        raise ValueError("links must be in topological order: -1 <= parent[i] < i")
    if not set(kind.tolist()) <= set(TREE_COORDS):
        raise ValueError(f"unknown joint kinds {sorted(set(kind.tolist()) - set(TREE_COORDS))}")
    if np.any((kind == TREE_FREE) & (parent != -1)):
        raise ValueError("a free joint joins a root to the world only")
    axis = np.asarray(axis, dtype=np.float64).reshape(n, 3)
    norm = np.linalg.norm(axis, axis=1)
    moving = np.isin(kind, (JOINT_HINGE, JOINT_SLIDER))
    if np.any(norm[moving] == 0.0):
        raise ValueError("a hinge or slider needs a non-zero axis")
    axis = np.where(norm[:, None] > 0.0, axis / np.where(norm > 0.0, norm, 1.0)[:, None], 0.0)
    rest = np.asarray(rest_q, dtype=np.float64).reshape(n, 4)
    rest = rest / np.linalg.norm(rest, axis=1, keepdims=True)
    anchor_child = np.asarray(anchor_child, dtype=np.float64).reshape(n, 3)
    coords = np.array([TREE_COORDS[k] for k in kind.tolist()], dtype=np.int64)
    dofs = np.array([TREE_DOFS[k] for k in kind.tolist()], dtype=np.int64)
    motion = np.zeros((int(dofs.sum()), 6))
    row = 0
    for i, k in enumerate(kind.tolist()):  # once per link at build time
        a, c = axis[i], anchor_child[i]
        if k == JOINT_HINGE:
            motion[row] = np.concatenate([a, np.cross(c, a)])
        elif k == JOINT_SLIDER:
            motion[row, 3:] = a
        elif k == JOINT_BALL:
            eye = np.eye(3)
            motion[row : row + 3] = np.concatenate([eye, np.cross(c, eye)], axis=1)
        elif k == TREE_FREE:
            motion[row : row + 6] = np.eye(6)
        row += dofs[i]
    w, v = rest[:, :1], rest[:, 1:]  # rest (0, a) = (-v . a, w a + v x a)
    rest_axis = np.concatenate([-np.sum(v * axis, axis=1, keepdims=True), w * axis + np.cross(v, axis)], axis=1)
    coord_start, dof_start, dinv_start = (
        frozen_ints(np.concatenate([[0], np.cumsum(c)])) for c in (coords, dofs, dofs * dofs)
    )
    return TreeTable(
        parent,
        kind,
        frozen_ints(np.arange(n) if body is None else body),
        frozen_ints(np.full(n, -1) if joint is None else joint),
        frozen_floats(anchor_parent, 3),
        frozen_floats(anchor_child, 3),
        frozen_floats(axis, 3),
        frozen_floats(rest, 4),
        frozen_floats(rest_axis, 4),
        frozen_floats(mass),
        frozen_floats(inertia, 3),
        coord_start,
        dof_start,
        dinv_start,
        frozen_floats(motion, 6),
        frozen_floats(np.zeros(int(dofs.sum())) if damping is None else damping),
        frozen_ints(np.zeros(n) if joint_side is None else joint_side),
        None
        if limit_index is None or len(limit_index) == 0
        else TreeLimits(_frozen_index(limit_index), frozen_floats(limit_data, LIMIT_COLUMNS)),
        _links_or_none(np.flatnonzero(kind == JOINT_BALL)),
        _links_or_none(np.flatnonzero((kind == JOINT_FIXED) | (kind == TREE_FREE))),
    )


def _links_or_none(links: np.ndarray) -> np.ndarray | None:
    return frozen_ints(links) if links.size else None


def _frozen_index(values) -> np.ndarray:  # noqa: ANN001
    """An int64 (m, 2) array, contiguous and read-only."""
    out = np.ascontiguousarray(np.asarray(values, dtype=np.int64).reshape(-1, 2))
    out.setflags(write=False)
    return out


def tree_link_count(tree: TreeTable) -> int:
    return int(tree.parent.shape[0])


def tree_dof_count(tree: TreeTable) -> int:
    return int(tree.dof_start[-1])


def tree_coord_count(tree: TreeTable) -> int:
    return int(tree.coord_start[-1])


def make_tree_work(tree: TreeTable) -> TreeWork:
    """Zeroed work arrays for `tree`'s links and rates."""
    n, dofs = tree_link_count(tree), tree_dof_count(tree)
    return TreeWork(
        np.zeros((n, 3, 3)), np.zeros((n, 3)), np.zeros((dofs, 6)), np.zeros((n, 6)), np.zeros((n, 6)),
        np.zeros((n, 6)), np.zeros((n, SYM6)), np.zeros((n, 6)), np.zeros((n, 6)), np.zeros((dofs, 6)),
        np.zeros(dofs), np.zeros(int(tree.dinv_start[-1])), np.zeros(dofs),
    )  # fmt: skip


def zero_coords(tree: TreeTable) -> np.ndarray:
    """The coordinates of the rest configuration: angles and travels 0, ball quaternions 1, a free root at
    the world origin unrotated. Shape (C,)."""
    coord = np.zeros(tree_coord_count(tree))
    for i, k in enumerate(tree.kind.tolist()):
        if k == JOINT_BALL:
            coord[tree.coord_start[i]] = 1.0
        elif k == TREE_FREE:
            coord[tree.coord_start[i] + 3] = 1.0
    return coord
