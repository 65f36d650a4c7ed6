"""A ball joint's swing and twist (the coordinates its cone and twist limits act on, drives.py).

The joint frame: x the cone axis, y the reference, z = x cross y; f_a and f_b (JointTable.cone[:, 0:4],
[:, 4:8]) are its orientation in each end's principal frame (the world's for the world end), equal in
the world at the initial poses. The relative rotation of a's joint frame in b's,

    Q = (q_b f_b)^* (q_a f_a),   Q = 1 at the initial poses,

is split into a swing and a twist, Q = S T (Jolt's SwingTwistConstraintPart, PhysX's D6 decomposition):
T = (w, x, 0, 0) / n a turn about the axis by the twist angle tau = 2 atan2(x, w) (n = sqrt(w^2 + x^2),
Q taken with w >= 0, so tau in [-pi, pi]), and S = Q T^* = (n, 0, (w y - x z) / n, (w z + x y) / n) a turn
about an axis across x by the swing angle phi = 2 atan2(m, n), m = sqrt(y^2 + z^2): the angle between
a's axis and b's. The swing's rotation vector r = phi (0, S_y, S_z) / m tilts a's axis toward b's
reference y by r_z and toward z by -r_y. With the cone's half-angles a1 (toward y) and a2 (toward z) the
swing limit is c <= 1 on

    c = sqrt((r_z / a1)^2 + (r_y / a2)^2),

which is phi / a for a circular cone (a1 = a2 = a) and the normalised ellipse f = c^2 - 1 in general: its
row is the gradient of c, the direction that increases the cone's violation fastest. Both coordinates are
even in Q (the same for -Q). Their rates: with dQ/dt = 1/2 (0, w_b) Q, w_b = R(q_b f_b)^T (omega_a -
omega_b) (the relative angular velocity in b's joint frame), a function h(Q) changes at

    dh/dt = j . w_b,   j = 1/2 (-dh/dQ_w v + Q_w dh/dv + v x dh/dv),   v = (Q_x, Q_y, Q_z),

so the row is J_a = (0, R(q_b f_b) j), J_b = -J_a (angular only, as the hinge's). The twist is singular at
a swing of a half turn (n = 0), the swing's row at no swing (m = 0, where c = 0 is far from its bound).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.integrators.kinematics import rotate
from rbcli.physics.joints.rows import quaternion_product


@numba.njit(cache=True)
def relative_rotation(table, j, qa, qb):  # noqa: ANN001, ANN202
    """(Q, p_b): Q = (q_b f_b)^* (q_a f_a) of joint j with w >= 0, and p_b = q_b f_b (world-from-b's joint
    frame); qa, qb 4-tuples (qb = 1 for the world)."""
    f = table.cone[j]  # [0:4] f_a, [4:8] f_b (tables.CONE_FRAME_A, CONE_FRAME_B)
    pa = quaternion_product(qa[0], qa[1], qa[2], qa[3], f[0], f[1], f[2], f[3])
    pb = quaternion_product(qb[0], qb[1], qb[2], qb[3], f[4], f[5], f[6], f[7])
    Q = quaternion_product(pb[0], -pb[1], -pb[2], -pb[3], pa[0], pa[1], pa[2], pa[3])
    if Q[0] < 0.0:
        Q = (-Q[0], -Q[1], -Q[2], -Q[3])
    return Q, pb


@numba.njit(cache=True, inline="always")
def _rate_row(Q, gw, gx, gy, gz):  # noqa: ANN001, ANN202
    """j = 1/2 (-g_w v + Q_w g_v + v x g_v) for the gradient g = dh/dQ (module docstring)."""
    w, x, y, z = Q
    return (
        0.5 * (-gw * x + w * gx + (y * gz - z * gy)),
        0.5 * (-gw * y + w * gy + (z * gx - x * gz)),
        0.5 * (-gw * z + w * gz + (x * gy - y * gx)),
    )


@numba.njit(cache=True)
def twist_angle_row(Q):  # noqa: ANN001, ANN202
    """(tau, j): the twist angle [rad] of Q (w >= 0) and its rate's row in b's joint frame."""
    w, x = Q[0], Q[1]
    n2 = w * w + x * x
    if n2 == 0.0:  # a swing of a half turn: no twist defined
        return 0.0, (0.0, 0.0, 0.0)
    tau = 2.0 * math.atan2(x, w)
    return tau, _rate_row(Q, -2.0 * x / n2, 2.0 * w / n2, 0.0, 0.0)


@numba.njit(cache=True)
def swing_vector(Q):  # noqa: ANN001, ANN202
    """(phi, r_y, r_z): the swing angle [rad] of Q and its rotation vector's components across the axis."""
    w, x, y, z = Q
    n, m = math.sqrt(w * w + x * x), math.sqrt(y * y + z * z)
    phi = 2.0 * math.atan2(m, n)
    if m == 0.0:
        return 0.0, 0.0, 0.0
    g = phi / (m * n)
    return phi, g * (w * y - x * z), g * (w * z + x * y)


@numba.njit(cache=True)
def swing_measure_row(Q, a1, a2):  # noqa: ANN001, ANN202
    """(c, j): the cone measure c = sqrt((r_z / a1)^2 + (r_y / a2)^2) of Q (<= 1 inside the cone; module
    docstring) and its rate's row in b's joint frame; (0, 0) at no swing."""
    w, x, y, z = Q
    n, m = math.sqrt(w * w + x * x), math.sqrt(y * y + z * z)
    if m == 0.0 or n == 0.0:
        return 0.0, (0.0, 0.0, 0.0)
    phi = 2.0 * math.atan2(m, n)
    A, B = w * y - x * z, w * z + x * y  # r_y = g A, r_z = g B
    g = phi / (m * n)
    i1, i2 = 1.0 / (a1 * a1), 1.0 / (a2 * a2)
    E = math.sqrt(B * B * i1 + A * A * i2)
    c = g * E
    # dphi = 2 (n dm - m dn) / (m^2 + n^2), dm = (0, 0, y, z) / m, dn = (w, x, 0, 0) / n
    s = 2.0 / (m * m + n * n)
    pw, px, py, pz = -s * m * w / n, -s * m * x / n, s * n * y / m, s * n * z / m
    # dg = dphi / (m n) - g (dm / m + dn / n)
    inv = 1.0 / (m * n)
    gw = pw * inv - g * w / (n * n)
    gx = px * inv - g * x / (n * n)
    gy = py * inv - g * y / (m * m)
    gz = pz * inv - g * z / (m * m)
    # dE = (B dB i1 + A dA i2) / E, dA = (y, -z, w, -x), dB = (z, y, x, w)
    ew = (B * z * i1 + A * y * i2) / E
    ex = (B * y * i1 - A * z * i2) / E
    ey = (B * x * i1 + A * w * i2) / E
    ez = (B * w * i1 - A * x * i2) / E
    return c, _rate_row(Q, E * gw + g * ew, E * gx + g * ex, E * gy + g * ey, E * gz + g * ez)


@numba.njit(cache=True)
def cone_row(table, j, swing, qa, qb):  # noqa: ANN001, ANN202
    """(c, J_a, J_b): joint j's swing measure (swing True; bound 1) or twist angle [rad], and its rate's row
    (6-tuples, world), at the ends' orientations qa, qb (4-tuples)."""
    Q, pb = relative_rotation(table, j, qa, qb)
    if swing:
        c, k = swing_measure_row(Q, table.cone[j, 8], table.cone[j, 9])
    else:
        c, k = twist_angle_row(Q)
    u = rotate(pb[0], pb[1], pb[2], pb[3], k[0], k[1], k[2])
    return c, (0.0, 0.0, 0.0, u[0], u[1], u[2]), (0.0, 0.0, 0.0, -u[0], -u[1], -u[2])


# ---- numpy twins (tests) -----------------------------------------------------------------------------


def swing_twist_numpy(Q: np.ndarray) -> tuple[float, np.ndarray]:
    """(tau, r): Q = S T by quaternion algebra: T the normalised (w, x, 0, 0), S = Q T^*; tau the twist angle
    [rad], r the swing's rotation vector (3,) [rad], r_x = 0."""
    Q = np.asarray(Q, dtype=np.float64)
    Q = -Q if Q[0] < 0 else Q
    T = np.array([Q[0], Q[1], 0.0, 0.0]) / np.hypot(Q[0], Q[1])
    w1, v1, w2, v2 = Q[0], Q[1:], T[0], -T[1:]
    S = np.r_[w1 * w2 - v1 @ v2, w1 * v2 + w2 * v1 + np.cross(v1, v2)]
    angle = 2.0 * np.arctan2(np.linalg.norm(S[1:]), S[0])
    r = np.zeros(3) if angle == 0.0 else angle * S[1:] / np.linalg.norm(S[1:])
    return float(2.0 * np.arctan2(T[1], T[0])), r


def swing_measure_numpy(Q: np.ndarray, a1: float, a2: float) -> float:
    """c of Q from swing_twist_numpy's rotation vector: sqrt((r_z / a1)^2 + (r_y / a2)^2)."""
    r = swing_twist_numpy(Q)[1]
    return float(np.hypot(r[2] / a1, r[1] / a2))
