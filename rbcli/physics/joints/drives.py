"""What acts on a hinge's or slider's own coordinate: velocity motors, dampers and limits; and on a ball
joint's swing and twist (joints/cone.py): its cone and twist limits, and its damper.

The coordinate c of joint j: a hinge's angle of body a relative to b about the axis u = R_a u_a,
c = atan2(u . (n_b x m_a), n_b . m_a) with n_b = R_b n_b1 and m_a = R_a m (the same world vector at the
initial poses, so c = 0 there); a slider's travel c = (p_a - p_b) . u - c0 along u = R_b u_b (the axis
carried by body b), c0 its initial value. Its rate r = J V: (omega_a - omega_b) . u for a hinge,
(v_a + omega_a x r_a - v_b - omega_b x r_b) . u + omega_b . (u x d) for a slider (d = p_a - p_b).

An impulse lambda along J, followed by the projection that keeps every joint's G V = 0, changes r by
k lambda, k = J W J^T - (G W J^T)^T A^-1 (G W J^T): the inverse effective inertia (or mass) of the
coordinate with the joints held (one solve with the stage's factor of A).

- motor (velocity stage): the impulse that brings r to its speed, capped at |lambda| <= cap h;
- damper (velocity stage, after the motor): the exact flow of dr/dt = -c k r over the step,
  r <- r exp(-c k h), so a flywheel on a damped hinge decays at exp(-c t / I) to round-off; a ball
  joint's damper acts so on the relative angular velocity about the world's x, y and z in turn;
- limits, one-sided: in the position stage a coordinate beyond a bound at the end of the step is put
  back onto it by an impulse at the step's start (as the joints' rows: h k lambda = bound - c, simplified
  Newton with the start's factor, alternating with the joints' own Newton until both hold); in the
  velocity stage a coordinate pushed back in this step, or at a bound (within LIMIT_CONTACT) with its
  rate pointing out of the range, is stopped (r = 0: an inelastic stop; the position push alone would
  reflect it, a bounce). A limit only ever pushes into the range (lambda of one sign:
  the active set is "beyond or at the bound and moving out"), never pulls.
Motors and dampers act one joint after another; the limits of a stage are solved together, their
coupling through the joints included (joints/limit_solve.py).
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.integrators.kinematics import rotate
from rbcli.physics.joints.cone import cone_row
from rbcli.physics.joints.impulses import apply_body_impulses, body_omega, gather_impulses
from rbcli.physics.joints.solver import solve_rows
from rbcli.physics.joints.tables import JOINT_BALL, JOINT_HINGE
from rbcli.physics.kernel_link import separately_compiled

# a coordinate within this of a bound [rad or m] is at it (the velocity stage stops outward motion):
# the position stage leaves it at round-off (~1e-16) from the bound, and no motion meant to stay clear of
# a limit comes that close within one step
LIMIT_CONTACT = 1e-9


@numba.njit(cache=True)
def _ends(table, j, x, q):  # noqa: ANN001, ANN202
    """(q_a, q_b, anchor offsets r_a, r_b [world], d = p_a - p_b) of joint j at (x, q); q_b = 1 for the world."""
    a, b = table.body_a[j], table.body_b[j]
    aw, ax, ay, az = q[a, 0], q[a, 1], q[a, 2], q[a, 3]
    ra = rotate(aw, ax, ay, az, table.anchor_a[j, 0], table.anchor_a[j, 1], table.anchor_a[j, 2])
    if b >= 0:
        bw, bx, by, bz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        rb = rotate(bw, bx, by, bz, table.anchor_b[j, 0], table.anchor_b[j, 1], table.anchor_b[j, 2])
        pb = (x[b, 0] + rb[0], x[b, 1] + rb[1], x[b, 2] + rb[2])
    else:
        bw, bx, by, bz = 1.0, 0.0, 0.0, 0.0
        rb = (0.0, 0.0, 0.0)
        pb = (table.anchor_b[j, 0], table.anchor_b[j, 1], table.anchor_b[j, 2])
    d = (x[a, 0] + ra[0] - pb[0], x[a, 1] + ra[1] - pb[1], x[a, 2] + ra[2] - pb[2])
    return (aw, ax, ay, az), (bw, bx, by, bz), ra, rb, d


@numba.njit(cache=True)
def _slider_axis(table, j, qb):  # noqa: ANN001, ANN202
    """u = R_b (n_b1 x n_b2), the slider's axis in the world."""
    n1, n2 = table.normal_b[j, 0], table.normal_b[j, 1]
    c0, c1, c2 = n1[1] * n2[2] - n1[2] * n2[1], n1[2] * n2[0] - n1[0] * n2[2], n1[0] * n2[1] - n1[1] * n2[0]
    return rotate(qb[0], qb[1], qb[2], qb[3], c0, c1, c2)


@numba.njit(cache=True)
def coordinate_row(table, j, x, q):  # noqa: ANN001, ANN202
    """(c, J_a, J_b): joint j's coordinate [rad or m] and its rate's row (6-tuples) at (x, q)."""
    qa, qb, ra, rb, d = _ends(table, j, x, q)
    if table.kind[j] == JOINT_HINGE:
        u = rotate(qa[0], qa[1], qa[2], qa[3], table.axis_a[j, 0], table.axis_a[j, 1], table.axis_a[j, 2])
        n = rotate(qb[0], qb[1], qb[2], qb[3], table.normal_b[j, 0, 0], table.normal_b[j, 0, 1],
                   table.normal_b[j, 0, 2])  # fmt: skip
        m = rotate(qa[0], qa[1], qa[2], qa[3], table.reference_a[j, 0], table.reference_a[j, 1],
                   table.reference_a[j, 2])  # fmt: skip
        cross = (n[1] * m[2] - n[2] * m[1], n[2] * m[0] - n[0] * m[2], n[0] * m[1] - n[1] * m[0])
        angle = math.atan2(u[0] * cross[0] + u[1] * cross[1] + u[2] * cross[2], n[0] * m[0] + n[1] * m[1] + n[2] * m[2])
        return angle, (0.0, 0.0, 0.0, u[0], u[1], u[2]), (0.0, 0.0, 0.0, -u[0], -u[1], -u[2])
    u = _slider_axis(table, j, qb)
    travel = d[0] * u[0] + d[1] * u[1] + d[2] * u[2] - table.travel0[j]
    ja = (u[0], u[1], u[2], ra[1] * u[2] - ra[2] * u[1], ra[2] * u[0] - ra[0] * u[2], ra[0] * u[1] - ra[1] * u[0])
    jb = (
        -u[0],
        -u[1],
        -u[2],
        -(rb[1] * u[2] - rb[2] * u[1]) + (u[1] * d[2] - u[2] * d[1]),
        -(rb[2] * u[0] - rb[0] * u[2]) + (u[2] * d[0] - u[0] * d[2]),
        -(rb[0] * u[1] - rb[1] * u[0]) + (u[0] * d[1] - u[1] * d[0]),
    )
    return travel, ja, jb


@numba.njit(cache=True, inline="always")
def weigh(work, body, jac):  # noqa: ANN001, ANN202
    """W_body jac (a 6-tuple) for one end (zero for the world and ground bodies)."""
    if body < 0:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    m = work.inv_mass[body]
    W = work.inv_inertia[body]
    return (
        m * jac[0],
        m * jac[1],
        m * jac[2],
        W[0, 0] * jac[3] + W[0, 1] * jac[4] + W[0, 2] * jac[5],
        W[1, 0] * jac[3] + W[1, 1] * jac[4] + W[1, 2] * jac[5],
        W[2, 0] * jac[3] + W[2, 1] * jac[4] + W[2, 2] * jac[5],
    )


@numba.njit(cache=True)
def effective_inverse(table, work, a, b, ja, jb) -> float:  # noqa: ANN001
    """k = J W J^T - (G W J^T)^T A^-1 (G W J^T) with the stage's W, G (work.jac_*) and factor of A;
    leaves y = A^-1 G W J^T in work.delta (the joints' share of an impulse along J)."""
    wa, wb = weigh(work, a, ja), weigh(work, b, jb)
    for k in range(table.kind.shape[0]):  # G W J^T: only rows on a or b couple
        ak, bk = table.body_a[k], table.body_b[k]
        for r in range(table.row_start[k], table.row_start[k] + table.row_count[k]):
            total = 0.0
            for c in range(6):
                if ak == a:
                    total += work.jac_a[r, c] * wa[c]
                if b >= 0 and ak == b:
                    total += work.jac_a[r, c] * wb[c]
                if bk >= 0 and bk == a:
                    total += work.jac_b[r, c] * wa[c]
                if bk >= 0 and b >= 0 and bk == b:
                    total += work.jac_b[r, c] * wb[c]
            work.rhs[r] = total
    solve_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b,
               work.rhs, work.delta)  # fmt: skip
    k_inv = 0.0
    for c in range(6):
        k_inv += ja[c] * wa[c] + jb[c] * wb[c]
    for r in range(work.rhs.shape[0]):
        k_inv -= work.rhs[r] * work.delta[r]
    return k_inv


@numba.njit(cache=True)
def _push(table, work, j, a, b, ja, jb, impulse, P, L) -> None:  # noqa: ANN001
    """lambda J^T on joint j's bodies and -lambda G^T y on every row (so G V stays as it was), applied
    to P, L; y from `effective_inverse`. The J^T part is joint j's in work.joint_impulse (the rows'
    parts go to their joints: gather_impulses)."""
    for r in range(work.delta.shape[0]):
        work.delta[r] = -work.delta[r] * impulse
        work.impulse[r] += work.delta[r]
    gather_impulses(table, work, work.delta)
    for c in range(6):
        work.impulse_body[a, c] += ja[c] * impulse
        work.joint_impulse[j, c] += ja[c] * impulse
        if b >= 0:
            work.impulse_body[b, c] += jb[c] * impulse
            work.joint_impulse[j, 6 + c] += jb[c] * impulse
    apply_body_impulses(table, work, P, L)


@numba.njit(cache=True, inline="always")
def limit_rate(model, q, P, L, a, b, ja, jb) -> float:  # noqa: ANN001
    """J V from the bodies' own velocities (a ground body's too)."""
    inv = 1.0 / model.body_mass[a]
    oa0, oa1, oa2 = body_omega(model, q, L, a)
    rate = inv * (ja[0] * P[a, 0] + ja[1] * P[a, 1] + ja[2] * P[a, 2]) + ja[3] * oa0 + ja[4] * oa1 + ja[5] * oa2
    if b >= 0:
        inv = 1.0 / model.body_mass[b]
        ob0, ob1, ob2 = body_omega(model, q, L, b)
        rate += inv * (jb[0] * P[b, 0] + jb[1] * P[b, 1] + jb[2] * P[b, 2]) + jb[3] * ob0 + jb[4] * ob1 + jb[5] * ob2
    return rate


# inline="always" (numba's, before typing): called from Python's view a small function,
# but LLVM left each a call, and a call passes the joint table and work by value (~30 arrays each); a
# hinge-limit scene (the ragdoll without cones) stepped ~9 % slower than when its limits called
# coordinate_row directly
@numba.njit(cache=True, inline="always")
def limit_row(table, j, swing, x, q):  # noqa: ANN001, ANN202
    """(c, J_a, J_b) of the coordinate joint j's limits act on: a ball joint's swing measure (swing True) or
    twist (joints/cone.py), else the hinge's or slider's coordinate (coordinate_row)."""
    if swing or table.kind[j] == JOINT_BALL:
        qa, qb, _, _, _ = _ends(table, j, x, q)
        return cone_row(table, j, swing, qa, qb)
    return coordinate_row(table, j, x, q)


@numba.njit(cache=True, inline="always")
def limit_bounds(table, j, slot):  # noqa: ANN001, ANN202
    """(lower, upper) of joint j's limit `slot`: 0 its coordinate's, 1 a ball joint's cone (c <= 1)."""
    if slot == 0:
        return table.limit_lower[j], table.limit_upper[j]
    if table.cone[j, 8] > 0.0:  # tables.CONE_SWING: a swing limit
        return -math.inf, 1.0
    return -math.inf, math.inf


@numba.njit(cache=True)
def _ball_damper(model, table, work, j, a, b, h, q, P, L) -> None:  # noqa: ANN001
    """A ball joint's damper: the hinge's exact one-coordinate damper, r <- r exp(-c k h), on the relative
    angular velocity about the world's x, y and z in turn (a Gauss-Seidel sweep: exact for each axis
    alone, dissipative always; the three together are the flow of -c K omega_rel only where K is
    diagonal in the world axes)."""
    for axis in range(3):
        e0, e1, e2 = (1.0 if axis == 0 else 0.0), (1.0 if axis == 1 else 0.0), (1.0 if axis == 2 else 0.0)
        ja, jb = (0.0, 0.0, 0.0, e0, e1, e2), (0.0, 0.0, 0.0, -e0, -e1, -e2)
        k_inv = effective_inverse(table, work, a, b, ja, jb)
        if k_inv > 0.0:
            rate = limit_rate(model, q, P, L, a, b, ja, jb)
            _push(table, work, j, a, b, ja, jb, rate * (math.exp(-table.damping[j] * k_inv * h) - 1.0) / k_inv, P, L)


@separately_compiled
@numba.njit(cache=True)
def drive_velocities(model, table, work, h, x, q, P, L) -> None:  # noqa: ANN001
    """The velocity stage's motors and dampers (module docstring), one joint after another, with the end
    configuration's W, G and factor; the limits' stops follow, solved together (limit_solve.py)."""
    for j in range(table.kind.shape[0]):
        motor, damper = table.motor_cap[j] > 0.0, table.damping[j] > 0.0
        if not (motor or damper):
            continue
        a, b = table.body_a[j], table.body_b[j]
        if table.kind[j] == JOINT_BALL:
            if damper:
                _ball_damper(model, table, work, j, a, b, h, q, P, L)
            continue
        _, ja, jb = limit_row(table, j, False, x, q)
        k_inv = effective_inverse(table, work, a, b, ja, jb)
        if k_inv > 0.0:  # 0: the coordinate cannot move (both ends fixed, or the joints forbid it)
            rate = limit_rate(model, q, P, L, a, b, ja, jb)
            impulse = 0.0
            if motor:
                cap = table.motor_cap[j] * h
                impulse = min(max((table.motor_speed[j] - rate) / k_inv, -cap), cap)
                rate += k_inv * impulse
            if damper:
                impulse += rate * (math.exp(-table.damping[j] * k_inv * h) - 1.0) / k_inv
            _push(table, work, j, a, b, ja, jb, impulse, P, L)
