"""Per-body rigid-body kinematics shared by the integrator kernels: compiled scalar functions plus
their numpy twins for the reference steps.

Conventions (state.py): q = (w, x, y, z) unit quaternion, world-from-PRINCIPAL frame, so R(q) maps
body (principal) components to world ones; L world angular momentum; body_inertia_inv = 1 / I_k.
  body momentum        m = R^T L                        (principal frame)
  angular velocity     omega_body = m / I,  omega = R omega_body (world)
  quaternion rate      dq/dt = 1/2 (0, omega) * q = 1/2 q * (0, omega_body)
  axis turn            the body turns by theta about its own principal axis k:
                       q <- q * (cos(theta/2), sin(theta/2) e_k),  m <- Rot_k(-theta) m,  L unchanged.
The axis turn with theta = h m_k / I_k is the exact flow, over a time h, of T_k = m_k^2 / (2 I_k),
one of the three pieces of the free body's kinetic energy (McLachlan 1993; Reich 1994; Dullweber,
Leimkuhler & McLachlan 1997): m_k is constant along it, so the turn is a plane rotation of
(m_i, m_j), (i, j, k) cyclic. The scalar functions take and return plain floats so numba keeps
everything in registers (no per-body arrays).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.rotation import quat_multiply, quat_rotate, quat_rotate_inverse

# rotate and rotate_inverse live with the other one-body rotation kernels; imported here for the integrators
from rbcli.physics.rotation_kernels import rotate, rotate_inverse  # noqa: F401

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True)
def carried_momentum_valid(s, q_end, l_end, q, L, b):  # noqa: ANN001, ANN201
    """Whether the state (q, L) of body b is bitwise what the last step wrote into its scratch row s
    (columns q_end..q_end+3, l_end..l_end+2): then the body momentum m that step carried belongs to it.

    Why carry m: near the separatrix the motion is decided by m's small components, and R(q)^T L gives
    them only to an ulp of |L| (q is rounded to an ulp), a fresh error at every step (docs/accuracy.md).
    Anything else that wrote q or L (an impulse, a state set from outside, a reset, the first step's
    zeroed scratch) fails this test, and the caller rebuilds m as R^T L."""
    return (
        q[b, 0] == s[q_end] and q[b, 1] == s[q_end + 1] and q[b, 2] == s[q_end + 2] and q[b, 3] == s[q_end + 3]
        and L[b, 0] == s[l_end] and L[b, 1] == s[l_end + 1] and L[b, 2] == s[l_end + 2]
    )  # fmt: skip


@numba.njit(cache=True)
def axis_order(i0, i1, i2):  # noqa: ANN001, ANN201
    """Principal axis indices (a, b, c) sorted by moment: I_a <= I_b <= I_c (ties keep index order)."""
    if i0 <= i1:
        if i1 <= i2:
            return 0, 1, 2
        if i0 <= i2:
            return 0, 2, 1
        return 2, 0, 1
    if i0 <= i2:
        return 1, 0, 2
    if i1 <= i2:
        return 1, 2, 0
    return 2, 1, 0


@numba.njit(cache=True)
def half_turn(k, h, m0, m1, m2, inv0, inv1, inv2):  # noqa: ANN001, ANN201
    """(cos, sin) of half the angle theta = h m_k / I_k that the flow of T_k turns the body in time h."""
    if k == 0:
        half = 0.5 * h * m0 * inv0
    elif k == 1:
        half = 0.5 * h * m1 * inv1
    else:
        half = 0.5 * h * m2 * inv2
    return small_angle_cos_sin(half)


@numba.njit(cache=True, inline="always")
def small_angle_cos_sin(a):  # noqa: ANN001, ANN201
    """(cos a, sin a): Taylor polynomials for |a| <= 1/16, libm beyond.

    Half-angles of a turn are omega h / 2, small at any sane dt, and libm's sin/cos were half of split2's
    per-body time. Truncation: the first omitted terms are a^11/11! and a^12/12!, < 3e-20 relative at
    |a| = 1/16, far below an ulp; Horner evaluation keeps the result within ~1 ulp of libm (tested).
    """
    if abs(a) <= 0.0625:
        a2 = a * a
        s = a + a * a2 * (-1.0 / 6.0 + a2 * (1.0 / 120.0 + a2 * (-1.0 / 5040.0 + a2 * (1.0 / 362880.0))))
        c = 1.0 + a2 * (-0.5 + a2 * (1.0 / 24.0 + a2 * (-1.0 / 720.0 + a2 * (1.0 / 40320.0 - a2 / 3628800.0))))
        return c, s
    return math.cos(a), math.sin(a)


@numba.njit(cache=True)
def turn(k, c, s, m0, m1, m2, w, x, y, z):  # noqa: ANN001, ANN201
    """Turn the body about its principal axis k by theta (c = cos(theta/2), s = sin(theta/2)).

    Returns (m0, m1, m2, w, x, y, z): m <- Rot_k(-theta) m (m_i' = m_i cos + m_j sin,
    m_j' = m_j cos - m_i sin, (i, j, k) cyclic) and q <- q * (c, s e_k).
    """
    # m turns as m + (cos(theta) - 1) m + sin(theta) m_perp with cos(theta) - 1 = -2 s^2 and
    # sin(theta) = 2 s c from the half angle (no second sin/cos). Why not m cos(theta) + m_perp sin(theta):
    # c = cos(theta/2) is rounded to an ulp of 1, and at a steady spin the same angle comes back at every
    # step, so that rounding scales the pair by the same 1 + 1e-16 each time; near the separatrix that
    # moved the flip (2 E I_2 - |L|^2 changed by 1e-7 of itself per flip, docs/accuracy.md). In this form
    # the scale is 1 + 4 s^2 (c^2 + s^2 - 1): the rounding of c enters times s^2.
    cm = -2.0 * s * s
    st = 2.0 * s * c
    if k == 0:
        return (m0, m1 + (m1 * cm + m2 * st), m2 + (m2 * cm - m1 * st),
                w * c - x * s, x * c + w * s, y * c + z * s, z * c - y * s)  # fmt: skip
    if k == 1:
        return (m0 + (m0 * cm - m2 * st), m1, m2 + (m2 * cm + m0 * st),
                w * c - y * s, x * c - z * s, y * c + w * s, z * c + x * s)  # fmt: skip
    return (m0 + (m0 * cm + m1 * st), m1 + (m1 * cm - m0 * st), m2,
            w * c - z * s, x * c + y * s, y * c - x * s, z * c + w * s)  # fmt: skip


@numba.njit(cache=True)
def sum_compensated(y, d, e):  # noqa: ANN001, ANN201
    """(y + d, the part of d that rounding lost), with e the part lost before (Kahan summation)."""
    d = d + e
    y_new = y + d
    return y_new, (y - y_new) + d


# a call, not inline="always": inlined into each of split4's 21 turns per body-step it saved ~20 % of
# split4's step but made every split2/split4 loop compile for 40+ s instead of ~10 s (a first run, the suite)
@numba.njit(cache=True)
def turn_compensated(k, c, s, m0, m1, m2, e0, e1, e2, w, x, y, z, compensate=True):  # noqa: ANN001, ANN201
    """`turn` with m summed with compensation: e = (e0, e1, e2) carries what rounding m + increment
    lost (Kahan), so the small components of m, which decide the motion near the separatrix, do not
    random-walk by an ulp of the large one per turn. Returns (m0, m1, m2, e0, e1, e2, w, x, y, z).
    compensate=False: plain sums, e returned unchanged (split2: its truncation error is far above)."""
    cm = -2.0 * s * s
    st = 2.0 * s * c
    if not compensate:
        m0n, m1n, m2n, wn, xn, yn, zn = turn(k, c, s, m0, m1, m2, w, x, y, z)
        return m0n, m1n, m2n, e0, e1, e2, wn, xn, yn, zn
    if k == 0:
        m1n, e1 = sum_compensated(m1, m1 * cm + m2 * st, e1)
        m2n, e2 = sum_compensated(m2, m2 * cm - m1 * st, e2)
        return (m0, m1n, m2n, e0, e1, e2,
                w * c - x * s, x * c + w * s, y * c + z * s, z * c - y * s)  # fmt: skip
    if k == 1:
        m0n, e0 = sum_compensated(m0, m0 * cm - m2 * st, e0)
        m2n, e2 = sum_compensated(m2, m2 * cm + m0 * st, e2)
        return (m0n, m1, m2n, e0, e1, e2,
                w * c - y * s, x * c - z * s, y * c + w * s, z * c + x * s)  # fmt: skip
    m0n, e0 = sum_compensated(m0, m0 * cm + m1 * st, e0)
    m1n, e1 = sum_compensated(m1, m1 * cm - m0 * st, e1)
    return (m0n, m1n, m2, e0, e1, e2,
            w * c - z * s, x * c + y * s, y * c - x * s, z * c + w * s)  # fmt: skip


# ---- numpy twins (vectorised over bodies) for the reference steps -------------------------------


def axis_order_numpy(inertia: np.ndarray) -> np.ndarray:
    """(body_count, 3) int: per body the axes (a, b, c) with I_a <= I_b <= I_c (stable)."""
    return np.argsort(inertia, axis=-1, kind="stable")


def turn_numpy(
    axis: np.ndarray, h: float, m: np.ndarray, q: np.ndarray, inertia_inv: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The flow of T_k over time h for each body's axis k = axis[b]; returns new (m, q)."""
    rows = np.arange(m.shape[0])
    half = 0.5 * h * m[rows, axis] * inertia_inv[rows, axis]
    c, s = np.cos(half), np.sin(half)
    turn_q = np.zeros_like(q)
    turn_q[:, 0] = c
    turn_q[rows, 1 + axis] = s
    i, j = (axis + 1) % 3, (axis + 2) % 3
    ct, st = c * c - s * s, 2.0 * s * c
    mi, mj = m[rows, i], m[rows, j]
    m = m.copy()
    m[rows, i] = mi * ct + mj * st
    m[rows, j] = mj * ct - mi * st
    return m, quat_multiply(q, turn_q)


def body_momentum_numpy(q: np.ndarray, L: np.ndarray) -> np.ndarray:
    """m = R(q)^T L, (body_count, 3)."""
    return quat_rotate_inverse(q, L)


def angular_velocity_numpy(q: np.ndarray, L: np.ndarray, inertia_inv: np.ndarray) -> np.ndarray:
    """World omega = R diag(1/I) R^T L, (body_count, 3)."""
    return quat_rotate(q, inertia_inv * quat_rotate_inverse(q, L))
