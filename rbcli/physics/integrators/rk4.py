"""`rk4`: the classical fourth-order Runge-Kutta method, rotation integrated in the body frame.

The ODE (m = R^T L the body-frame angular momentum, q^ = q/|q|):
  dx/dt = P/M,  dP/dt = F,  dL/dt = tau                       (world)
  dm/dt = m x omega_b + R(q^)^T tau,  omega_b = diag(1/I) m  (Euler's equations, body frame)
  dq/dt = 1/2 q^ * (0, omega_b)
integrated together by RK4 (four wrench evaluations, at t, t + h/2 twice and t + h). Every stage's
quaternion is written normalised, so the forces always see a rotation; the right-hand side does not
change under q -> c q, so this is still exactly RK4 on one smooth ODE and keeps order 4.

Why the body frame: the obvious form, RK4 on the state's own (q, L) with omega = R I^-1 R^T L, is
also fourth order but its error constant is ruinous near the separatrix: every phase error of the
fast rotation goes straight into m = R^T L, which decides when the body flips. Measured on the
intermediate-axis flip (I = diag(1, 2, 3), omega0 = (0.01, 5, 0), dt = 0.01, 20 s): 2.4e-2 rad in
the (q, L) form against 3.5e-7 here. In the body form m obeys its own autonomous equation (slow
near the axis) and q only follows it.

L stays the state: L (world) is integrated by the same RK4, so torque-free it is kept exactly, and
at the end of the step q is turned by the smallest rotation that makes R(q) m parallel to L (the
"alignment"): then R(q) m is parallel to L again, and the turn is of the size of the local error,
O(h^5), so the order stays 4. Not symplectic: the energy drifts slowly (linearly in time), which long
runs show; split2 does not drift.

m is carried from one step to the next (in the scratch, with the q and L it belongs to), not rebuilt as
R(q)^T L at each step, and its sum is compensated (Kahan): near the separatrix the motion is decided by
the small components of m (the distance to the separatrix, 2 E I_2 - |L|^2 = m_1^2 - m_3^2/3 for
I = diag(1, 2, 3), does not contain m_2), and R(q)^T L computes them with an absolute error of an ulp
of |L|, from a q that is itself rounded to an ulp: 0.01 known to ~1e-15, at every step. That error
piles up in the flip's timing: on I = diag(1, 2, 3), omega0 = (0.01, 5, 0), 20 s, the error grew as
the step count, 1.6e-7 rad at dt = 1e-3 and 1.4e-6 at 1e-4, whatever the order. Carried, m_1 is
rounded to an ulp of itself; compensated, the low bits of each step's increment are not lost either
(carrying alone: 7e-9; both: the error falls as h^4 to 7e-11 at dt = 1e-4, docs/accuracy.md). m is
not rescaled to |L|: RK4's errors in |m| and in the energy nearly cancel in the distance to the
separatrix, and projecting |m| alone undid that (2.9e-8 rad at dt = 1e-3 instead of 9e-11); |m| stays
within the O(h^4) error of |L|, the size of the method's error anyway.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.forces.wrench import accumulate_wrench, wrench_numpy
from rbcli.physics.integrators.kinematics import carried_momentum_valid, rotate, rotate_inverse
from rbcli.physics.rotation import quat_multiply, quat_rotate, quat_rotate_inverse
from rbcli.physics.step import STEP_ENTRY, STEP_KERNEL

# per body: y0 = (x, q, P, L, m) (16), the weighted sum of stage rates (16), the stage's m (3), then
# what is carried from one step to the next: the compensation of each component's sum (16, those of q
# unused), the body momentum m (3) and the q (4) and L (3) it belongs to (the state the step wrote)
SCRATCH_WIDTH = 61
_SUM = 16
_M_STAGE = 32
_COMP = 35
_M_CARRIED = 51
_Q_END = 54
_L_END = 58

STAGE_FIRST = 0
STAGE_MIDDLE = 1
STAGE_LAST = 2


@numba.njit(cache=True)
def body_rates(w, x, y, z, m0, m1, m2, inv0, inv1, inv2):  # noqa: ANN001, ANN201 - numba scalars
    """Torque-free rates (dq/dt (4), dm/dt (3)) of a unit q: 1/2 q * (0, omega_b) and m x omega_b."""
    o0, o1, o2 = m0 * inv0, m1 * inv1, m2 * inv2
    return (
        -0.5 * (x * o0 + y * o1 + z * o2),
        0.5 * (w * o0 + y * o2 - z * o1),
        0.5 * (w * o1 + z * o0 - x * o2),
        0.5 * (w * o2 + x * o1 - y * o0),
        m1 * o2 - m2 * o1,
        m2 * o0 - m0 * o2,
        m0 * o1 - m1 * o0,
    )


@numba.njit(cache=True)
def align(w, x, y, z, m0, m1, m2, L0, L1, L2):  # noqa: ANN001, ANN201 - numba scalars
    """q turned (in the world) by the smallest rotation taking R(q) m onto the direction of L.

    The rotation from unit a to unit b is the quaternion (1 + a.b, a x b) normalised (half-angle
    formula); nothing to do when m or L is zero. q need not be unit (it is normalised first: R(q)
    of a non-unit q is not a rotation, and the error would be O(h^2) per step). Returns a unit q.
    """
    norm = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w * norm, x * norm, y * norm, z * norm
    v0, v1, v2 = rotate(w, x, y, z, m0, m1, m2)
    nv = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    nl = math.sqrt(L0 * L0 + L1 * L1 + L2 * L2)
    if nv > 0.0 and nl > 0.0:
        v0, v1, v2 = v0 / nv, v1 / nv, v2 / nv
        u0, u1, u2 = L0 / nl, L1 / nl, L2 / nl
        dw = 1.0 + v0 * u0 + v1 * u1 + v2 * u2
        d0, d1, d2 = v1 * u2 - v2 * u1, v2 * u0 - v0 * u2, v0 * u1 - v1 * u0
        w, x, y, z = (dw * w - d0 * x - d1 * y - d2 * z,  # d * q
                      dw * x + d0 * w + d1 * z - d2 * y,
                      dw * y - d0 * z + d1 * w + d2 * x,
                      dw * z + d0 * y - d1 * x + d2 * w)  # fmt: skip
    norm = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    return w * norm, x * norm, y * norm, z * norm


# per stage: where the wrench is evaluated (fraction of dt) and how far the next stage state reaches
_STAGE_TIME = np.array([0.0, 0.5, 0.5, 1.0])
_STAGE_REACH = np.array([0.5, 0.5, 1.0, 1.0])


@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One RK4 step of every body, in place: four wrench evaluations (one call site, so the compiled
    wrench is inlined once, not four times)."""
    for stage in range(4):
        accumulate_wrench(model, forces, contact, force_data, t + _STAGE_TIME[stage] * dt, x, q, P, L, F, tau)
        kind = STAGE_FIRST if stage == 0 else (STAGE_LAST if stage == 3 else STAGE_MIDDLE)
        reach = _STAGE_REACH[stage] * dt
        _stage(model, forces.has_torque, forces.torque_body, kind, reach, dt, x, q, P, L, F, tau, scratch)


@numba.njit(cache=True)
def _advance(s, j, kind, a, h, y, r):  # noqa: ANN001, ANN202
    """One component y with rate r: save y0 / accumulate / combine (see `_stage`); returns the new y."""
    if kind == STAGE_FIRST:
        s[j] = y
        s[_SUM + j] = r
        return y + a * r
    if kind == STAGE_MIDDLE:
        s[_SUM + j] += 2.0 * r
        return s[j] + a * r
    # compensated (Kahan) summation: the increment is O(h) y, so the rounding of y0 + increment
    # would discard its low bits at every step; the lost part is carried into the next increment
    increment = h / 6.0 * (s[_SUM + j] + r) + s[_COMP + j]
    y_new = s[j] + increment
    s[_COMP + j] = (s[j] - y_new) + increment
    return y_new


@numba.njit(cache=True)
def _advance_plain(s, j, kind, a, h, y, r):  # noqa: ANN001, ANN202
    """`_advance` without compensation (the quaternion: it is normalised and aligned after the sum)."""
    if kind == STAGE_FIRST:
        s[j] = y
        s[_SUM + j] = r
        return y + a * r
    if kind == STAGE_MIDDLE:
        s[_SUM + j] += 2.0 * r
        return s[j] + a * r
    return s[j] + h / 6.0 * (s[_SUM + j] + r)


@numba.njit(cache=True, inline="always")
def _carried(s) -> bool:  # noqa: ANN001
    """Whether L's stage sum or its compensation (scratch columns of L, 10..12) holds anything: the last
    stage must then combine them even where its own torque is zero."""
    return (s[_SUM + 10] != 0.0 or s[_SUM + 11] != 0.0 or s[_SUM + 12] != 0.0
            or s[_COMP + 10] != 0.0 or s[_COMP + 11] != 0.0 or s[_COMP + 12] != 0.0)  # fmt: skip


@numba.njit(**STEP_KERNEL)
def _stage(model, has_torque, torque_body, kind, a, h, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001
    """Rates k of the current stage (x, q, P, L, m; F and tau evaluated on it), then per component

    first:  y0 = y, sum = k,   y = y0 + a k          (m carried from the last step, or R^T L)
    middle: sum += 2 k,        y = y0 + a k
    last:   y = y0 + h/6 (sum + k) compensated (but q), then q aligned with L; m, q, L kept
    with q normalised after each update. Scratch columns: y0 0..15, sum 16..31, stage m 32..34,
    compensations 35..50, carried m 51..53, the q and L the step wrote 54..60.
    tau enters (L and Euler's equations) only for the bodies torque_body flags: the others have tau = 0,
    whose RK4 update of L is the identity, so L and its scratch columns are left alone. A flagged body
    whose tau is zero at a stage (a contact scene's bodies while nothing touches: issue 47 item 6, ~55 ns
    of a 350 ns step at 2 bodies) takes that identity too, with the bookkeeping a later stage needs: the
    first stage saves L and zeroes its sum, a middle stage restores L, the last one restores it unless a
    sum or a compensation must be combined. The same values as `_advance` with rate 0 but for the sign
    of a zero (0 + -0 is +0; the state's values are otherwise bitwise the same).
    """
    for b in range(x.shape[0]):
        s = scratch[b]
        inv_mass = 1.0 / model.body_mass[b]
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        if kind == STAGE_FIRST:
            if carried_momentum_valid(s, _Q_END, _L_END, q, L, b):
                m0, m1, m2 = s[_M_CARRIED], s[_M_CARRIED + 1], s[_M_CARRIED + 2]
            else:  # m rebuilt from the state: the compensations of m and L belong to the old one
                m0, m1, m2 = rotate_inverse(w, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2])
                for k in range(10, 16):
                    s[_COMP + k] = 0.0
        else:
            m0, m1, m2 = s[_M_STAGE], s[_M_STAGE + 1], s[_M_STAGE + 2]
        inv = model.body_inertia_inv
        dw, dx, dy, dz, dm0, dm1, dm2 = body_rates(w, qx, qy, qz, m0, m1, m2, inv[b, 0], inv[b, 1], inv[b, 2])
        if has_torque and torque_body[b]:
            if tau[b, 0] != 0.0 or tau[b, 1] != 0.0 or tau[b, 2] != 0.0 or (kind == STAGE_LAST and _carried(s)):
                tb0, tb1, tb2 = rotate_inverse(w, qx, qy, qz, tau[b, 0], tau[b, 1], tau[b, 2])
                dm0, dm1, dm2 = dm0 + tb0, dm1 + tb1, dm2 + tb2
                for k in range(3):
                    L[b, k] = _advance(s, 10 + k, kind, a, h, L[b, k], tau[b, k])
            else:  # tau = 0 here (a contact body while nothing touches): `_advance` with rate 0, its sums kept
                for k in range(3):
                    if kind == STAGE_FIRST:
                        s[10 + k], s[_SUM + 10 + k] = L[b, k], 0.0
                    else:
                        L[b, k] = s[10 + k]
        for k in range(3):
            p = P[b, k]
            x[b, k] = _advance(s, k, kind, a, h, x[b, k], p * inv_mass)
            P[b, k] = _advance(s, 7 + k, kind, a, h, p, F[b, k])
        m0 = _advance(s, 13, kind, a, h, m0, dm0)
        m1 = _advance(s, 14, kind, a, h, m1, dm1)
        m2 = _advance(s, 15, kind, a, h, m2, dm2)
        w = _advance_plain(s, 3, kind, a, h, w, dw)
        qx = _advance_plain(s, 4, kind, a, h, qx, dx)
        qy = _advance_plain(s, 5, kind, a, h, qy, dy)
        qz = _advance_plain(s, 6, kind, a, h, qz, dz)
        if kind == STAGE_LAST:
            w, qx, qy, qz = align(w, qx, qy, qz, m0, m1, m2, L[b, 0], L[b, 1], L[b, 2])
            s[_M_CARRIED], s[_M_CARRIED + 1], s[_M_CARRIED + 2] = m0, m1, m2
            s[_Q_END], s[_Q_END + 1], s[_Q_END + 2], s[_Q_END + 3] = w, qx, qy, qz
            s[_L_END], s[_L_END + 1], s[_L_END + 2] = L[b, 0], L[b, 1], L[b, 2]
        else:
            norm = 1.0 / math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
            w, qx, qy, qz = w * norm, qx * norm, qy * norm, qz * norm
            s[_M_STAGE], s[_M_STAGE + 1], s[_M_STAGE + 2] = m0, m1, m2
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = w, qx, qy, qz


# ---- numpy reference ------------------------------------------------------------------------------


def rates_numpy(model, forces, t, x, q, P, L, m):  # noqa: ANN001, ANN201
    """(dx, dq, dP, dL, dm) of the ODE above at a stage with unit q, vectorised over bodies."""
    F, tau = wrench_numpy(model, forces, t, x, q, P, L)
    if not forces.has_torque:
        tau = np.zeros_like(L)
    omega_body = model.body_inertia_inv * m
    dq = 0.5 * quat_multiply(q, np.concatenate([np.zeros((len(q), 1)), omega_body], axis=1))
    dm = np.cross(m, omega_body) + quat_rotate_inverse(q, tau)
    return [P / model.body_mass[:, None], dq, F, tau, dm]


def align_numpy(q: np.ndarray, m: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Numpy twin of `align` (bodies with m = 0 or L = 0 only renormalised)."""
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    v = quat_rotate(q, m)
    nv, nl = np.linalg.norm(v, axis=1, keepdims=True), np.linalg.norm(L, axis=1, keepdims=True)
    ok = (nv > 0.0) & (nl > 0.0)
    v, u = v / np.where(ok, nv, 1.0), L / np.where(ok, nl, 1.0)
    d = np.concatenate([1.0 + np.sum(v * u, axis=1, keepdims=True), np.cross(v, u)], axis=1)
    out = np.where(ok, quat_multiply(d, q), q)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Plain numpy reference of `step`, vectorised over bodies, in place."""
    y0 = [a.copy() for a in (x, q, P, L)] + [quat_rotate_inverse(q, L)]

    def stage(k: list, a: float) -> list:
        y = [y + a * dy for y, dy in zip(y0, k, strict=True)]
        y[1] /= np.linalg.norm(y[1], axis=1, keepdims=True)
        return y

    k1 = rates_numpy(model, forces, t, *y0)
    k2 = rates_numpy(model, forces, t + 0.5 * dt, *stage(k1, 0.5 * dt))
    k3 = rates_numpy(model, forces, t + 0.5 * dt, *stage(k2, 0.5 * dt))
    k4 = rates_numpy(model, forces, t + dt, *stage(k3, dt))
    new = [y + dt / 6.0 * (a + 2.0 * b + 2.0 * c + d) for y, a, b, c, d in zip(y0, k1, k2, k3, k4, strict=True)]
    x[:], P[:], L[:] = new[0], new[2], new[3]
    q[:] = align_numpy(new[1], new[4], L)
