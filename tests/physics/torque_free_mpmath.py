"""A 50-digit reference of the torque-free rigid body (mpmath), for the `exact` integrator's horizon tests.

The float64 references (`rbcli.analysis.exact`, the compiled flow) cannot show 1e-10 rad at t = 2000 s
near the separatrix: their own rounding is amplified there. This one evaluates the classical solution
(Landau & Lifshitz, Mechanics, sections 35-37; the same equations as `rbcli.analysis.exact`, whose
docstring derives them) at 50 significant digits from the float64 state the simulation holds, taken
as exact binary numbers, so what it returns is that state's true motion to ~1e-40:

    m(t) = (a_1 cn u, s a_2 sn u, a_3 dn u),  u = u_0 + lambda t       (working frame, m_3, m_1 >= 0)
    B(t) = Rz(phi) Rx(theta) Rz(psi),  R(t) = R_w(0) B(0)^T B(t)           (L along z of the L frame)
    phi(t) - phi(0) = G t / I_3 + G (I_3 - I_1) / (I_1 I_3 lambda) [Pi(-N; am u|m) - Pi(-N; am u_0|m)]

The period parameters are formed without cancellation: the parameter m = d21 D3 / (d32 D1) and its
complement mc = d31 D2 / (d32 D1) each from sums of the body-momentum components (D2 = G^2 - 2 E I_2
directly from m_1 and m_3), never mc = 1 - m; mpmath then works at 50 digits, so whatever it loses to
m -> 1 internally (log10(1/mc) digits) leaves 40.
"""

from __future__ import annotations

import mpmath as mp
import numpy as np

DIGITS = 50


def _quat_to_matrix(q: list) -> list:
    w, x, y, z = q
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
    ]


def _matrix_to_quat(R: mp.matrix) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (Shepperd: the largest of four square roots)."""
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    candidates = [trace, R[0, 0], R[1, 1], R[2, 2]]
    i = max(range(4), key=lambda k: candidates[k])
    if i == 0:
        w = mp.sqrt(1 + trace) / 2
        q = [w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w)]
    elif i == 1:
        x = mp.sqrt(1 + R[0, 0] - R[1, 1] - R[2, 2]) / 2
        q = [(R[2, 1] - R[1, 2]) / (4 * x), x, (R[0, 1] + R[1, 0]) / (4 * x), (R[0, 2] + R[2, 0]) / (4 * x)]
    elif i == 2:
        y = mp.sqrt(1 - R[0, 0] + R[1, 1] - R[2, 2]) / 2
        q = [(R[0, 2] - R[2, 0]) / (4 * y), (R[0, 1] + R[1, 0]) / (4 * y), y, (R[1, 2] + R[2, 1]) / (4 * y)]
    else:
        z = mp.sqrt(1 - R[0, 0] - R[1, 1] + R[2, 2]) / 2
        q = [(R[1, 0] - R[0, 1]) / (4 * z), (R[0, 2] + R[2, 0]) / (4 * z), (R[1, 2] + R[2, 1]) / (4 * z), z]
    return np.array([float(v) for v in q])


def _rz(a: mp.mpf) -> mp.matrix:
    c, s = mp.cos(a), mp.sin(a)
    return mp.matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _rx(a: mp.mpf) -> mp.matrix:
    c, s = mp.cos(a), mp.sin(a)
    return mp.matrix([[1, 0, 0], [0, c, -s], [0, s, c]])


def torque_free_quaternions(inertia, q0, L, steps, dt) -> np.ndarray:  # noqa: ANN001
    """q(t) (len(steps), 4), wxyz world-from-principal, of the torque-free body with principal moments
    `inertia` (3,) [kg m^2], orientation q0 (wxyz, world-from-principal) and world angular momentum L
    [kg m^2/s] at t = 0, at the times t = n dt [s] (n in `steps`, dt the float64 step taken as exact, as
    the simulation's grid is); computed at 50 digits, rounded to float64 at the end.
    Generic bodies and axisymmetric ones (two equal moments), not the sphere or a steady rotation."""
    with mp.workdps(DIGITS):
        moments = [mp.mpf(float(v)) for v in inertia]
        q = [mp.mpf(float(v)) for v in q0]
        norm = mp.sqrt(sum(v * v for v in q))
        R0 = mp.matrix(_quat_to_matrix([v / norm for v in q]))
        L_world = mp.matrix([mp.mpf(float(v)) for v in L])
        m0 = R0.T * L_world
        # working frame (rbcli.analysis.exact._working_frame): axis 3 is the circulation axis
        a, b, c = sorted(range(3), key=lambda k: (float(inertia[k]), k))
        Ia, Ib, Ic = moments[a], moments[b], moments[c]
        if Ib == Ic:
            major = False
        elif Ia == Ib:
            major = True
        else:
            major = m0[c] ** 2 * (Ic - Ib) / Ic >= m0[a] ** 2 * (Ib - Ia) / Ia
        order = [a, b, c] if major else [c, b, a]
        P = mp.zeros(3, 3)
        for row, column in enumerate(order):
            P[row, column] = 1
        if mp.det(P) < 0:
            P[1, :] = -P[1, :]
        if (P * m0)[2] < 0:
            P[1, :], P[2, :] = -P[1, :], -P[2, :]
        if (P * m0)[0] < 0:
            P[0, :], P[1, :] = -P[0, :], -P[1, :]
        m1, m2, m3 = P * m0
        I1, I2, I3 = (moments[k] for k in order)
        G = mp.sqrt(m1 * m1 + m2 * m2 + m3 * m3)
        d21, d32, d31 = abs(I2 - I1), abs(I3 - I2), abs(I3 - I1)
        D1 = m2 * m2 * d21 / I2 + m3 * m3 * d31 / I3  # |G^2 - 2 E I_1|
        D3 = m1 * m1 * d31 / I1 + m2 * m2 * d32 / I2  # |2 E I_3 - G^2|
        D2 = m3 * m3 * d32 / I3 - m1 * m1 * d21 / I1  # |G^2 - 2 E I_2|, >= 0 in the working frame
        lam = mp.sqrt(d32 * D1 / (I1 * I2 * I3))
        k2 = d21 * D3 / (d32 * D1)
        mc = d31 * D2 / (d32 * D1)
        assert abs(k2 + mc - 1) < mp.mpf(10) ** (10 - DIGITS), "m + mc = 1 up to rounding"
        r = I1 * d32 / (I2 * d31)
        N = I3 * d21 / (I1 * d32)
        a1 = mp.sqrt(m1 * m1 + r * m2 * m2)
        a3 = mp.sqrt(m3 * m3 + m2 * m2 * I3 * d21 / (I2 * d31))
        s = 1 if I3 > I1 else -1
        phi0 = mp.atan2(s * m2 * mp.sqrt(r), m1)
        u0 = mp.ellipf(phi0, k2)
        K = mp.ellipk(k2)
        pi0 = mp.ellippi(-N, phi0, k2)

        def attitude(t: mp.mpf) -> mp.matrix:
            u = u0 + lam * t
            sn, cn, dn = (mp.ellipfun(kind, u, m=k2) for kind in ("sn", "cn", "dn"))
            # am(u) = j pi + atan(sn/cn): |am - pi u / (2K)| < pi/2 picks j
            reduced = mp.atan2(sn if cn >= 0 else -sn, abs(cn))
            am = mp.nint((mp.pi * u / (2 * K) - reduced) / mp.pi) * mp.pi + reduced
            phi = G * t / I3 + G * (I3 - I1) / (I1 * I3 * lam) * (mp.ellippi(-N, am, k2) - pi0)
            theta = mp.atan2(a1 * mp.sqrt(1 + N * sn * sn), a3 * dn)
            psi = mp.atan2(mp.sqrt(r) * cn, s * sn)
            return _rz(phi) * _rx(theta) * _rz(psi)

        B0 = attitude(mp.mpf(0))
        R_w0 = R0 * P.T
        return np.array([_matrix_to_quat(R_w0 * B0.T * attitude(int(n) * mp.mpf(float(dt))) * P) for n in steps])
