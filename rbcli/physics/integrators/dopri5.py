"""`dopri5`: the Dormand-Prince 5(4) Runge-Kutta pair, the integrator behind adaptive time stepping.

Dormand & Prince 1980, "A family of embedded Runge-Kutta formulae", J. Comput. Appl. Math. 6; the
coefficients as in Hairer, Norsett & Wanner, Solving ODEs I, table II.5.2. Same ODE and body-frame
formulation as `rk4` (x, q, P, L with the body momentum m integrated by Euler's equations, stage
quaternions normalised, q aligned with L at the end; see rk4's docstring for why).

With a fixed dt (`step`): the fifth-order solution, six wrench evaluations per step (the seventh
stage only serves the error estimate). With `simulation.tolerance` (`rbcli.physics.adaptive`): each
attempt also evaluates the seventh stage at the new state, f(y_new), which is the first stage of the
next step (FSAL: six evaluations per attempt), and err = h sum_i (b_i - bhat_i) k_i is the error of
the embedded fourth-order solution, an upper estimate for the fifth-order one that is kept (local
extrapolation). The kernels below are the building blocks the adaptive driver calls.

Round-off (as rk4, docs/accuracy.md): the body momentum m is carried from one step to the next with
the q and L it belongs to, not rebuilt as R(q)^T L (an ulp of |L| on its small components at every
step, which decide the flip near the separatrix), and the final sum y0 + h sum_i b_i k_i of x, P, L and
m is compensated (Kahan). Both leaked: on the intermediate-axis flip (I = diag(1, 2, 3), omega0 =
(0.01, 5, 0), 20 s) the error grew with the step count, 2.8e-8 rad at dt = 1e-2 to 1.5e-6 at 1e-4,
and 2.5e-8 (tolerance 1e-6) to 3.9e-7 (1e-12) adaptive (tests/physics/test_integrators_roundoff.py).
A step's new compensation is written to a trial column and becomes the state's only when the step is
accepted (`accept`, or `commit` after a fixed step), so a rejected attempt leaves no trace. Cost:
+13 % per body-step at 100 bodies, +38 % at 10,000 (the wider work row; measured on a loaded machine).

Work columns per body (`SCRATCH_WIDTH`): y0 = (x, q, P, L, m) 0..15, stage rates k_1..k_7 at
16 + 16 i, the current stage's m at 128..130, the compensations of y0's sums at 131..146 (those of q
unused), the trial step's at 147..162, and what a step carries to the next: m at 163..165 and the q
and L it belongs to at 166..172 (kinematics.carried_momentum_valid).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.forces.wrench import accumulate_wrench
from rbcli.physics.integrators.kinematics import carried_momentum_valid, rotate_inverse
from rbcli.physics.integrators.rk4 import align, align_numpy, body_rates, rates_numpy
from rbcli.physics.rotation import quat_rotate_inverse
from rbcli.physics.step import STEP_ENTRY

SCRATCH_WIDTH = 173
STATE_SIZE = 16  # x (3), q (4), P (3), L (3), m (3)
_RATES = 16
_M_STAGE = 128
_COMP = 131
_COMP_TRIAL = 147
_M_CARRIED = 163
_Q_END = 166
_L_END = 170

# Butcher tableau: A[i, j] for stage i built from the rates of stages j < i; row 6 = the 5th-order weights
C = np.array([0.0, 1.0 / 5.0, 3.0 / 10.0, 4.0 / 5.0, 8.0 / 9.0, 1.0, 1.0])
A = np.zeros((7, 6))
A[1, :1] = [1.0 / 5.0]
A[2, :2] = [3.0 / 40.0, 9.0 / 40.0]
A[3, :3] = [44.0 / 45.0, -56.0 / 15.0, 32.0 / 9.0]
A[4, :4] = [19372.0 / 6561.0, -25360.0 / 2187.0, 64448.0 / 6561.0, -212.0 / 729.0]
A[5, :5] = [9017.0 / 3168.0, -355.0 / 33.0, 46732.0 / 5247.0, 49.0 / 176.0, -5103.0 / 18656.0]
A[6, :6] = [35.0 / 384.0, 0.0, 500.0 / 1113.0, 125.0 / 192.0, -2187.0 / 6784.0, 11.0 / 84.0]
# b - bhat: the error of the embedded 4th-order solution, over the 7 stages
E = np.array([71.0 / 57600.0, 0.0, -71.0 / 16695.0, 71.0 / 1920.0, -17253.0 / 339200.0, 22.0 / 525.0, -1.0 / 40.0])


@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One fixed dopri5 step of every body (fifth order, six wrench evaluations), in place."""
    begin(model, forces, contact, force_data, t, x, q, P, L, F, tau, scratch)
    advance(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch)
    commit(q, L, scratch)


@numba.njit(cache=True)
def begin(model, forces, contact, force_data, t, x, q, P, L, F, tau, work) -> None:  # noqa: ANN001
    """Save y0 = the current state and its rates k_1 = f(t, y0) into work (one wrench evaluation); y0's
    m is the carried one when q and L are what the last step wrote, else R^T L (module docstring)."""
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    _stage_pass(model, forces.has_torque, forces.torque_body, 0, True, True, 0.0, x, q, P, L, F, tau, work)


@numba.njit(cache=True)
def advance(model, forces, contact, force_data, t, h, x, q, P, L, F, tau, work) -> None:  # noqa: ANN001
    """From y0, k_1 in work: stages 2..6, leaving the fifth-order y(t + h) in the state arrays."""
    _combine(model, 1, h, x, q, P, L, work)
    for i in range(1, 6):
        accumulate_wrench(model, forces, contact, force_data, t + C[i] * h, x, q, P, L, F, tau)
        _stage_pass(model, forces.has_torque, forces.torque_body, i, False, False, h, x, q, P, L, F, tau, work)


@numba.njit(cache=True)
def error_norm(model, forces, contact, force_data, t, h, tolerance, x, q, P, L, F, tau, work) -> float:  # noqa: ANN001
    """k_7 = f(t + h, y_new) (kept for the next step) and the scaled error max_j |err_j| / sc_j.

    err = h sum_i E_i k_i per component of (x, q, P, L, m); sc_j = tolerance (1 + max(|y0_j|, |y1_j|))
    (Hairer-Norsett-Wanner's mixed absolute/relative scale with atol = rtol = tolerance). Accept <= 1.
    """
    accumulate_wrench(model, forces, contact, force_data, t + h, x, q, P, L, F, tau)
    _stage_pass(model, forces.has_torque, forces.torque_body, 6, False, False, h, x, q, P, L, F, tau, work)
    worst = 0.0
    for b in range(x.shape[0]):
        s = work[b]
        m0, m1, m2 = s[_M_STAGE], s[_M_STAGE + 1], s[_M_STAGE + 2]
        for j in range(STATE_SIZE):
            if j < 3:
                y1 = x[b, j]
            elif j < 7:
                y1 = q[b, j - 3]
            elif j < 10:
                y1 = P[b, j - 7]
            elif j < 13:
                y1 = L[b, j - 10]
            else:
                y1 = m0 if j == 13 else (m1 if j == 14 else m2)
            err = 0.0
            for i in range(7):
                err += E[i] * s[_RATES + 16 * i + j]
            ratio = abs(h * err) / (tolerance * (1.0 + max(abs(s[j]), abs(y1))))
            if not ratio <= worst:  # also catches NaN
                worst = ratio
    return worst


@numba.njit(cache=True)
def accept(x, q, P, L, work) -> None:  # noqa: ANN001
    """The accepted state becomes y0 (with the step's m, not R^T L) and its rates k_7 become k_1 (first
    same as last); the step's compensations and m are committed (`commit`)."""
    for b in range(x.shape[0]):
        s = work[b]
        for j in range(STATE_SIZE):
            s[_RATES + j] = s[_RATES + 16 * 6 + j]
        for k in range(3):
            s[k], s[7 + k], s[10 + k] = x[b, k], P[b, k], L[b, k]
        s[3], s[4], s[5], s[6] = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        s[13], s[14], s[15] = s[_M_STAGE], s[_M_STAGE + 1], s[_M_STAGE + 2]
    commit(q, L, work)


@numba.njit(cache=True)
def commit(q, L, work) -> None:  # noqa: ANN001
    """The step just computed is the state's: its compensations become y0's, and its m is carried with
    the q and L it belongs to (the next `begin` takes it when nothing else wrote q or L)."""
    for b in range(q.shape[0]):
        s = work[b]
        for j in range(STATE_SIZE):
            s[_COMP + j] = s[_COMP_TRIAL + j]
        for k in range(3):
            s[_M_CARRIED + k], s[_L_END + k] = s[_M_STAGE + k], L[b, k]
        for k in range(4):
            s[_Q_END + k] = q[b, k]


@numba.njit(cache=True)
def restore(x, q, P, L, work) -> None:  # noqa: ANN001
    """Put y0 back into the state arrays (after a rejected attempt); k_1 stays valid."""
    for b in range(x.shape[0]):
        s = work[b]
        for k in range(3):
            x[b, k], P[b, k], L[b, k] = s[k], s[7 + k], s[10 + k]
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = s[3], s[4], s[5], s[6]


@numba.njit(cache=True)
def _stage_pass(model, has_torque, torque_body, i, from_state, save, h, x, q, P, L, F, tau, work) -> None:  # noqa: ANN001
    """k_i = f at the state in the arrays (when from_state: m carried from the last step if q and L are
    what it wrote, else R^T L with the compensations of L and m cleared; otherwise the stage m in work);
    save: also store the state as y0. Then, for i < 6 and not from_state, build stage i + 1.
    tau is read only for the bodies torque_body flags (the others' tau is 0: their rates get 0)."""
    for b in range(x.shape[0]):
        s = work[b]
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        if from_state and carried_momentum_valid(s, _Q_END, _L_END, q, L, b):
            m0, m1, m2 = s[_M_CARRIED], s[_M_CARRIED + 1], s[_M_CARRIED + 2]
        elif from_state:  # m rebuilt from the state: the compensations of m and L belong to the old one
            m0, m1, m2 = rotate_inverse(w, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2])
            for j in range(10, 16):
                s[_COMP + j] = 0.0
        else:
            m0, m1, m2 = s[_M_STAGE], s[_M_STAGE + 1], s[_M_STAGE + 2]
        inv = model.body_inertia_inv
        dw, dx, dy, dz, dm0, dm1, dm2 = body_rates(w, qx, qy, qz, m0, m1, m2, inv[b, 0], inv[b, 1], inv[b, 2])
        k = s[_RATES + 16 * i : _RATES + 16 * i + 16]
        inv_mass = 1.0 / model.body_mass[b]
        torque = has_torque and torque_body[b]
        for j in range(3):
            k[j] = P[b, j] * inv_mass
            k[7 + j] = F[b, j]
            k[10 + j] = tau[b, j] if torque else 0.0
        k[3], k[4], k[5], k[6] = dw, dx, dy, dz
        k[13], k[14], k[15] = dm0, dm1, dm2
        if torque:
            tb0, tb1, tb2 = rotate_inverse(w, qx, qy, qz, tau[b, 0], tau[b, 1], tau[b, 2])
            k[13], k[14], k[15] = dm0 + tb0, dm1 + tb1, dm2 + tb2
        if save:
            for j in range(3):
                s[j], s[7 + j], s[10 + j] = x[b, j], P[b, j], L[b, j]
            s[3], s[4], s[5], s[6] = w, qx, qy, qz
            s[13], s[14], s[15] = m0, m1, m2
    if not from_state and i < 6:
        _combine(model, i + 1, h, x, q, P, L, work)


@numba.njit(cache=True)
def _combine(model, row, h, x, q, P, L, work) -> None:  # noqa: ANN001
    """Stage `row` state y0 + h sum_j A[row, j] k_j into the arrays (q normalised; row 6 aligned, and its
    sums but q's compensated: the increment's lost low bits go to the trial column, see `commit`)."""
    for b in range(x.shape[0]):
        s = work[b]
        for j in range(STATE_SIZE):
            acc = 0.0
            for i in range(row):
                acc += A[row, i] * s[_RATES + 16 * i + j]
            if row < 6:  # tested first: with the j test first the stages cost 1.35x, not 1.13x
                value = s[j] + h * acc
            elif 3 <= j < 7:
                value = s[j] + h * acc
            else:
                increment = h * acc + s[_COMP + j]
                value = s[j] + increment
                s[_COMP_TRIAL + j] = (s[j] - value) + increment
            if j < 3:
                x[b, j] = value
            elif j < 7:
                q[b, j - 3] = value
            elif j < 10:
                P[b, j - 7] = value
            elif j < 13:
                L[b, j - 10] = value
            else:
                s[_M_STAGE + j - 13] = value
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        if row == 6:
            w, qx, qy, qz = align(w, qx, qy, qz, s[_M_STAGE], s[_M_STAGE + 1], s[_M_STAGE + 2],
                                  L[b, 0], L[b, 1], L[b, 2])  # fmt: skip
        else:
            norm = 1.0 / math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
            w, qx, qy, qz = w * norm, qx * norm, qy * norm, qz * norm
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = w, qx, qy, qz


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Plain numpy reference of `step`, vectorised over bodies, in place."""
    y0 = [a.copy() for a in (x, q, P, L)] + [quat_rotate_inverse(q, L)]
    rates = [rates_numpy(model, forces, t, *y0)]
    for row in range(1, 7):
        y = [y0[n] + dt * sum(A[row, i] * rates[i][n] for i in range(row)) for n in range(5)]
        if row == 6:
            x[:], P[:], L[:] = y[0], y[2], y[3]
            q[:] = align_numpy(y[1], y[4], y[3])
            return
        y[1] = y[1] / np.linalg.norm(y[1], axis=1, keepdims=True)
        rates.append(rates_numpy(model, forces, t + C[row] * dt, *y))
