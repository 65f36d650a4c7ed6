"""The joint table (read-only, the model's `joint`) and the joints' work arrays (the run's Data.joint).

Rows are grouped by joint: joint j connects body_a[j] and body_b[j] (WORLD = -1 for the world; body_a
is never the world) and owns rows row_start[j] .. row_start[j] + row_count[j] - 1. Each row r is one
scalar constraint g_r(x, q) = 0 with its Jacobian G_r = d g_r / d(v_a, omega_a, v_b, omega_b)
(world frame; docs/joints.md has every type's rows):

    ball      3  p_a - p_b = 0, p = x + R r the anchor's world position
    distance  1  |p_a - p_b| - length = 0
    hinge     5  ball, and (R_a u_a) . (R_b n_bk) = 0 for the two unit normals n_b1, n_b2 of the axis
    slider    5  relative rotation held (3), and (p_a - p_b) . (R_b n_bk) = 0 (2)
    fixed     6  ball, and relative rotation held (3)

Relative rotation: with c = q_b0^* q_a0 (the initial relative rotation, principal frames), the error
quaternion e = q_a c^* q_b^* is 1 while it holds; its rows are g = 2 vec(e) (w_e >= 0), the rotation
vector of the error to second order.

Points are body-fixed offsets about the centre of mass in the PRINCIPAL frame (as forces/tables.py),
vectors likewise; an end on the world has its point and vectors in the world frame. Static and
kinematic bodies act as the world (`body_ground`: infinite mass) but keep their own frame, so a
kinematic body's anchor moves with it (a driven crank).

This module imports numpy only, so scene/compile_joints.py builds tables cheaply.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rbcli.physics.joints.solver_layout import JointGraph, SolverWork, joint_graph, make_solver_work
from rbcli.physics.table_arrays import frozen_floats, frozen_ints

WORLD = -1

JOINT_BALL, JOINT_HINGE, JOINT_FIXED, JOINT_SLIDER, JOINT_DISTANCE = range(5)
JOINT_KINDS = {
    "ball": JOINT_BALL,
    "hinge": JOINT_HINGE,
    "fixed": JOINT_FIXED,
    "slider": JOINT_SLIDER,
    "distance": JOINT_DISTANCE,
}
JOINT_ROWS = {JOINT_BALL: 3, JOINT_HINGE: 5, JOINT_FIXED: 6, JOINT_SLIDER: 5, JOINT_DISTANCE: 1}

# columns of JointWork.stats: Newton iterations of the last position stage, the largest |g| it left
# [m or rad], the largest |G V| the velocity stage left [m/s or rad/s], rows found redundant (dropped),
# the round-off level at which the position stage's Newton iteration stopped [m] (stages.py), and
# steps whose extrapolated first iterate did not converge, so that the Newton ran again from the free
# drift (counted over the run: rattle.py)
STAT_ITERATIONS, STAT_POSITION, STAT_VELOCITY, STAT_REDUNDANT, STAT_FLOOR, STAT_RESTARTS = range(6)
STAT_COUNT = 6
# columns of JointTable.cone
CONE_FRAME_A, CONE_FRAME_B, CONE_SWING = 0, 4, 8


class JointTable(NamedTuple):
    """Every joint of a scene (see the module docstring); read-only arrays, shapes over joints J,
    rows R and bodies N."""

    kind: np.ndarray  # int64 (J,): JOINT_*
    body_a: np.ndarray  # int64 (J,), never WORLD
    body_b: np.ndarray  # int64 (J,), WORLD for the world
    anchor_a: np.ndarray  # [m] (J, 3), principal frame of body_a, about its centre of mass
    anchor_b: np.ndarray  # [m] (J, 3), principal frame of body_b; a world point for WORLD
    axis_a: np.ndarray  # [1] (J, 3), unit, principal frame of body_a (hinge, slider)
    normal_b: np.ndarray  # [1] (J, 2, 3), two unit normals of the axis, principal frame of body_b (or world)
    relative_q: np.ndarray  # (J, 4) wxyz: c = q_b0^* q_a0, the initial relative rotation (fixed, slider)
    length: np.ndarray  # [m] (J,): distance joints' rod
    damping: np.ndarray  # (J,): hinge [N m s/rad], slider [N s/m]; 0: no damper (stages.py: drives)
    motor_speed: np.ndarray  # (J,): hinge [rad/s], slider [m/s]: the target rate of a velocity motor
    motor_cap: np.ndarray  # (J,): hinge [N m], slider [N]: the motor's largest torque / force; 0: no motor
    limit_lower: np.ndarray  # (J,): hinge [rad], slider [m], ball twist [rad] from the initial pose; -inf: none
    limit_upper: np.ndarray  # (J,): +inf: none
    reference_a: np.ndarray  # [1] (J, 3), principal frame of body_a: n_b1 at the initial poses (hinge angle 0)
    travel0: np.ndarray  # [m] (J,): a slider's initial (p_a - p_b) . u (its travel is measured from it)
    # (J, 10) a ball joint's cone (joints/cone.py), one array (each array of the table costs every kernel
    # call that takes it): [0:4] f_a, [4:8] f_b, the wxyz principal-from-joint frame of each end (world-
    # from-joint for the world), the joint frame's x the cone axis, y its reference, the same world frame
    # at the initial poses; [8:10] the swing half-angles [rad] toward the reference and toward axis x
    # reference, 0: no swing limit (CONE_FRAME_A, CONE_FRAME_B, CONE_SWING). Twist: limit_lower / upper.
    cone: np.ndarray
    row_start: np.ndarray  # int64 (J,)
    row_count: np.ndarray  # int64 (J,)
    body_ground: np.ndarray  # bool (N,): static or kinematic bodies, which act as the world
    graph: JointGraph  # the solver's ordering (joints/solver.py: leaves first, loop joints apart)


# the highest degree of the polynomial through the last steps' multipliers that gives the next step's
# first Newton iterate (joints/rattle.py `_first_iterate`); the history holds GUESS_ORDER + 1 steps
GUESS_ORDER = 5

# the most limits solved together in one block (joints/limit_solve.py); a stage with more active limits
# solves them in blocks of this many, one block after another: the scratch below is O(block x rows)
LIMIT_BLOCK = 64


class LimitScratch(NamedTuple):
    """The limit solve's arrays for one block of active limits (joints/limit_solve.py), C = min(limit
    slots of the scene, LIMIT_BLOCK), R rows."""

    ends: np.ndarray  # (C, 4) int64: joint, body_a, body_b, slot (0 the coordinate's, 1 a ball's cone)
    jacs: np.ndarray  # (C, 12): the limit's row J_a, J_b (world)
    bounds: np.ndarray  # (C, 3): target of K lambda, lambda's lower and upper bound
    lam: np.ndarray  # (C,)
    y: np.ndarray  # (C, R): A^-1 G W J^T of each limit (the joints' share of a unit impulse along it)
    k: np.ndarray  # (C, C): K, the limits' coupling with the joints held


class JointWork(NamedTuple):
    """The joint stages' mutable arrays, allocated once per run (`make_joint_work`), in Data.joint."""

    jac_a: np.ndarray  # (R, 6): d g_r / d(v_a, omega_a), world
    jac_b: np.ndarray  # (R, 6): d g_r / d(v_b, omega_b), world (unused for WORLD)
    residual: np.ndarray  # (R,): g, or G V in the velocity stage
    rhs: np.ndarray  # (R,)
    delta: np.ndarray  # (R,): the solve's output
    impulse: np.ndarray  # [N s or N m s] (R,): the last step's multipliers: position + velocity stage
    x_start: np.ndarray  # [m] (N, 3): the step's start configuration, where the position impulse acts
    q_start: np.ndarray  # (N, 4)
    inv_mass: np.ndarray  # [1/kg] (N,): 0 for ground bodies
    inv_inertia: np.ndarray  # [1/(kg m^2)] (N, 3, 3), world frame: R I0^-1 R^T, 0 for ground bodies
    impulse_body: np.ndarray  # [N s, N m s] (N, 6): one solve's momentum change per body
    # (J, 2): +1 / -1 where this step's position stage pushed a limit back onto its upper / lower bound;
    # column 0 the joint's coordinate (hinge angle, slider travel, ball twist), 1 a ball joint's swing
    limit_hit: np.ndarray
    # [N s or N m s] (J, 2): the impulse this step's position stage gave each limit so far (its sign is
    # the side it pushes from: joints/limit_solve.py keeps it so)
    limit_push: np.ndarray
    limit_scratch: LimitScratch
    # [N s, N m s] (J, 12), world frame: each joint's impulse on its bodies over the last (sub-)step, its
    # rows', motor's, damper's and limit's summed: [0:3] linear and [3:6] angular (about the centre of
    # mass) on body_a, [6:12] on body_b (zero for the world); / h it is the joint's reaction force and
    # torque (Simulation.joint_reactions)
    joint_impulse: np.ndarray
    stats: np.ndarray  # (STAT_COUNT,): see STAT_*
    solver: SolverWork
    # the configuration the solver's factor (and jac_a, jac_b, inv_mass, inv_inertia) belongs to, and
    # [1 when it is set, the rows it dropped]: a stage finding the state bitwise there reuses the factor
    # (stages.py `_factor_at`), which is then bitwise what a new factor would be
    x_factor: np.ndarray  # [m] (N, 3)
    q_factor: np.ndarray  # (N, 4)
    factor_state: np.ndarray  # (2,)
    # the position stage's multipliers Lambda of the last GUESS_ORDER + 1 steps (row 0 the last), how
    # many of them are set (guess_count[0]) and the degree of the extrapolation that gives the next step's
    # first Newton iterate (guess_count[1]; rattle.py `_first_iterate`, `_remember`); carried by
    # checkpoints so a resumed run continues bitwise, forgotten by Data.clear_work
    guess: np.ndarray  # [N s or N m s] (GUESS_ORDER + 1, R)
    guess_count: np.ndarray  # (2,)
    # the momenta after the start kick, before the guess's impulse: the Newton restarts from them when
    # the guess does not converge (rattle.py)
    P_kicked: np.ndarray  # [N s] (N, 3)
    L_kicked: np.ndarray  # [N m s] (N, 3)
    # the momenta the last velocity stage left: the next step's joint_begin finds G V as that stage left
    # it when the state is bitwise still there (stages.py), without computing G V again
    P_left: np.ndarray  # [N s] (N, 3)
    L_left: np.ndarray  # [N m s] (N, 3)


def joint_table(
    kind=(),
    body_a=(),
    body_b=(),
    anchor_a=(),
    anchor_b=(),
    axis_a=(),
    normal_b=(),
    relative_q=(),
    length=(),
    damping=None,
    motor_speed=None,
    motor_cap=None,
    limit_lower=None,
    limit_upper=None,
    reference_a=None,
    travel0=None,
    cone_frame_a=None,
    cone_frame_b=None,
    swing_limit=None,
    *,
    body_ground: np.ndarray,
) -> JointTable:  # noqa: ANN001
    """A JointTable from per-joint sequences (damping and motors default to none); rows numbered in
    joint order."""
    kinds = frozen_ints(kind)
    count = frozen_ints([JOINT_ROWS[int(k)] for k in kinds])
    start = frozen_ints(np.concatenate([[0], np.cumsum(count)[:-1]]) if count.size else [])
    ground = np.ascontiguousarray(np.asarray(body_ground, dtype=np.bool_))
    ground.setflags(write=False)
    a, b = frozen_ints(body_a), frozen_ints(body_b)
    zeros, rows = np.zeros(kinds.shape[0]), kinds.shape[0]
    damper, speed, cap = (frozen_floats(zeros if v is None else v) for v in (damping, motor_speed, motor_cap))
    lower = frozen_floats(np.full(rows, -np.inf) if limit_lower is None else limit_lower)
    upper = frozen_floats(np.full(rows, np.inf) if limit_upper is None else limit_upper)
    reference = frozen_floats(np.zeros((rows, 3)) if reference_a is None else reference_a, 3)
    identity = np.tile([1.0, 0.0, 0.0, 0.0], (rows, 1))
    frame_a, frame_b = (identity if f is None else np.reshape(f, (-1, 4)) for f in (cone_frame_a, cone_frame_b))
    swing = np.zeros((rows, 2)) if swing_limit is None else np.reshape(swing_limit, (-1, 2))
    cone = frozen_floats(np.hstack([frame_a, frame_b, swing]) if rows else np.zeros((0, 10)), 10)
    return JointTable(
        kinds,
        a,
        b,
        frozen_floats(anchor_a, 3),
        frozen_floats(anchor_b, 3),
        frozen_floats(axis_a, 3),
        frozen_floats(normal_b, 2, 3),
        frozen_floats(relative_q, 4),
        frozen_floats(length),
        damper,
        speed,
        cap,
        lower,
        upper,
        reference,
        frozen_floats(zeros if travel0 is None else travel0),
        cone,
        start,
        count,
        ground,
        joint_graph(a, b, ground, count),
    )


def joint_row_total(table: JointTable) -> int:
    return int(table.row_count.sum())


def limit_slots(table: JointTable) -> int:
    """How many limits `table` has: a bounded coordinate, a ball joint's cone (joints/drives.py)."""
    bounded = np.isfinite(table.limit_lower) | np.isfinite(table.limit_upper)
    return int(bounded.sum() + (table.cone[:, 8] > 0.0).sum())


def make_joint_work(table: JointTable) -> JointWork:
    """Zeroed work arrays for `table`'s rows and bodies."""
    rows, bodies = joint_row_total(table), table.body_ground.shape[0]
    block = min(limit_slots(table), LIMIT_BLOCK)
    scratch = LimitScratch(
        np.zeros((block, 4), dtype=np.int64), np.zeros((block, 12)), np.zeros((block, 3)), np.zeros(block),
        np.zeros((block, rows)), np.zeros((block, block)),
    )  # fmt: skip
    return JointWork(
        np.zeros((rows, 6)), np.zeros((rows, 6)), np.zeros(rows), np.zeros(rows), np.zeros(rows), np.zeros(rows),
        np.zeros((bodies, 3)), np.zeros((bodies, 4)), np.zeros(bodies), np.zeros((bodies, 3, 3)),
        np.zeros((bodies, 6)), np.zeros((table.kind.shape[0], 2)), np.zeros((table.kind.shape[0], 2)), scratch,
        np.zeros((table.kind.shape[0], 12)),
        np.zeros(STAT_COUNT), make_solver_work(table.graph), np.zeros((bodies, 3)), np.zeros((bodies, 4)), np.zeros(2),
        np.zeros((GUESS_ORDER + 1, rows)), np.zeros(2), np.zeros((bodies, 3)), np.zeros((bodies, 3)),
        np.zeros((bodies, 3)), np.zeros((bodies, 3)),
    )  # fmt: skip
