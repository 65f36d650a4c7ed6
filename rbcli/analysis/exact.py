"""Exact solutions for tests and error reports: free flight and the torque-free rigid body.

Vectorised numpy/scipy reference, written independently of the compiled drift
``rbcli.physics.free_rotation_exact`` so the two cross-check each other: here the attitude uses the
classical Euler angles of Landau & Lifshitz (Mechanics, section 37) about the fixed L, with the
precession angle phi from the elliptic integral of the third kind alone; the compiled map uses the
swing-twist construction of Celledoni et al. (2008) with an extra arctangent term.

Torque-free body, principal frame (I_1 <= I_2 <= I_3 after relabelling, see ``_working_frame``):
    Euler:  m' = m x omega, omega = m / I;   attitude: R' = R [omega]x, R world-from-body, L = R m.
    m(t) = (a_1 cn u, s a_2 sn u, a_3 dn u), u = lambda t + u_0               (LL 37.10-37.11)
    L-frame Euler angles (z along L): B = Rz(phi) Rx(theta) Rz(psi), m / G = B^T e_z, so
        m / G = (sin theta sin psi, sin theta cos psi, cos theta)                (LL 35.1)
    phi' = G (m_1^2/I_1 + m_2^2/I_2) / (m_1^2 + m_2^2) = G / I_3 + G (I_3 - I_1) / (I_1 I_3 (1 + N sn^2 u))
    phi(t) - phi(0) = G t / I_3 + G (I_3 - I_1) / (I_1 I_3 lambda) [Pi(-N; am u|m) - Pi(-N; am u_0|m)]
    with N = I_3 (I_2 - I_1) / (I_1 (I_3 - I_2)) (LL 37.14-37.15 in this notation).
The world attitude is R(t) = R(0) B(0)^T B(t). Where that closed form for phi loses digits (short
arcs, where the Pi difference is O(lambda t) from O(1) terms, and bodies with I_max / I_min large,
where G t / I_3 and the Pi term each exceed phi many times) phi' = G (1/I_1 + (N/I_3) sn^2) /
(1 + N sn^2), which has positive terms only, is integrated by quadrature instead (trapezoidal rule
over whole periods, Gauss-Legendre for the rest).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.special as sp

from rbcli.physics.rotation import matrix_to_quat, quat_conjugate, quat_multiply

# scipy.special.ellipj switches to a first-order series in 1 - m for m >= 1 - 1e-10 (Cephes ellpj),
# which is wrong once |u| exceeds a few units; below this complementary parameter the reference
# takes sn, cn, dn from the compiled Bulirsch implementation instead (checked against scipy and
# identities in tests/physics/test_elliptic.py).
_SCIPY_ELLIPJ_MIN_MC = 1.0e-8


@dataclass(frozen=True)
class TorqueFreeSolution:
    """Exact torque-free motion sampled at times t.

    t (T,) [s]; R (T, 3, 3) world-from-body; q (T, 4) the same as unit quaternions (w, x, y, z),
    sign kept continuous in t; omega_body (T, 3) [rad/s] body frame; omega_world (T, 3) [rad/s];
    L_world (3,) [kg m^2/s] world angular momentum (constant). "Body" is the frame the inertia was
    given in (principal if moments were given, the user's frame if a full tensor was).
    """

    t: np.ndarray
    R: np.ndarray
    q: np.ndarray
    omega_body: np.ndarray
    omega_world: np.ndarray
    L_world: np.ndarray


def free_flight(x0: np.ndarray, v0: np.ndarray, gravity: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ballistic motion x = x0 + v0 t + g t^2 / 2, v = v0 + g t; returns x, v of shape (T, 3) [m], [m/s]."""
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))[:, None]
    x0, v0, g = (np.asarray(a, dtype=np.float64) for a in (x0, v0, gravity))
    return x0 + v0 * t + 0.5 * g * t * t, v0 + g * t


def geodesic_angle(R_a: np.ndarray, R_b: np.ndarray) -> np.ndarray:
    """Rotation angle [rad] of R_a^T R_b, in [0, pi], vectorised over leading axes.

    atan2(|axial part|, (trace - 1) / 2): unlike arccos of the trace this keeps full absolute
    accuracy near 0, and near pi the axial part is still an accurate small sine.
    """
    M = np.einsum("...ji,...jk->...ik", np.asarray(R_a, dtype=np.float64), np.asarray(R_b, dtype=np.float64))
    axial = np.stack([M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]], -1)
    return np.arctan2(0.5 * np.linalg.norm(axial, axis=-1), 0.5 * (np.trace(M, axis1=-2, axis2=-1) - 1.0))


def quat_geodesic_angle(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Rotation angle [rad] in [0, pi] between unit quaternions (w, x, y, z), q and -q alike.

    2 atan2(|v|, |w|) of conj(q_a) q_b: accurate near 0 and near pi.
    """
    d = quat_multiply(quat_conjugate(q_a), q_b)
    return 2.0 * np.arctan2(np.linalg.norm(d[..., 1:], axis=-1), np.abs(d[..., 0]))


def _rot_x(a: np.ndarray) -> np.ndarray:
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def _rot_z(a: np.ndarray) -> np.ndarray:
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _rotation_about(axis_angle: np.ndarray) -> np.ndarray:
    """Rodrigues: rotation matrices for rotation vectors, shape (..., 3) -> (..., 3, 3)."""
    v = np.asarray(axis_angle, dtype=np.float64)
    angle = np.linalg.norm(v, axis=-1)
    safe = np.where(angle > 0.0, angle, 1.0)
    k = v / safe[..., None]
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 2] = -k[..., 2], k[..., 1], -k[..., 0]
    K[..., 1, 0], K[..., 2, 0], K[..., 2, 1] = k[..., 2], -k[..., 1], k[..., 0]
    s, c = np.sin(angle)[..., None, None], (1.0 - np.cos(angle))[..., None, None]
    return np.eye(3) + s * K + c * (K @ K)


def _continuous_quat(R: np.ndarray) -> np.ndarray:
    """Quaternions (w, x, y, z) of R (T, 3, 3) with the sign chosen continuous along T."""
    q = matrix_to_quat(R)
    flips = np.concatenate([[False], np.sum(q[1:] * q[:-1], axis=-1) < 0.0])
    sign = np.where(np.logical_xor.accumulate(flips), -1.0, 1.0)
    return q * sign[:, None]


def _principal(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(moments (3,), V (3, 3)) with inertia = V diag(moments) V^T, det V = +1.

    V's columns are the principal axes in the given body frame; for three moments V = identity.
    """
    inertia = np.asarray(inertia, dtype=np.float64)
    if inertia.shape == (3,):
        moments, V = inertia.copy(), np.eye(3)
    elif inertia.shape == (3, 3):
        if not np.allclose(inertia, inertia.T, rtol=1e-12, atol=0.0):
            raise ValueError("inertia tensor must be symmetric")
        moments, V = np.linalg.eigh(0.5 * (inertia + inertia.T))
        if np.linalg.det(V) < 0.0:
            V[:, 2] = -V[:, 2]
    else:
        raise ValueError(f"inertia must have shape (3,) or (3, 3), got {inertia.shape}")
    if np.any(moments <= 0.0):
        raise ValueError("principal moments of inertia must be positive")
    return moments, V


def _initial_state(
    inertia: np.ndarray, R0: np.ndarray, omega0: np.ndarray, frame: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(moments, V, R0 world-from-principal, omega0 principal) from the user's inputs."""
    moments, V = _principal(inertia)
    R0 = np.asarray(R0, dtype=np.float64)
    if R0.shape == (4,):  # a (w, x, y, z) quaternion
        from rbcli.physics.rotation import quat_to_matrix

        R0 = quat_to_matrix(R0 / np.linalg.norm(R0))
    omega0 = np.asarray(omega0, dtype=np.float64)
    if frame == "world":
        omega0 = R0.T @ omega0
    elif frame != "body":
        raise ValueError(f"frame must be 'body' or 'world', got {frame!r}")
    return moments, V, R0 @ V, V.T @ omega0


def _working_frame(moments: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P, I_w): a signed permutation P (det +1) with m_w = P m and moments I_w = |P| moments.

    Axis 3 of the working frame is the one m circulates about (major axis if G^2 >= 2 E I_mid,
    else the minor one), I_w is monotone with any equal pair in positions 1 and 2, m_w3 >= 0 and
    m_w1 >= 0 (so the initial amplitude lies in [-pi/2, pi/2] and the separatrix m_w1 > 0 branch is
    the one taken).
    """
    a, b, c = np.argsort(moments, kind="stable")
    Ia, Ib, Ic = moments[[a, b, c]]
    if Ib == Ic:
        major = False
    elif Ia == Ib:
        major = True
    else:
        # G^2 - 2 E I_b as a difference of two non-negative sums
        major = m[c] ** 2 * (Ic - Ib) / Ic >= m[a] ** 2 * (Ib - Ia) / Ia
    order = [a, b, c] if major else [c, b, a]
    P = np.zeros((3, 3))
    P[[0, 1, 2], order] = 1.0
    if np.linalg.det(P) < 0.0:
        P[1] = -P[1]
    mw = P @ m
    if mw[2] < 0.0:
        P[1:] = -P[1:]
        mw = P @ m
    if mw[0] < 0.0:
        P[:2] = -P[:2]
    return P, moments[order]


def _ellipj(u: np.ndarray, m: float, mc: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """sn, cn, dn, am of u (array) for parameter m (complement mc), scipy where it is accurate."""
    if mc >= _SCIPY_ELLIPJ_MIN_MC or mc == 0.0:
        return sp.ellipj(u, m)
    from rbcli.physics.elliptic import ellipj_mc, ellipk_mc

    sn, cn, dn = np.array([ellipj_mc(float(x), mc) for x in np.ravel(u)]).T.reshape((3,) + np.shape(u))
    # am = j pi + atan(sn / cn), j from |am - pi u / (2K)| < pi / 2
    r = np.arctan2(np.where(cn >= 0.0, sn, -sn), np.abs(cn))
    j = np.round((0.5 * np.pi * u / ellipk_mc(mc) - r) / np.pi)
    return sn, cn, dn, j * np.pi + r


def _ellippi_neg(n_abs: float, phi: np.ndarray, m: float, mc: float) -> np.ndarray:
    """Pi(-n_abs; phi|m) for any real phi (arrays), via Carlson R_F, R_J (DLMF 19.25.14, 19.6).

    For n_abs > 1 the two Carlson terms cancel down to O(n_abs^(-1/2)); then the n -> m/n
    transformation (DLMF 19.7.9) with its R_C written as an arctangent is used instead.
    """
    j = np.round(phi / np.pi)
    r = phi - j * np.pi
    s, c = np.sin(r), np.cos(r)
    c2, s2 = c * c, s * s
    d = c2 + mc * s2

    def reduced(s, c2, s2, d):
        if n_abs > 1.0:
            q = m / n_abs  # Pi(-n) = Pi's partner at characteristic m/(-n) = -q, moved to the left
            w = np.sqrt((1.0 + n_abs) * (1.0 + q))
            return np.arctan2(s * w, np.sqrt(c2 * d)) / w + q / 3.0 * s * s2 * sp.elliprj(c2, d, 1.0, 1.0 + q * s2)
        return s * sp.elliprf(c2, d, 1.0) - n_abs / 3.0 * s * s2 * sp.elliprj(c2, d, 1.0, 1.0 + n_abs * s2)

    value = reduced(s, c2, s2, d)
    if np.any(j != 0.0):
        value = value + 2.0 * j * reduced(1.0, 0.0, 1.0, mc)
    return value


def _integrate_from(f, u0: float, span: np.ndarray, period: float, dist: float) -> np.ndarray:
    """int_u0^(u0 + span) f(u) du for each entry of span (any sign); f has period ``period`` (inf: none)
    and is analytic within dist of the real axis.

    Whole periods: trapezoidal rule (error ~ exp(-2 pi 0.8 dist M / period) < 1e-16); the rest:
    16-point Gauss-Legendre on panels no longer than dist / 2 (error ~ 8^-32).
    """
    sign, length = np.sign(span), np.abs(span)
    start = np.where(span < 0.0, u0 + span, u0)
    count = np.floor(length / period) if np.isfinite(period) else np.zeros_like(length)
    rest = length - count * period if np.isfinite(period) else length
    whole = 0.0
    if np.any(count > 0):
        points = int(np.ceil(14.7 * 0.5 * period / dist)) + 1
        whole = period * np.mean(f(u0 + period * np.arange(points) / points))
    panels = max(1, int(np.ceil(rest.max() / (0.5 * dist))))
    x, w = sp.roots_legendre(16)
    step = rest / panels
    nodes = start[:, None, None] + step[:, None, None] * (np.arange(panels)[None, :, None] + 0.5 * (1.0 + x))
    partial = 0.5 * step * np.einsum("k,tpk->t", w, f(nodes))
    return sign * (count * whole + partial)


def _body_momentum_and_angles(I_w: np.ndarray, m_w: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """m_w(t) (T, 3) and B(t) (T, 3, 3) = Rz(phi) Rx(theta) Rz(psi) (working frame to L frame).

    None when m_w is an eigenvector of the inertia (a steady rotation, lambda = 0 or u_0 infinite).
    """
    I1, I2, I3 = I_w
    m1, m2, m3 = m_w
    G = np.sqrt(m1 * m1 + m2 * m2 + m3 * m3)
    d21, d32, d31 = abs(I2 - I1), abs(I3 - I2), abs(I3 - I1)
    D1 = m2 * m2 * d21 / I2 + m3 * m3 * d31 / I3  # |G^2 - 2 E I_1|
    D3 = m1 * m1 * d31 / I1 + m2 * m2 * d32 / I2  # |2 E I_3 - G^2|
    lam = np.sqrt(d32 * D1 / (I1 * I2 * I3))
    if lam == 0.0:
        return None
    k2 = d21 * D3 / (d32 * D1)
    mc = max(d31 * (m3 * m3 * d32 / I3 - m1 * m1 * d21 / I1) / (d32 * D1), 0.0)
    if k2 <= 0.5:
        mc = 1.0 - k2
    else:
        k2 = 1.0 - mc
    r = I1 * d32 / (I2 * d31)
    N = I3 * d21 / (I1 * d32)
    a1 = np.sqrt(m1 * m1 + r * m2 * m2)
    a2 = np.sqrt(m1 * m1 / r + m2 * m2)
    a3 = np.sqrt(m3 * m3 + m2 * m2 * I3 * d21 / (I2 * d31))
    s = 1.0 if I3 > I1 else -1.0
    phi0 = np.arctan2(s * m2 * np.sqrt(r), m1)
    if mc == 0.0 and m1 == 0.0:
        return None  # intermediate-axis equilibrium
    u0 = sp.ellipkinc(phi0, k2)
    u = u0 + lam * t
    sn, cn, dn, am = _ellipj(u, k2, mc)
    m_t = np.stack([a1 * cn, s * a2 * sn, a3 * dn], -1)
    theta = np.arctan2(a1 * np.sqrt(1.0 + N * sn * sn), a3 * dn)
    psi = np.arctan2(np.sqrt(r) * cn, s * sn)
    # Precession angle. Closed form (LL 37.14): phi = G t / I3 + G (I3 - I1) / (I1 I3) int dt / (1 + N sn^2),
    # whose two terms can each exceed phi by kappa = max(I1, I2) (1/I3 + |1/I1 - 1/I3|) (a tumbling
    # rod: kappa ~ I_max / I_min); and over short arcs the Pi difference cancels from O(1) terms to
    # O(lambda t). In those cases integrate phi' = G (1/I1 + (N/I3) sn^2) / (1 + N sn^2) instead,
    # a positive-term form of LL's phi' = G (m1^2/I1 + m2^2/I2) / (m1^2 + m2^2).
    dist = min(1.0, np.arctan(1.0 / np.sqrt(N))) if N > 0.0 else 1.0  # poles of 1/(1 + N sn^2)
    kappa = max(I1, I2) * (1.0 / I3 + abs(1.0 / I1 - 1.0 / I3))
    phi = np.empty_like(t)
    quadrature = (lam * np.abs(t) <= 0.5 * dist) | (kappa > 16.0)
    if np.any(~quadrature):
        closed = ~quadrature
        pi_t = _ellippi_neg(N, am[closed], k2, mc)
        pi_0 = _ellippi_neg(N, np.array([phi0]), k2, mc)[0]
        phi[closed] = G * t[closed] / I3 + G * (I3 - I1) / (I1 * I3) * (pi_t - pi_0) / lam
    if np.any(quadrature):

        def rate(v):  # dphi/du
            sn2 = _ellipj(v, k2, mc)[0] ** 2
            return G * (1.0 / I1 + N / I3 * sn2) / ((1.0 + N * sn2) * lam)

        period = 2.0 * sp.ellipkm1(mc) if mc > 0.0 else np.inf  # K from 1 - m, not m
        phi[quadrature] = _integrate_from(rate, u0, lam * t[quadrature], period, dist)
    return m_t, _rot_z(phi) @ _rot_x(theta) @ _rot_z(psi)


def torque_free(
    inertia: np.ndarray, R0: np.ndarray, omega0: np.ndarray, t: np.ndarray, frame: str = "body"
) -> TorqueFreeSolution:
    """Exact torque-free rigid-body motion (Jacobi elliptic functions + Pi), sampled at times t [s].

    inertia: principal moments (3,) [kg m^2] (body frame principal), or a symmetric (3, 3) body
    inertia tensor (then diagonalised; R and omega_body stay in the given body frame).
    R0: (3, 3) world-from-body at t = 0 (or a (w, x, y, z) quaternion). omega0 [rad/s] in ``frame``
    ("body" or "world"). Equations: module docstring. Exact up to rounding; near the separatrix
    (G^2 ~ 2 E I_mid) the motion itself is ill-conditioned, see rbcli.physics.free_rotation_exact.
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    moments, V, R0p, w0 = _initial_state(inertia, R0, omega0, frame)
    m0 = moments * w0
    L_world = R0p @ m0
    m_p = None
    if np.all(m0 == 0.0) or moments.min() == moments.max():
        R_p = None  # L = 0 or a sphere: omega constant in body and world
    else:
        P, I_w = _working_frame(moments, m0)
        # evaluate at t = 0 too: R(t) = R(0) B(0)^T B(t)
        solution = _body_momentum_and_angles(I_w, P @ m0, np.concatenate([[0.0], t]))
        if solution is None:
            R_p = None  # m is an eigenvector: steady rotation
        else:
            m_w, B = solution
            R_w0 = R0p @ P.T
            R_p = R_w0 @ B[0].T @ B[1:] @ P
            m_p = m_w[1:] @ P  # (P^T m_w) row-wise
    if R_p is None:
        R_p = _rotation_about(np.outer(t, R0p @ w0)) @ R0p
        m_p = np.broadcast_to(m0, (t.size, 3))
    return _solution(t, R_p, m_p / moments, V, L_world)


def torque_free_axisymmetric(
    inertia: np.ndarray, R0: np.ndarray, omega0: np.ndarray, t: np.ndarray, frame: str = "body"
) -> TorqueFreeSolution:
    """Regular precession of an axisymmetric body (two equal principal moments), closed form.

    With I_perp the repeated moment, e_s the symmetry axis and omega_s the spin about it,
        R(t) = Rot(L / I_perp, t) R0 Rot(e_s, beta t),  beta = omega_s (I_perp - I_s) / I_perp,
        omega_body(t) = R(t)^T L / I_perp + beta e_s
    (body omega = m / I_perp + beta e_s reproduces m = I omega; Goldstein 5.6). Independent of the
    elliptic-function solution: used to check it. inertia: (3,) principal moments.
    """
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    moments, V, R0p, w0 = _initial_state(inertia, R0, omega0, frame)
    i_s = None
    for k in range(3):
        others = [moments[j] for j in range(3) if j != k]
        if others[0] == others[1]:
            i_s = k
    if i_s is None:
        raise ValueError("torque_free_axisymmetric needs two equal principal moments")
    i_perp = moments[(i_s + 1) % 3]
    m0 = moments * w0
    L_world = R0p @ m0
    beta = w0[i_s] * (i_perp - moments[i_s]) / i_perp
    e_s = np.zeros(3)
    e_s[i_s] = 1.0
    R_p = _rotation_about(np.outer(t, L_world / i_perp)) @ R0p @ _rotation_about(np.outer(t, beta * e_s))
    omega_p = np.einsum("tji,j->ti", R_p, L_world / i_perp) + beta * e_s
    return _solution(t, R_p, omega_p, V, L_world)


def _solution(
    t: np.ndarray, R_p: np.ndarray, omega_p: np.ndarray, V: np.ndarray, L_world: np.ndarray
) -> TorqueFreeSolution:
    """Package a motion computed in the principal frame (R_p world-from-principal, omega_p principal
    components) back in the caller's body frame: R = R_p V^T, omega_body = V omega_p."""
    R = R_p @ V.T
    return TorqueFreeSolution(
        t=t,
        R=R,
        q=_continuous_quat(R),
        omega_body=omega_p @ V.T,
        omega_world=np.einsum("tij,tj->ti", R_p, omega_p),
        L_world=L_world,
    )


def pendulum_angle(theta0: float, omega0: float, t: np.ndarray) -> np.ndarray:
    """The angle [rad] of a rigid pendulum released from rest at theta0 (|theta0| < pi), with
    omega0 = sqrt(M g d / I_pivot) [1/s]: theta(t) = sign(theta0) 2 arcsin(k sn(K(m) - omega0 t | m)),
    k = sin(|theta0| / 2), m = k^2 (the classical solution: Lawden, Elliptic Functions and Applications,
    5.2; at t = 0, sn(K) = 1 gives theta0; the period is 4 K(m) / omega0)."""
    k = float(np.sin(abs(theta0) / 2.0))
    m, mc = k * k, float(np.cos(abs(theta0) / 2.0) ** 2)  # mc = 1 - m without the cancellation near the top
    sn = _ellipj(_ellipk(m, mc) - omega0 * np.asarray(t, dtype=np.float64), m, mc)[0]
    return float(np.sign(theta0)) * 2.0 * np.arcsin(np.clip(k * sn, -1.0, 1.0))


def pendulum_period(theta0: float, omega0: float) -> float:
    """The rigid pendulum's period 4 K(m) / omega0 [s], m = sin^2(theta0 / 2) (see pendulum_angle)."""
    return 4.0 * _ellipk(float(np.sin(abs(theta0) / 2.0) ** 2), float(np.cos(abs(theta0) / 2.0) ** 2)) / omega0


def _ellipk(m: float, mc: float) -> float:
    """K(m) from scipy, or from the complement mc where scipy loses it (m within 1e-8 of 1)."""
    if mc >= _SCIPY_ELLIPJ_MIN_MC:
        return float(sp.ellipk(m))
    from rbcli.physics.elliptic import ellipk_mc

    return float(ellipk_mc(mc))
