"""Exact solutions (rbcli.analysis.exact) against numerical integration, closed forms and invariants.

Reference integrations use scipy's DOP853 at rtol 1e-12, atol 1e-14 on Euler's equations
I omega' = (I omega) x omega with the attitude R' = R [omega]x (R world-from-body). On 20 s of
motion its global error is ~1e-11 (it accumulates ~rtol per step over ~1e3 steps), so comparisons
with it use 1e-9: 100x margin, while any error in the formulas (a sign, a branch, a wrong Pi
characteristic) shows up at 1e-3 or more. Near the separatrix the motion amplifies perturbations
~1e5-fold, so there the checks are invariants and group laws instead.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.special as sp
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from rbcli.analysis.exact import (
    free_flight,
    geodesic_angle,
    quat_geodesic_angle,
    torque_free,
    torque_free_axisymmetric,
)
from rbcli.physics.rotation import matrix_to_quat, quat_multiply, quat_to_matrix

EPS = np.finfo(float).eps


def skew(w):
    return np.array([[0.0, -w[2], w[1]], [w[2], 0.0, -w[0]], [-w[1], w[0], 0.0]])


def integrate_rigid_body(inertia_tensor, R0, omega0_body, t):
    """DOP853 on I w' = (I w) x w, R' = R [w]x with a full body inertia tensor; R (T, 3, 3), w (T, 3)."""
    J = np.asarray(inertia_tensor, dtype=float)
    J_inv = np.linalg.inv(J)

    def rhs(_, y):
        w, R = y[:3], y[3:].reshape(3, 3)
        return np.concatenate([J_inv @ np.cross(J @ w, w), (R @ skew(w)).ravel()])

    sol = solve_ivp(rhs, (0.0, t[-1]), np.concatenate([omega0_body, np.ravel(R0)]), method="DOP853",
                    rtol=1e-12, atol=1e-14, t_eval=t)  # fmt: skip
    return sol.y[3:].T.reshape(-1, 3, 3), sol.y[:3].T


def random_rotation(rng):
    q = rng.normal(size=4)
    return quat_to_matrix(q / np.linalg.norm(q))


def test_free_flight_is_the_constant_acceleration_solution():
    # x'' = g exactly: x(t) = x0 + v0 t + g t^2/2 is checked against DOP853 on (x, v)' = (v, g),
    # which is exact for quadratics up to rounding
    x0, v0, g = np.array([1.0, -2.0, 0.5]), np.array([0.3, 4.0, -1.0]), np.array([0.0, 0.0, -9.81])
    t = np.linspace(0.0, 3.0, 31)
    x, v = free_flight(x0, v0, g, t)
    sol = solve_ivp(lambda _, y: np.concatenate([y[3:], g]), (0, 3.0), np.concatenate([x0, v0]), method="DOP853",
                    rtol=1e-13, atol=1e-13, t_eval=t)  # fmt: skip
    np.testing.assert_allclose(x, sol.y[:3].T, atol=1e-11)
    np.testing.assert_allclose(v, sol.y[3:].T, atol=1e-11)
    assert x.shape == v.shape == (31, 3)


@pytest.mark.parametrize(
    "inertia, omega0, R0_seed",
    [
        ([1.0, 2.0, 3.0], [1.0, 1.0, 2.0], None),  # the task's case: L about the major axis
        ([1.0, 2.0, 3.0], [3.0, 0.4, 0.2], None),  # L near the minor axis
        ([2.7, 0.6, 1.3], [-0.7, 1.9, 0.8], 11),  # unsorted moments, random orientation
        ([0.9, 1.4, 2.2], [1.1, -0.5, -1.7], 12),
    ],
)
def test_torque_free_matches_dop853(inertia, omega0, R0_seed):
    # eq.: Euler's equations and R' = R [omega]x; T = 20 s covers several nutation periods
    R0 = np.eye(3) if R0_seed is None else random_rotation(np.random.default_rng(R0_seed))
    t = np.linspace(0.0, 20.0, 81)
    exact = torque_free(inertia, R0, omega0, t)
    R_ref, w_ref = integrate_rigid_body(np.diag(inertia), R0, np.asarray(omega0), t)
    assert geodesic_angle(exact.R, R_ref).max() < 1e-9
    np.testing.assert_allclose(exact.omega_body, w_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(exact.omega_world, np.einsum("tij,tj->ti", R_ref, w_ref), rtol=0, atol=1e-9)
    np.testing.assert_allclose(quat_to_matrix(exact.q), exact.R, rtol=0, atol=4 * EPS)
    np.testing.assert_allclose(exact.L_world, R0 @ (np.asarray(inertia) * omega0), rtol=4 * EPS)


def test_full_inertia_tensor_and_world_frame_omega_match_dop853():
    # a non-principal body frame: J = V diag(I) V^T; R and omega_body must come back in that frame
    rng = np.random.default_rng(5)
    V = random_rotation(rng)
    J = V @ np.diag([0.8, 1.7, 2.9]) @ V.T
    R0 = random_rotation(rng)
    omega_world = np.array([0.4, -1.3, 0.9])
    t = np.linspace(0.0, 20.0, 41)
    exact = torque_free(J, R0, omega_world, t, frame="world")
    R_ref, w_ref = integrate_rigid_body(J, R0, R0.T @ omega_world, t)
    assert geodesic_angle(exact.R, R_ref).max() < 1e-9
    np.testing.assert_allclose(exact.omega_body, w_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(exact.omega_world[0], omega_world, rtol=0, atol=1e-14)


@pytest.mark.parametrize("inertia", [[1.0, 1.0, 2.0], [2.0, 1.0, 2.0], [3.0, 0.5, 0.5], [1.0, 1.0, 1e-3]])
def test_general_solution_reduces_to_regular_precession(inertia):
    # I_1 = I_2 != I_3 (in any position): the elliptic solution has m = 0 (sn = sin, Pi = phi) and
    # must equal Goldstein's closed form R(t) = Rot(L/I_perp, t) R0 Rot(e_s, beta t); both are exact to
    # ~EPS x angle; angles here up to ~2000 rad (thin rod), bound 20 EPS per radian
    rng = np.random.default_rng(6)
    t = np.linspace(0.0, 25.0, 51)
    for _ in range(4):
        R0 = random_rotation(rng)
        omega0 = rng.normal(size=3)
        general = torque_free(inertia, R0, omega0, t)
        closed = torque_free_axisymmetric(inertia, R0, omega0, t)
        tol = 20 * EPS * (1.0 + np.linalg.norm(omega0) * t[-1])
        assert geodesic_angle(general.R, closed.R).max() < tol
        np.testing.assert_allclose(general.omega_body, closed.omega_body, rtol=0, atol=tol)


def test_sphere_and_zero_angular_velocity():
    R0 = random_rotation(np.random.default_rng(7))
    t = np.linspace(0.0, 5.0, 11)
    omega = np.array([0.3, -0.2, 1.1])
    sphere = torque_free([2.0, 2.0, 2.0], R0, omega, t)
    for k, tk in enumerate(t):  # R(t) = exp(t [R0 omega]x) R0
        angle = np.linalg.norm(omega) * tk
        axis = R0 @ omega / np.linalg.norm(omega)
        rot = quat_to_matrix(np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis]))
        assert geodesic_angle(sphere.R[k], rot @ R0) < 8 * EPS * (1 + angle)
    still = torque_free([1.0, 2.0, 3.0], R0, np.zeros(3), t)
    np.testing.assert_array_equal(still.R, np.broadcast_to(R0, (11, 3, 3)))
    np.testing.assert_array_equal(still.omega_world, np.zeros((11, 3)))


def test_intermediate_axis_flip_period():
    # I = (1, 2, 3), omega0 = (0.01, 5, 0): M^2 < 2 E I_2, so m circulates about the minor axis and
    # m_2 = L . b_2 (the body 2-axis along L) changes sign every 2 K(k^2) / lambda (Landau & Lifshitz
    # 37.10-37.12 with indices 1 and 3 swapped):
    #   lambda^2 = (I2 - I1)(2 E I3 - M^2) / (I1 I2 I3), k^2 = (I3 - I2)(M^2 - 2 E I1) / ((I2 - I1)(2 E I3 - M^2))
    # Zero crossings are located with brentq on the exact solution to ~1e-12 s.
    I1, I2, I3 = 1.0, 2.0, 3.0
    omega0 = np.array([0.01, 5.0, 0.0])
    m0 = np.array([I1, I2, I3]) * omega0
    M2, two_e = m0 @ m0, m0 @ (m0 / [I1, I2, I3])
    lam = np.sqrt((I2 - I1) * (two_e * I3 - M2) / (I1 * I2 * I3))
    k2 = (I3 - I2) * (M2 - two_e * I1) / ((I2 - I1) * (two_e * I3 - M2))
    half_period = 2.0 * sp.ellipk(k2) / lam

    def m2(tk):
        s = torque_free([I1, I2, I3], np.eye(3), omega0, [tk])
        return (s.R[0].T @ s.L_world)[1]

    t = np.linspace(0.0, 3.2 * half_period, 400)
    values = np.array(
        [(s.R.transpose(0, 2, 1) @ s.L_world)[:, 1] for s in [torque_free([I1, I2, I3], np.eye(3), omega0, t)]]
    )[0]
    flips = [brentq(m2, t[i], t[i + 1], xtol=1e-13) for i in np.nonzero(np.diff(np.sign(values)))[0]]
    assert len(flips) == 3  # the body really turns over, three times in 3.2 half-periods
    np.testing.assert_allclose(np.diff(flips), half_period, rtol=1e-9)
    assert np.min(values) < -0.99 * np.linalg.norm(m0) and np.max(values) > 0.99 * np.linalg.norm(m0)


@pytest.mark.parametrize(
    "offset, tol_restart, tol_reverse",
    [(1e-5, 1e-10, 1e-10), (1e-10, 1e-6, 1e-6), (0.0, 1e-12, 1.5e-8)],
)
def test_near_separatrix_invariants_group_law_and_reversal(offset, tol_restart, tol_reverse):
    # I = (1, 1.5, 3), omega0 from m = (1, 0.7, 1 + offset): D2 / G^2 ~ offset (exactly 0 for 0.0).
    # Invariants of the exact motion: L_world(t) = R(t) I omega_body(t) constant, |m| and 2E constant
    # (to rounding: 16 EPS relative). Group law: restarting from the state at t1 and running t2 must
    # give the state at t1 + t2; reversal: running -t from the state at t returns the start. Each
    # restart rounds the state, and the flow amplifies that: by ~G^2 / D2 x (lam t / K) off the
    # separatrix (EPS x 2.5e5 x O(1) at offset 1e-5; at most EPS x 2.5e10 at 1e-10), and on it by
    # exp(lam t) = 7e6 for the reversal from t = 30 s (lam = sqrt(D1 |D3| / (I1 I3)) / G = 0.53 1/s),
    # where the state sits 1e-7 from the saddle m = (0, G, 0). Tolerances: those estimates x ~10.
    inertia = np.array([1.0, 1.5, 3.0])
    R0 = random_rotation(np.random.default_rng(8))
    omega0 = np.array([1.0, 0.7, 1.0 + offset]) / inertia
    t = np.linspace(0.0, 30.0, 61)
    s = torque_free(inertia, R0, omega0, t)
    m = inertia * s.omega_body
    L_t = np.einsum("tij,tj->ti", s.R, m)
    np.testing.assert_allclose(L_t, np.broadcast_to(s.L_world, L_t.shape), rtol=0, atol=16 * EPS * 2)
    np.testing.assert_allclose(np.linalg.norm(m, axis=1), np.linalg.norm(m[0]), rtol=16 * EPS)
    np.testing.assert_allclose(np.sum(m * s.omega_body, axis=1), m[0] @ s.omega_body[0], rtol=16 * EPS)
    k = 20  # restart at t = 10 s, run 20 s more
    restarted = torque_free(inertia, s.R[k], s.omega_body[k], t[: 61 - k])
    assert geodesic_angle(restarted.R, s.R[k:]).max() < tol_restart
    back = torque_free(inertia, s.R[-1], s.omega_body[-1], -t)
    assert geodesic_angle(back.R[-1], R0) < tol_reverse


def test_geodesic_angle_is_accurate_near_zero_and_pi():
    # R_b = R_a Rot(axis, theta): the angle must come back to ~EPS absolute at both ends (arccos of
    # the trace would give ~1e-8 near 0 and near pi)
    rng = np.random.default_rng(9)
    R_a = random_rotation(rng)
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    thetas = np.array([0.0, 1e-12, 1e-7, 0.5, 2.0, np.pi - 1e-7, np.pi - 1e-12, np.pi])
    q_rel = np.stack([np.cos(thetas / 2), *(np.sin(thetas / 2)[None] * axis[:, None])], -1)
    R_b = R_a @ quat_to_matrix(q_rel)
    np.testing.assert_allclose(geodesic_angle(np.broadcast_to(R_a, R_b.shape), R_b), thetas, rtol=0, atol=8 * EPS)
    q_a = matrix_to_quat(R_a)
    q_b = quat_multiply(q_a, q_rel)
    np.testing.assert_allclose(quat_geodesic_angle(q_a, q_b), thetas, rtol=0, atol=8 * EPS)
    np.testing.assert_allclose(quat_geodesic_angle(q_a, -q_b), thetas, rtol=0, atol=8 * EPS)  # q ~ -q
