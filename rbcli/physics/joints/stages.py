"""The joint stages of a step: RATTLE-type position and velocity stages after split2's update.

After the unconstrained split2 step (all forces; D(h/2) K(h) D(h/2), docs/integrators.md) the state is
(x~, q~, P~, L~). The constraint force acts as an impulse Lambda at the kick, in the direction of the
rows' Jacobian G at the step's midpoint configuration (SHAKE at the midpoint, Hairer-Lubich-Wanner
VII.1; Leimkuhler-Reich ch. 7):

    P = P~ + G_mid^T Lambda,  and the second half drift moves the bodies by
    x = x~ + h/2 M^-1 dP,   q = exp(h/2 I_w^-1 dL) q~           (dP, dL: body b's part of G_mid^T Lambda)

with Lambda such that g(x, q) = 0 at the end of the step. `joint_position` solves that by simplified
Newton, Lambda += -(2/h) A^-1 g(x, q), A = G_mid W G_mid^T factored once per step, until |g| stops
falling (round-off: each iteration gains a factor ~ h |omega|, measured 4-6 iterations at dt = 1e-3).
The translation part is exact (the drift is linear in P); the rotation part is the first-order response
of the turns to dL, an O(h^3) local difference, so the method keeps order 2.

The midpoint configuration comes from the end state without a saved copy: x_mid = x~ - h/2 P~/M
exactly (the second drift used the kicked P~), and q_mid = exp(-h/2 omega~) q~, omega~ = I_w^-1 L~,
the second half turn undone to O(h^2) (exact for isotropic bodies, whose half turn it is).

`joint_velocity` then projects the momenta so that the end velocities satisfy the hidden constraint
G_end V = 0 (one linear solve): mu = A_end^-1 G_end V, (P, L) -= G_end^T mu. Both multipliers summed
are the step's joint impulse (work.impulse), the reaction force being impulse / h.

Why the midpoint (measured, docs/joints.md): with G at the end (a plain post-projection) the
projection removes the velocity's normal part at the end, which shortens the tangential speed by a
factor cos(h omega) per step: first order and dissipative (energy falls steadily); with G at the
midpoint the impulse's tangential part at the end, Lambda sin(h omega / 2), restores it to O(h^3), and
the period error is second order with the energy error bounded.

Static and kinematic bodies act as the world (W = 0, nothing applied to them) but their anchors move
with their pose; a kinematic body's velocity enters G V. Stats go to work.stats (tables.STAT_*).
"""

from __future__ import annotations

import math
from typing import Any

import numba
from numba.core import types
from numba.extending import overload

from rbcli.physics.integrators.kinematics import rotate, rotate_inverse
from rbcli.physics.joints.dense import factor_rows, solve_rows
from rbcli.physics.joints.rows import joint_rows
from rbcli.physics.joints.tables import JOINT_HINGE, STAT_ITERATIONS, STAT_POSITION, STAT_REDUNDANT, STAT_VELOCITY
from rbcli.physics.step import STEP_KERNEL

# the Newton iteration stops when |g| falls by less than this factor in one iteration (round-off
# reached), or after NEWTON_ITERATIONS (a step far too long for its joints: the stats show it)
NEWTON_STALL = 0.5
NEWTON_ITERATIONS = 50

_OPTIONS: Any = STEP_KERNEL


@numba.njit(cache=True)
def _body_weights(model, table, work, q) -> None:  # noqa: ANN001
    """inv_mass and world inverse inertia R I0^-1 R^T of every body at orientations q (0: ground)."""
    for b in range(q.shape[0]):
        if table.body_ground[b]:
            work.inv_mass[b] = 0.0
            for i in range(3):
                for k in range(3):
                    work.inv_inertia[b, i, k] = 0.0
            continue
        work.inv_mass[b] = 1.0 / model.body_mass[b]
        w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        c00, c01, c02 = rotate(w, x, y, z, 1.0, 0.0, 0.0)
        c10, c11, c12 = rotate(w, x, y, z, 0.0, 1.0, 0.0)
        c20, c21, c22 = rotate(w, x, y, z, 0.0, 0.0, 1.0)
        i0, i1, i2 = model.body_inertia_inv[b, 0], model.body_inertia_inv[b, 1], model.body_inertia_inv[b, 2]
        # columns c_k = R e_k: (R D R^T)_ik = sum_k D_k c_k[i] c_k[m]
        col = ((c00, c01, c02), (c10, c11, c12), (c20, c21, c22))
        for i in range(3):
            for m in range(3):
                work.inv_inertia[b, i, m] = (
                    i0 * col[0][i] * col[0][m] + i1 * col[1][i] * col[1][m] + (i2 * col[2][i] * col[2][m])
                )


@numba.njit(cache=True, inline="always")
def _turn(q, b, t0, t1, t2) -> None:  # noqa: ANN001
    """q_b <- exp(theta / 2) q_b for the world rotation vector theta, renormalised."""
    angle = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if angle == 0.0:
        return
    c, s = math.cos(0.5 * angle), math.sin(0.5 * angle) / angle
    rx, ry, rz = s * t0, s * t1, s * t2
    w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    w, qx, qy, qz = (
        c * w - rx * qx - ry * qy - rz * qz,
        c * qx + rx * w + ry * qz - rz * qy,
        c * qy - rx * qz + ry * w + rz * qx,
        c * qz + rx * qy - ry * qx + rz * w,
    )
    norm = 1.0 / math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
    q[b, 0], q[b, 1], q[b, 2], q[b, 3] = w * norm, qx * norm, qy * norm, qz * norm


@numba.njit(cache=True, inline="always")
def _omega(model, q, L, b):  # noqa: ANN001, ANN202
    """omega = R I0^-1 R^T L [rad/s], world."""
    w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    m0, m1, m2 = rotate_inverse(w, x, y, z, L[b, 0], L[b, 1], L[b, 2])
    inv = model.body_inertia_inv
    return rotate(w, x, y, z, inv[b, 0] * m0, inv[b, 1] * m1, inv[b, 2] * m2)


@numba.njit(cache=True)
def _gather_impulses(table, work, multipliers) -> None:  # noqa: ANN001
    """impulse_body = G^T multipliers per body (ground bodies and the world get nothing)."""
    impulse = work.impulse_body
    impulse[:, :] = 0.0
    for j in range(table.kind.shape[0]):
        a, b = table.body_a[j], table.body_b[j]
        for r in range(table.row_start[j], table.row_start[j] + table.row_count[j]):
            m = multipliers[r]
            for c in range(6):
                impulse[a, c] += work.jac_a[r, c] * m
                if b >= 0:
                    impulse[b, c] += work.jac_b[r, c] * m


@numba.njit(cache=True)
def joint_position(model, table, work, h, x, q, P, L) -> None:  # noqa: ANN001
    """The position stage: the midpoint impulse that puts the end configuration on g = 0 (module docstring)."""
    n = x.shape[0]
    half = 0.5 * h
    for b in range(n):  # the midpoint configuration of the step just taken
        inv_m = 1.0 / model.body_mass[b]
        work.x_mid[b, 0] = x[b, 0] - half * inv_m * P[b, 0]
        work.x_mid[b, 1] = x[b, 1] - half * inv_m * P[b, 1]
        work.x_mid[b, 2] = x[b, 2] - half * inv_m * P[b, 2]
        for c in range(4):
            work.q_mid[b, c] = q[b, c]
        w0, w1, w2 = _omega(model, q, L, b)
        _turn(work.q_mid, b, -half * w0, -half * w1, -half * w2)
    _body_weights(model, table, work, work.q_mid)
    joint_rows(table, work.x_mid, work.q_mid, work.jac_a, work.jac_b, work.residual, True)
    redundant = factor_rows(
        table.graph,
        work.solver,
        table.row_start,
        table.row_count,
        table.body_a,
        table.body_b,
        work.jac_a,
        work.jac_b,
        work.inv_mass,
        work.inv_inertia,
    )
    work.impulse[:] = 0.0
    worst = joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, False)
    iterations = 0
    scale = -2.0 / h
    while worst > 0.0 and iterations < NEWTON_ITERATIONS:
        for r in range(work.rhs.shape[0]):
            work.rhs[r] = scale * work.residual[r]
        solve_rows(
            table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b, work.rhs, work.delta
        )
        for r in range(work.delta.shape[0]):
            work.impulse[r] += work.delta[r]
        _gather_impulses(table, work, work.delta)
        for b in range(n):
            if table.body_ground[b]:
                continue
            d = work.impulse_body[b]
            if d[0] == 0.0 and d[1] == 0.0 and d[2] == 0.0 and d[3] == 0.0 and d[4] == 0.0 and d[5] == 0.0:
                continue  # a body without joints
            P[b, 0] += d[0]
            P[b, 1] += d[1]
            P[b, 2] += d[2]
            L[b, 0] += d[3]
            L[b, 1] += d[4]
            L[b, 2] += d[5]
            drift = half * work.inv_mass[b]
            x[b, 0] += drift * d[0]
            x[b, 1] += drift * d[1]
            x[b, 2] += drift * d[2]
            W = work.inv_inertia[b]
            t0 = half * (W[0, 0] * d[3] + W[0, 1] * d[4] + W[0, 2] * d[5])
            t1 = half * (W[1, 0] * d[3] + W[1, 1] * d[4] + W[1, 2] * d[5])
            t2 = half * (W[2, 0] * d[3] + W[2, 1] * d[4] + W[2, 2] * d[5])
            _turn(q, b, t0, t1, t2)
        iterations += 1
        previous = worst
        worst = joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, False)
        if worst > NEWTON_STALL * previous:
            break
    work.stats[STAT_ITERATIONS] = iterations
    work.stats[STAT_POSITION] = worst
    work.stats[STAT_REDUNDANT] = redundant


@numba.njit(cache=True)
def joint_velocity(model, table, work, h, x, q, P, L) -> None:  # noqa: ANN001
    """The velocity stage: (P, L) -= G^T mu with G V = 0 after it, G at the end configuration."""
    _body_weights(model, table, work, q)
    joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, True)
    factor_rows(
        table.graph,
        work.solver,
        table.row_start,
        table.row_count,
        table.body_a,
        table.body_b,
        work.jac_a,
        work.jac_b,
        work.inv_mass,
        work.inv_inertia,
    )
    row_velocities(model, table, work, q, P, L)
    solve_rows(
        table.graph,
        work.solver,
        table.row_start,
        table.row_count,
        table.body_a,
        table.body_b,
        work.residual,
        work.delta,
    )
    for r in range(work.delta.shape[0]):
        work.delta[r] = -work.delta[r]
        work.impulse[r] += work.delta[r]
    _gather_impulses(table, work, work.delta)
    for b in range(x.shape[0]):
        if table.body_ground[b]:
            continue
        d = work.impulse_body[b]
        P[b, 0] += d[0]
        P[b, 1] += d[1]
        P[b, 2] += d[2]
        L[b, 0] += d[3]
        L[b, 1] += d[4]
        L[b, 2] += d[5]
    for j in range(table.kind.shape[0]):
        if table.motor_cap[j] > 0.0 or table.damping[j] > 0.0:
            _drive(model, table, work, j, h, x, q, P, L)
    work.stats[STAT_VELOCITY] = row_velocities(model, table, work, q, P, L)


@numba.njit(cache=True)
def _drive(model, table, work, j, h, x, q, P, L) -> None:  # noqa: ANN001
    """Joint j's motor and damper, acting on its rate r = J V within the joints' constraints.

    The rate of a hinge is r = (omega_a - omega_b) . u (u = R_a u_a), of a slider r = d/dt ((p_a - p_b) . u)
    (u = R_b u_b, the axis carried by body b). An impulse lambda along J, followed by the projection that
    keeps every joint's G V = 0, changes r by k lambda, with k = J W J^T - (G W J^T)^T A^-1 (G W J^T) the
    inverse effective inertia (or mass) of the rate inside the constraints. The motor takes the impulse
    that brings r to its speed, capped at |lambda| <= cap h (the torque or force cap over the step); the
    damper then makes r decay by the exact flow of dr/dt = -c k r over the step, r <- r exp(-c k h)
    (a flywheel on a damped hinge decays at the analytic rate exp(-c t / I), to round-off). Both at the
    velocity level, after the step's projection: first order in time for the motor's switching.
    """
    a, b = table.body_a[j], table.body_b[j]
    aw, ax, ay, az = q[a, 0], q[a, 1], q[a, 2], q[a, 3]
    if b >= 0:
        bw, bx, by, bz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    else:
        bw, bx, by, bz = 1.0, 0.0, 0.0, 0.0
    if table.kind[j] == JOINT_HINGE:
        u0, u1, u2 = rotate(aw, ax, ay, az, table.axis_a[j, 0], table.axis_a[j, 1], table.axis_a[j, 2])
        ja = (0.0, 0.0, 0.0, u0, u1, u2)
        jb = (0.0, 0.0, 0.0, -u0, -u1, -u2)
    else:  # slider: the axis is n_b1 x n_b2 in b's frame
        n1, n2 = table.normal_b[j, 0], table.normal_b[j, 1]
        c0, c1, c2 = n1[1] * n2[2] - n1[2] * n2[1], n1[2] * n2[0] - n1[0] * n2[2], n1[0] * n2[1] - n1[1] * n2[0]
        u0, u1, u2 = rotate(bw, bx, by, bz, c0, c1, c2)
        ra0, ra1, ra2 = rotate(aw, ax, ay, az, table.anchor_a[j, 0], table.anchor_a[j, 1], table.anchor_a[j, 2])
        if b >= 0:
            rb0, rb1, rb2 = rotate(bw, bx, by, bz, table.anchor_b[j, 0], table.anchor_b[j, 1], table.anchor_b[j, 2])
            pb0, pb1, pb2 = x[b, 0] + rb0, x[b, 1] + rb1, x[b, 2] + rb2
        else:
            rb0, rb1, rb2 = 0.0, 0.0, 0.0
            pb0, pb1, pb2 = table.anchor_b[j, 0], table.anchor_b[j, 1], table.anchor_b[j, 2]
        d0, d1, d2 = x[a, 0] + ra0 - pb0, x[a, 1] + ra1 - pb1, x[a, 2] + ra2 - pb2
        ja = (u0, u1, u2, ra1 * u2 - ra2 * u1, ra2 * u0 - ra0 * u2, ra0 * u1 - ra1 * u0)
        jb = (
            -u0,
            -u1,
            -u2,
            -(rb1 * u2 - rb2 * u1) + (u1 * d2 - u2 * d1),
            -(rb2 * u0 - rb0 * u2) + (u2 * d0 - u0 * d2),
            -(rb0 * u1 - rb1 * u0) + (u0 * d1 - u1 * d0),
        )
    wa, wb = _weigh(work, a, ja), _weigh(work, b, jb)
    # G W J^T per row (only rows on a or b couple), then y = A^-1 G W J^T with the end factor
    for k in range(table.kind.shape[0]):
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
    if not k_inv > 0.0:  # the rate cannot move (both ends fixed, or the constraints forbid it)
        return
    rate = _rate(model, q, P, L, x, a, b, ja, jb)
    impulse = 0.0
    if table.motor_cap[j] > 0.0:
        cap = table.motor_cap[j] * h
        impulse = min(max((table.motor_speed[j] - rate) / k_inv, -cap), cap)
        rate += k_inv * impulse
    if table.damping[j] > 0.0:
        impulse += rate * (math.exp(-table.damping[j] * k_inv * h) - 1.0) / k_inv
    # J^T lambda on the joint's bodies, then -G^T (y lambda) so every joint's G V stays 0
    for r in range(work.delta.shape[0]):
        work.delta[r] = -work.delta[r] * impulse
        work.impulse[r] += work.delta[r]
    _gather_impulses(table, work, work.delta)
    for c in range(6):
        work.impulse_body[a, c] += ja[c] * impulse
        if b >= 0:
            work.impulse_body[b, c] += jb[c] * impulse
    for body in range(x.shape[0]):
        if table.body_ground[body]:
            continue
        d = work.impulse_body[body]
        P[body, 0] += d[0]
        P[body, 1] += d[1]
        P[body, 2] += d[2]
        L[body, 0] += d[3]
        L[body, 1] += d[4]
        L[body, 2] += d[5]


@numba.njit(cache=True, inline="always")
def _weigh(work, body, jac):  # noqa: ANN001, ANN202
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


@numba.njit(cache=True, inline="always")
def _rate(model, q, P, L, x, a, b, ja, jb) -> float:  # noqa: ANN001
    """J V: the drive's rate from the bodies' own velocities (a ground body's too)."""
    inv = 1.0 / model.body_mass[a]
    oa0, oa1, oa2 = _omega(model, q, L, a)
    rate = inv * (ja[0] * P[a, 0] + ja[1] * P[a, 1] + ja[2] * P[a, 2]) + ja[3] * oa0 + ja[4] * oa1 + ja[5] * oa2
    if b >= 0:
        inv = 1.0 / model.body_mass[b]
        ob0, ob1, ob2 = _omega(model, q, L, b)
        rate += inv * (jb[0] * P[b, 0] + jb[1] * P[b, 1] + jb[2] * P[b, 2]) + jb[3] * ob0 + jb[4] * ob1 + jb[5] * ob2
    return rate


@numba.njit(cache=True)
def row_velocities(model, table, work, q, P, L) -> float:  # noqa: ANN001
    """residual = G V (every body's own velocity, ground bodies' too); returns max |G V|."""
    worst = 0.0
    for j in range(table.kind.shape[0]):
        a, b = table.body_a[j], table.body_b[j]
        inv_a = 1.0 / model.body_mass[a]
        oa0, oa1, oa2 = _omega(model, q, L, a)
        va = (inv_a * P[a, 0], inv_a * P[a, 1], inv_a * P[a, 2], oa0, oa1, oa2)
        vb = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        if b >= 0:
            inv_b = 1.0 / model.body_mass[b]
            ob0, ob1, ob2 = _omega(model, q, L, b)
            vb = (inv_b * P[b, 0], inv_b * P[b, 1], inv_b * P[b, 2], ob0, ob1, ob2)
        for r in range(table.row_start[j], table.row_start[j] + table.row_count[j]):
            total = 0.0
            for c in range(6):
                total += work.jac_a[r, c] * va[c] + work.jac_b[r, c] * vb[c]
            work.residual[r] = total
            worst = max(worst, abs(total))
    return worst


# ---- the pipeline's dispatchers: compiled to nothing for a scene without joints ---------------------


def _absent(*argument_types: types.Type) -> bool:
    return any(isinstance(t, types.NoneType) for t in argument_types)


def _member(tuple_type: Any, name: str) -> types.Type:  # noqa: ANN401 - a numba NamedTuple type
    return dict(zip(tuple_type.fields, tuple_type.types, strict=True))[name]


def joint_position_stage(model, forces, force_data, h, x, q, P, L) -> None:  # noqa: ANN001
    """`joint_position` when the scene has joints (forces.joint is not None)."""
    raise TypeError("a stage dispatcher runs in compiled kernels only (physics/joints/stages.py)")


@overload(joint_position_stage, jit_options=_OPTIONS)
def _joint_position_stage(model, forces, force_data, h, x, q, P, L):  # noqa: ANN001, ANN202
    if _absent(_member(forces, "joint"), _member(force_data, "joint")):
        return lambda model, forces, force_data, h, x, q, P, L: None

    def run(model, forces, force_data, h, x, q, P, L):  # noqa: ANN001, ANN202
        joint_position(model, forces.joint, force_data.joint, h, x, q, P, L)

    return run


def joint_velocity_stage(model, forces, force_data, h, x, q, P, L) -> None:  # noqa: ANN001
    """`joint_velocity` when the scene has joints (forces.joint is not None)."""
    raise TypeError("a stage dispatcher runs in compiled kernels only (physics/joints/stages.py)")


@overload(joint_velocity_stage, jit_options=_OPTIONS)
def _joint_velocity_stage(model, forces, force_data, h, x, q, P, L):  # noqa: ANN001, ANN202
    if _absent(_member(forces, "joint"), _member(force_data, "joint")):
        return lambda model, forces, force_data, h, x, q, P, L: None

    def run(model, forces, force_data, h, x, q, P, L):  # noqa: ANN001, ANN202
        joint_velocity(model, forces.joint, force_data.joint, h, x, q, P, L)

    return run
