"""The joints' constraint rows at a configuration: residuals g and Jacobians G (compiled; numpy twin in
reference.py). tables.py lists each type's rows; the derivations:

    point rows      g = p_a - p_b, p = x + R r:  d g_i/dt = v_a . e_i + omega_a . (r_a x e_i) - (same for b),
                    since (omega x r) . e = omega . (r x e)
    axis rows       g = u . n with u = R_a u_a, n = R_b n_b:  dg/dt = (omega_a - omega_b) . (u x n)
    offset rows     g = d . n, d = p_a - p_b:  dg/dt = (v_a + omega_a x r_a - v_b - omega_b x r_b) . n
                    + d . (omega_b x n), the last term omega_b . (n x d)
    rotation rows   e = q_a c^* q_b^*, g = 2 vec(e):  with de/dt = (omega_a e - e omega_b) / 2 (pure
                    quaternions), d(2 v_e)/dt = (w_e 1 - [v_e]x) omega_a - (w_e 1 + [v_e]x) omega_b
    distance row    g = |d| - l:  dg/dt = n . (v_a + omega_a x r_a - v_b - omega_b x r_b), n = d / |d|

Every Jacobian is exact at its configuration, so the velocity stage's projection G V = 0 is the exact
tangency condition, and the position stage's Newton iteration uses them with its own fixed matrix.
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.integrators.kinematics import rotate
from rbcli.physics.joints.tables import JOINT_BALL, JOINT_DISTANCE, JOINT_FIXED, JOINT_HINGE, JOINT_SLIDER
from rbcli.physics.kernel_link import separately_compiled


@separately_compiled
@numba.njit(cache=True)
def joint_rows(table, x, q, jac_a, jac_b, residual, with_jacobian) -> float:  # noqa: ANN001
    """g (residual) of every row at (x, q), and G (jac_a, jac_b) when with_jacobian; returns max |g|."""
    worst = 0.0
    for j in range(table.kind.shape[0]):
        a, b, r0, kind = table.body_a[j], table.body_b[j], table.row_start[j], table.kind[j]
        aw, ax, ay, az = q[a, 0], q[a, 1], q[a, 2], q[a, 3]
        ra0, ra1, ra2 = rotate(aw, ax, ay, az, table.anchor_a[j, 0], table.anchor_a[j, 1], table.anchor_a[j, 2])
        if b >= 0:
            bw, bx, by, bz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
            rb0, rb1, rb2 = rotate(bw, bx, by, bz, table.anchor_b[j, 0], table.anchor_b[j, 1], table.anchor_b[j, 2])
            pb0, pb1, pb2 = x[b, 0] + rb0, x[b, 1] + rb1, x[b, 2] + rb2
        else:
            bw, bx, by, bz = 1.0, 0.0, 0.0, 0.0
            rb0, rb1, rb2 = 0.0, 0.0, 0.0
            pb0, pb1, pb2 = table.anchor_b[j, 0], table.anchor_b[j, 1], table.anchor_b[j, 2]
        d0, d1, d2 = x[a, 0] + ra0 - pb0, x[a, 1] + ra1 - pb1, x[a, 2] + ra2 - pb2
        r = r0
        if kind == JOINT_BALL or kind == JOINT_HINGE or kind == JOINT_FIXED:
            for i in range(3):
                e0, e1, e2 = (1.0 if i == 0 else 0.0), (1.0 if i == 1 else 0.0), (1.0 if i == 2 else 0.0)
                residual[r] = d0 if i == 0 else (d1 if i == 1 else d2)
                if with_jacobian:
                    _linear_row(jac_a, jac_b, r, e0, e1, e2, ra0, ra1, ra2, rb0, rb1, rb2, 0.0, 0.0, 0.0)
                r += 1
        if kind == JOINT_DISTANCE:
            length = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            residual[r] = length - table.length[j]
            if with_jacobian:
                inv = 1.0 / length if length > 0.0 else 0.0
                _linear_row(jac_a, jac_b, r, d0 * inv, d1 * inv, d2 * inv, ra0, ra1, ra2, rb0, rb1, rb2, 0.0, 0.0, 0.0)
            r += 1
        if kind == JOINT_FIXED or kind == JOINT_SLIDER:
            r = _rotation_rows(table, j, r, aw, ax, ay, az, bw, bx, by, bz, jac_a, jac_b, residual, with_jacobian)
        if kind == JOINT_HINGE:
            u0, u1, u2 = rotate(aw, ax, ay, az, table.axis_a[j, 0], table.axis_a[j, 1], table.axis_a[j, 2])
            for k in range(2):
                n0, n1, n2 = rotate(
                    bw, bx, by, bz, table.normal_b[j, k, 0], table.normal_b[j, k, 1], table.normal_b[j, k, 2]
                )
                residual[r] = u0 * n0 + u1 * n1 + u2 * n2
                if with_jacobian:
                    c0, c1, c2 = u1 * n2 - u2 * n1, u2 * n0 - u0 * n2, u0 * n1 - u1 * n0
                    for m in range(3):
                        jac_a[r, m], jac_b[r, m] = 0.0, 0.0
                    jac_a[r, 3], jac_a[r, 4], jac_a[r, 5] = c0, c1, c2
                    jac_b[r, 3], jac_b[r, 4], jac_b[r, 5] = -c0, -c1, -c2
                r += 1
        if kind == JOINT_SLIDER:
            for k in range(2):
                n0, n1, n2 = rotate(
                    bw, bx, by, bz, table.normal_b[j, k, 0], table.normal_b[j, k, 1], table.normal_b[j, k, 2]
                )
                residual[r] = d0 * n0 + d1 * n1 + d2 * n2
                if with_jacobian:  # omega_b . (n x d): the normal turns with body b
                    t0, t1, t2 = n1 * d2 - n2 * d1, n2 * d0 - n0 * d2, n0 * d1 - n1 * d0
                    _linear_row(jac_a, jac_b, r, n0, n1, n2, ra0, ra1, ra2, rb0, rb1, rb2, t0, t1, t2)
                r += 1
        for s in range(r0, r):
            worst = max(worst, abs(residual[s]))
    return worst


@numba.njit(cache=True, inline="always")
def _linear_row(jac_a, jac_b, r, n0, n1, n2, ra0, ra1, ra2, rb0, rb1, rb2, t0, t1, t2) -> None:  # noqa: ANN001
    """Row r of g = d . n (n held): (n, r_a x n) for a, (-n, -(r_b x n) + t) for b (t: n's own turn)."""
    jac_a[r, 0], jac_a[r, 1], jac_a[r, 2] = n0, n1, n2
    jac_a[r, 3], jac_a[r, 4], jac_a[r, 5] = ra1 * n2 - ra2 * n1, ra2 * n0 - ra0 * n2, ra0 * n1 - ra1 * n0
    jac_b[r, 0], jac_b[r, 1], jac_b[r, 2] = -n0, -n1, -n2
    jac_b[r, 3] = -(rb1 * n2 - rb2 * n1) + t0
    jac_b[r, 4] = -(rb2 * n0 - rb0 * n2) + t1
    jac_b[r, 5] = -(rb0 * n1 - rb1 * n0) + t2


@numba.njit(cache=True, inline="always")
def quaternion_product(aw, ax, ay, az, bw, bx, by, bz):  # noqa: ANN001, ANN202
    """Hamilton product a b of quaternions (w, x, y, z)."""
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@numba.njit(cache=True, inline="always")
def _rotation_rows(table, j, r, aw, ax, ay, az, bw, bx, by, bz, jac_a, jac_b, residual, with_jacobian) -> int:  # noqa: ANN001
    """The three relative-rotation rows of joint j from row r; returns the next row."""
    c = table.relative_q[j]
    tw, tx, ty, tz = quaternion_product(aw, ax, ay, az, c[0], -c[1], -c[2], -c[3])
    ew, ex, ey, ez = quaternion_product(tw, tx, ty, tz, bw, -bx, -by, -bz)
    if ew < 0.0:  # e and -e are the same rotation: take the one near 1
        ew, ex, ey, ez = -ew, -ex, -ey, -ez
    for i in range(3):
        residual[r] = 2.0 * (ex if i == 0 else (ey if i == 1 else ez))
        if with_jacobian:  # row i of (w_e 1 - [v_e]x) for omega_a and of -(w_e 1 + [v_e]x) for omega_b
            for m in range(3):
                jac_a[r, m], jac_b[r, m] = 0.0, 0.0
            k0, k1, k2 = _cross_row(i, ex, ey, ez)
            jac_a[r, 3], jac_a[r, 4], jac_a[r, 5] = -k0, -k1, -k2
            jac_b[r, 3], jac_b[r, 4], jac_b[r, 5] = -k0, -k1, -k2
            jac_a[r, 3 + i] += ew
            jac_b[r, 3 + i] -= ew
        r += 1
    return r


@numba.njit(cache=True, inline="always")
def _cross_row(i, vx, vy, vz):  # noqa: ANN001, ANN202
    """Row i of the cross-product matrix [v]x ([v]x w = v x w)."""
    if i == 0:
        return 0.0, -vz, vy
    if i == 1:
        return vz, 0.0, -vx
    return -vy, vx, 0.0
