"""Exact torque-free flow of a rigid body's orientation (compiled), for the ``exact`` splitting drift.

Celledoni, Fassò, Säfström & Zanna 2008, "The exact computation of the free rigid body motion and
its use in splitting methods", SIAM J. Sci. Comput. 30(4) (CFSZ below), with the sign corrections
and the case (ii) quaternion construction of P. Leroy's note "On an article by Celledoni et al."
(Principia documentation, 2020). Symbols: principal moments I [kg m^2], world angular momentum L
[kg m^2/s] (constant), body angular momentum m = R^T L, G = |L|, 2E = sum m_i^2 / I_i.

1. Working frame. Sort the moments I_a <= I_b <= I_c and let
   D2 = m_c^2 (I_c - I_b)/I_c - m_a^2 (I_b - I_a)/I_a     (= G^2 - 2 E I_b, sign picks the case).
   D2 >= 0: m circulates about the major axis c; D2 < 0: about the minor axis a. Relabel the axes
   (1, 2, 3) = (a, b, c) or (c, b, a) so that the circulation axis is 3 and I_1, I_2, I_3 is
   monotone; an odd relabelling, and the sign flips that make m_3 >= 0 and m_1 >= 0 at t = 0, are
   paired so the working frame is a proper rotation C of the principal frame (m_w = C m_p).
   Equal moments are put in positions 1, 2 (I_1 = I_2 gives m = 0 exactly); I_a = I_c is the sphere.
2. Body momentum (CFSZ section 2.2, case (ii); Landau & Lifshitz section 37), with d_ij = |I_i - I_j|:
       m(t) = (a_1 cn u, s a_2 sn u, a_3 dn u),  u = u_0 + lambda t,  s = sign(I_3 - I_1),
       a_1^2 = m_1^2 + r m_2^2,  a_2^2 = m_1^2 / r + m_2^2,  a_3^2 = m_3^2 + m_2^2 I_3 d_21 / (I_2 d_31),
       r = I_1 d_32 / (I_2 d_31),  lambda^2 = d_32 D_1 / (I_1 I_2 I_3),
       m (parameter) = d_21 D_3 / (d_32 D_1),  mc = 1 - m = d_31 D2 / (d_32 D_1),
       D_1 = m_2^2 d_21/I_2 + m_3^2 d_31/I_3,  D_3 = m_1^2 d_31/I_1 + m_2^2 d_32/I_2,
   every amplitude a sum of non-negative terms (Leroy's "The quantity Delta_j"): only D2 cancels,
   and only because the state is near the separatrix. u_0 = F(phi_0|m) with
   tan phi_0 = s m_2 sqrt(r) / m_1, |phi_0| <= pi/2 since m_1 >= 0.
3. Attitude (CFSZ section 3 / Leroy "case (ii)"): with P(m) the minimal rotation taking e3 to m/G,
       R_w(t) = R_w(0) P(m(0)) Rz(psi(t) - psi(0)) P(m(t))^T,
       psi' = (2E + G m_3 / I_3) / (G + m_3)            (m_3 = a_3 dn u >= 0: no singularity)
   a) closed form (1/(G + a_3 dn) = (G - a_3 dn) / (a_1^2 (1 + N sn^2)), Leroy eq. for case (ii)):
       psi(t) - psi(0) = G t / I_3 + (I_3 - I_1)/(I_1 I_3 lambda)
                         * [G Delta Pi(-N; am u|m) - a_3 Delta Theta / sqrt(1 + N)],
       N = I_3 d_21 / (I_1 d_32) (a constant of the body), Theta(phi) = atan(sqrt(1 + N) tan phi)
      (continuous branch), Pi extended beyond pi/2 by Pi(n; phi + j pi) = Pi(n; phi) + 2 j Pi(n),
      Pi and Theta evaluated from sn and cn (not am) so cos^2 phi stays relatively accurate near
      pi/2, and Pi for N > 1 by the n -> m/n transformation (elliptic.ellippi_sc);
   b) quadrature of psi' itself in u (positive terms only): Gauss-Legendre over short arcs, and
      whole periods by the trapezoidal rule plus Gauss-Legendre for the rest, used where (a) loses
      digits: arcs with lambda |h| < dist / 2 (dist: distance of the integrand's poles from the real
      axis), where (a) subtracts O(1) terms to get O(lambda h), and bodies with a large ratio of
      moments (a thin rod), where its two terms exceed psi by kappa = (G^2/2E) max(1/I_3,
      |1/I_1 - 1/I_3|) > 16;
   c) I_1 = I_2: regular precession psi' = a_3 / I_3 + (G - a_3) / I_1 (exact, no elliptic functions).

Conditioning and accuracy. Generic states: about eps x (rotation angle), ~1e-14 rad after 100 rad
(measured against a 40-digit evaluation of the same flow, with psi by independent quadrature). Near
the separatrix the flow itself is ill-conditioned: the period grows like ln(1/mc) / lambda, so a
relative perturbation eps of m (the input is only known to that) moves mc by eps G^2 / D2 and the
phase after time t by about (lambda t / K) (eps G^2 / D2) / ln(16/mc); at D2 / G^2 ~ 1e-5 that is
~1e5 times the generic error, and no formula can remove it. The implementation adds no cancellation
of its own there: mc is formed from D2 directly, never as 1 - m, and sn, cn, dn, K, F, Pi all take
mc. Exactly on the separatrix (mc = 0) the same formulas hold with sn = tanh, cn = dn = sech.
Remaining amplification: long steps (lambda |h| > dist / 2) of bodies with N >> 1 whose quadrature
would exceed 4000 evaluations fall back to (a).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.elliptic import (
    JACOBI_WORK_SIZE,
    ellipj_mc_work,
    ellipk_mc,
    ellippi_complete_mc,
    ellippi_sc,
    elliprf,
)

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True, inline="always")
def _quat_mul(
    aw: float, ax: float, ay: float, az: float, bw: float, bx: float, by: float, bz: float
) -> tuple[float, float, float, float]:
    """Hamilton product a * b of quaternions (w, x, y, z)."""
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@numba.njit(cache=True, inline="always")
def _quat_e3_to(m1: float, m2: float, m3: float) -> tuple[float, float, float, float]:
    """Unit quaternion of the minimal rotation taking e3 to m/|m|; requires m3 >= 0 (no cancellation).

    Axis e3 x m, half-angle from cos(theta) = m3/|m|: q ~ (|m| + m3, -m2, m1, 0).
    """
    g = math.sqrt(m1 * m1 + m2 * m2 + m3 * m3)
    w = g + m3
    n = math.sqrt(w * w + m1 * m1 + m2 * m2)
    if n == 0.0:
        return 1.0, 0.0, 0.0, 0.0
    return w / n, -m2 / n, m1 / n, 0.0


@numba.njit(cache=True, inline="always")
def _pick(v0: float, v1: float, v2: float, i: int) -> float:
    """Component i of the vector (v0, v1, v2)."""
    return v0 if i == 0 else (v1 if i == 1 else v2)


@numba.njit(cache=True, inline="always")
def _scatter(d1: float, d2: float, d3: float, w1: int, w2: int, w3: int, k: int) -> float:
    """Component k of the vector v with v[w1] = d1, v[w2] = d2, v[w3] = d3."""
    return d1 if w1 == k else (d2 if w2 == k else d3)


@numba.njit(cache=True)
def _psi_rate(i1: float, i2: float, i3: float, m1: float, m2: float, m3: float) -> float:
    """psi' = (2E + G m3/I3) / (G + m3) [rad/s] for the current m (working frame, m3 >= 0).

    Written with positive terms only (CFSZ's form); G/I3 + (2E - G^2/I3)/(G + m3) is the same
    value but cancels when I3 is the smallest moment (a tumbling rod).
    """
    g = math.sqrt(m1 * m1 + m2 * m2 + m3 * m3)
    two_e = m1 * m1 / i1 + m2 * m2 / i2 + m3 * m3 / i3
    return (two_e + g * m3 / i3) / (g + m3)


# Gauss-Legendre nodes and weights on [-1, 1]: row n holds the n-point rule (n = 1 .. _GL_MAX)
_GL_MAX = 12
_GL_X = np.zeros((_GL_MAX + 1, _GL_MAX))
_GL_W = np.zeros((_GL_MAX + 1, _GL_MAX))
for _n in range(1, _GL_MAX + 1):
    _GL_X[_n, :_n], _GL_W[_n, :_n] = np.polynomial.legendre.leggauss(_n)


@numba.njit(cache=True)
def _gauss_legendre_psi(
    two_e: float, c3: float, g: float, a3: float, ua: float, span: float, mc: float, dist: float, work: np.ndarray
) -> float:
    """int_ua^(ua + span) (2E + c3 dn u) / (G + a3 dn u) du by composite Gauss-Legendre, span >= 0.

    The integrand is analytic within dist of the real u axis, so on a panel of length l the
    n-point rule converges like rho^(-2n), rho = x + sqrt(x^2 + 1), x = 2 (0.8 dist) / l (Bernstein
    ellipse, 20% margin); panels are at most dist / 2 long and n is the smallest with
    rho^(-2n) < 1e-18 (n <= 10 there).
    """
    if span <= 0.0:
        return 0.0
    panels = int(math.ceil(span / (0.5 * dist)))
    length = span / panels
    x = 1.6 * dist / length
    rho = x + math.sqrt(x * x + 1.0)
    n = min(_GL_MAX, max(1, int(math.ceil(20.7 / math.log(rho)))))
    total = 0.0
    for p in range(panels):
        centre = ua + (p + 0.5) * length
        for i in range(n):
            _, _, dn = ellipj_mc_work(centre + 0.5 * length * _GL_X[n, i], mc, work)
            total += _GL_W[n, i] * (two_e + c3 * dn) / (g + a3 * dn)
    return 0.5 * length * total


@numba.njit(cache=True)
def _quadrature_psi(
    two_e: float, c3: float, g: float, a3: float, u0: float, span: float, mc: float, dist: float, work: np.ndarray
) -> float:
    """int_u0^(u0 + span) of the psi integrand in u (see _gauss_legendre_psi); nan if too costly.

    span = lambda h is passed as such, not as u1 - u0, which would carry |u0| eps absolute error.

    Whole periods 2K by the trapezoidal rule (geometric convergence for a periodic integrand
    analytic in the strip |Im u| < dist: error ~ exp(-2 pi 0.8 dist M / 2K) < 1e-16 for
    M = 14.7 K / dist points), the remainder by composite Gauss-Legendre. Cost is bounded by two
    periods whatever the step; nan (caller falls back to the closed form) beyond 4000 evaluations.
    """
    sign = 1.0
    if span < 0.0:
        u0, span, sign = u0 + span, -span, -1.0
    whole = 0.0
    count = 0.0
    period = 0.0
    if mc > 0.0:
        period = 2.0 * ellipk_mc(mc)
        count = math.floor(span / period)
    points = int(math.ceil(14.7 * 0.5 * period / dist)) + 1 if count > 0.0 else 0
    if points + 10.0 * math.ceil((span - count * period) / (0.5 * dist)) > 4000.0:
        return math.nan
    if count > 0.0:
        for k in range(points):
            _, _, dn = ellipj_mc_work(u0 + k * period / points, mc, work)
            whole += (two_e + c3 * dn) / (g + a3 * dn)
        whole *= count * period / points
    rest = _gauss_legendre_psi(two_e, c3, g, a3, u0, span - count * period, mc, dist, work)
    return sign * (whole + rest)


@numba.njit(cache=True)
def _working_frame_step(
    i1: float, i2: float, i3: float, m1: float, m2: float, m3: float, h: float, work: np.ndarray
) -> tuple[float, float, float, float]:
    """Relative rotation D (quaternion) with R_w(h) = R_w(0) D, in the working frame of the docstring.

    Requires I_1 <= I_2 <= I_3 or I_1 >= I_2 >= I_3 with I_2 != I_3, m3 >= 0, m1 >= 0, and that m
    circulates about axis 3 (D2 >= 0 up to rounding).
    """
    g2 = m1 * m1 + m2 * m2 + m3 * m3
    g = math.sqrt(g2)
    d21 = abs(i2 - i1)
    d32 = abs(i3 - i2)
    d31 = abs(i3 - i1)
    # D_1 = |G^2 - 2E I_1|, D_3 = |2E I_3 - G^2|: sums of non-negative terms
    big_d1 = m2 * m2 * d21 / i2 + m3 * m3 * d31 / i3
    big_d3 = m1 * m1 * d31 / i1 + m2 * m2 * d32 / i2
    lam = math.sqrt(d32 * big_d1 / (i1 * i2 * i3))
    qw0, qx0, qy0, qz0 = _quat_e3_to(m1, m2, m3)
    if lam == 0.0:
        # m is an eigenvector (m in the degenerate plane of an axisymmetric body): it stays put
        dpsi = h * _psi_rate(i1, i2, i3, m1, m2, m3)
        m1n, m2n, m3n = m1, m2, m3
    else:
        # the parameter and its complement, each from the formula without cancellation
        k2 = d21 * big_d3 / (d32 * big_d1)
        d2 = m3 * m3 * d32 / i3 - m1 * m1 * d21 / i1  # G^2 - 2E I_2 (signed to be >= 0 here)
        mc = max(d31 * d2 / (d32 * big_d1), 0.0)
        if k2 <= 0.5:
            mc = 1.0 - k2
        mc = min(mc, 1.0)
        r = i1 * d32 / (i2 * d31)
        a1 = math.sqrt(m1 * m1 + r * m2 * m2)
        a2 = math.sqrt(m1 * m1 / r + m2 * m2)
        a3 = math.sqrt(m3 * m3 + m2 * m2 * i3 * d21 / (i2 * d31))
        sgn = 1.0 if i3 > i1 else -1.0
        # initial amplitude phi_0 (|phi_0| <= pi/2 because m1 >= 0)
        sphi = sgn * m2 * math.sqrt(r)
        cphi = m1
        rho = math.hypot(sphi, cphi)
        if rho == 0.0:
            sphi, cphi = 0.0, 1.0
        else:
            sphi, cphi = sphi / rho, cphi / rho
        if cphi == 0.0 and mc == 0.0:
            # exactly at the intermediate-axis equilibrium (u_0 = +-inf): stationary
            dpsi = h * _psi_rate(i1, i2, i3, m1, m2, m3)
            m1n, m2n, m3n = m1, m2, m3
        else:
            c2 = cphi * cphi
            u0 = sphi * elliprf(c2, c2 + mc * sphi * sphi, 1.0)
            u1 = u0 + lam * h
            sn, cn, dn = ellipj_mc_work(u1, mc, work)
            m1n, m2n, m3n = a1 * cn, sgn * a2 * sn, a3 * dn
            nn = i3 * d21 / (i1 * d32)
            two_e = m1 * m1 / i1 + m2 * m2 / i2 + m3 * m3 / i3
            # distance from the real u axis to the nearest singularity of 1/(G + a3 dn u):
            # sn^2 = -1/N at u = i y with sc(y|mc) = 1/sqrt(N), y >= atan(1/sqrt(N)); else >= K' >= pi/2
            dist = min(1.0, math.atan(1.0 / math.sqrt(nn))) if nn > 0.0 else 1.0
            # the closed form below adds G h/I3 and (I3 - I1)/(I1 I3 lambda) x bracket, each up to
            # (G^2 / 2E) max(1/I3, |1/I1 - 1/I3|) times psi itself: its rounding is amplified by that
            amplification = g * g / two_e * max(1.0 / i3, abs(1.0 / i1 - 1.0 / i3))
            dpsi = math.nan
            if nn == 0.0 and mc == 1.0:
                # I_1 = I_2: regular precession, Pi = Theta = am = u, psi' = a3/I3 + (G - a3)/I1
                dpsi = h * (a3 / i3 + a1 * a1 / ((g + a3) * i1))
            elif abs(lam * h) <= 0.5 * dist or amplification > 16.0:
                # short arc (the closed form's bracket is O(lambda h) but its terms are O(1), error
                # eps G / (I lambda)) or ill-conditioned closed form: integrate psi' itself, whose
                # integrand (2E + G m3/I3) / (G + m3) has positive terms only
                dpsi = _quadrature_psi(two_e, g * a3 / i3, g, a3, u0, lam * h, mc, dist, work) / lam
            if math.isnan(dpsi):
                sq = math.sqrt(1.0 + nn)
                pi0 = ellippi_sc(-nn, sphi, cphi, mc)
                th0 = math.atan2(sq * sphi, cphi)
                # reduced amplitude r1 in [-pi/2, pi/2] from (sn, cn), plus j half-turns
                rho1 = math.hypot(sn, cn)
                s1 = (sn if cn >= 0.0 else -sn) / rho1
                c1 = abs(cn) / rho1
                pi1 = ellippi_sc(-nn, s1, c1, mc)
                th1 = math.atan2(sq * s1, c1)
                if mc > 0.0:
                    # |am(u) - pi u / (2K)| < pi/2, so the rounding picks the half-turn count exactly
                    kk = ellipk_mc(mc)
                    j = round((0.5 * math.pi * u1 / kk - math.atan2(s1, c1)) / math.pi)
                    if j != 0.0:
                        pi1 += 2.0 * j * ellippi_complete_mc(-nn, mc)
                        th1 += j * math.pi
                bracket = g * (pi1 - pi0) - a3 * (th1 - th0) / sq
                dpsi = g * h / i3 + (i3 - i1) / (i1 * i3 * lam) * bracket
    qw1, qx1, qy1, qz1 = _quat_e3_to(m1n, m2n, m3n)
    half = 0.5 * dpsi
    cw, sz = math.cos(half), math.sin(half)
    # D = P(m0) Rz(dpsi) P(m1)^T
    aw, ax, ay, az = _quat_mul(qw0, qx0, qy0, qz0, cw, 0.0, 0.0, sz)
    return _quat_mul(aw, ax, ay, az, qw1, -qx1, -qy1, -qz1)


@numba.njit(cache=True)
def free_rotation_exact(inertia: np.ndarray, q: np.ndarray, L: np.ndarray, h: float, q_out: np.ndarray) -> None:
    """Advance one body's orientation by time h [s] under the exact torque-free flow.

    inertia: principal moments (I1, I2, I3) [kg m^2], any order, any of them equal (not zero).
    q: orientation (w, x, y, z), world-from-principal (normalised here). L: world angular momentum
    [kg m^2/s], constant along the flow. h may be negative (exact time reversal). Writes the unit
    quaternion at t + h into q_out (shape (4,); may be q itself). Equations: module docstring.
    """
    _free_rotation_exact_work(inertia, q, L, h, q_out, np.empty(JACOBI_WORK_SIZE))


@numba.njit(cache=True)
def working_frame(inertia: np.ndarray, mp0: float, mp1: float, mp2: float) -> tuple:
    """The working frame of the torque-free flow for principal moments `inertia` and body momentum m:
    (sphere, I_min, w1, w2, w3, s1, s2, s3). sphere: all moments equal (the flow is a uniform spin
    about L / I_min, the rest unused). Otherwise the principal axes relabelled w1, w2, w3 (the largest
    moment first when m lies in the major-axis region, m_c^2 (I_c - I_b) / I_c >= m_a^2 (I_b - I_a) / I_a,
    else the smallest) with signs s_i making the frame proper and s3 m3 >= 0, s1 m1 >= 0. One home for
    the one-shot flow and the anchored one (free_rotation_anchored.py), which must agree bit for bit."""
    # sort the axes by moment: ia <= ib <= ic
    ia, ib, ic = 0, 1, 2
    if inertia[ia] > inertia[ib]:
        ia, ib = ib, ia
    if inertia[ib] > inertia[ic]:
        ib, ic = ic, ib
    if inertia[ia] > inertia[ib]:
        ia, ib = ib, ia
    big_a, big_b, big_c = inertia[ia], inertia[ib], inertia[ic]
    if big_a == big_c:
        return True, big_a, ia, ib, ic, 1.0, 1.0, 1.0
    if big_b == big_c:
        major = False
    elif big_a == big_b:
        major = True
    else:
        m_a, m_c = _pick(mp0, mp1, mp2, ia), _pick(mp0, mp1, mp2, ic)
        major = m_c * m_c * (big_c - big_b) / big_c >= m_a * m_a * (big_b - big_a) / big_a
    w1, w2, w3 = (ia, ib, ic) if major else (ic, ib, ia)
    # proper working frame: an odd relabelling flips axis 1; then m3 >= 0, m1 >= 0 by pair flips
    s1 = 1.0 if (w1 + 1) % 3 == w2 else -1.0
    s2 = 1.0
    s3 = 1.0
    if _pick(mp0, mp1, mp2, w3) < 0.0:
        s2, s3 = -s2, -s3
    if s1 * _pick(mp0, mp1, mp2, w1) < 0.0:
        s1, s2 = -s1, -s2
    return False, big_a, w1, w2, w3, s1, s2, s3


@numba.njit(cache=True)
def _free_rotation_exact_work(
    inertia: np.ndarray, q: np.ndarray, L: np.ndarray, h: float, q_out: np.ndarray, work: np.ndarray
) -> None:
    """``free_rotation_exact`` with a caller-provided scratch array for the Jacobi functions."""
    qn = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    w, x, y, z = q[0] / qn, q[1] / qn, q[2] / qn, q[3] / qn
    lx, ly, lz = L[0], L[1], L[2]
    if lx == 0.0 and ly == 0.0 and lz == 0.0 or h == 0.0:
        q_out[0], q_out[1], q_out[2], q_out[3] = w, x, y, z
        return
    # m = R^T L (body principal components)
    mp0 = (1.0 - 2.0 * (y * y + z * z)) * lx + 2.0 * (x * y + w * z) * ly + 2.0 * (x * z - w * y) * lz
    mp1 = 2.0 * (x * y - w * z) * lx + (1.0 - 2.0 * (x * x + z * z)) * ly + 2.0 * (y * z + w * x) * lz
    mp2 = 2.0 * (x * z + w * y) * lx + 2.0 * (y * z - w * x) * ly + (1.0 - 2.0 * (x * x + y * y)) * lz
    sphere, big_a, w1, w2, w3, s1, s2, s3 = working_frame(inertia, mp0, mp1, mp2)
    if sphere:
        # sphere: omega = L / I is constant in the world, R(t) = exp(h [omega]x) R(0)
        angle = math.sqrt(lx * lx + ly * ly + lz * lz) / big_a * h
        axis = 1.0 / math.sqrt(lx * lx + ly * ly + lz * lz)
        sh = math.sin(0.5 * angle) * axis
        out = _quat_mul(math.cos(0.5 * angle), sh * lx, sh * ly, sh * lz, w, x, y, z)
        q_out[0], q_out[1], q_out[2], q_out[3] = out[0], out[1], out[2], out[3]
        return
    m1, m2, m3 = _pick(mp0, mp1, mp2, w1), _pick(mp0, mp1, mp2, w2), _pick(mp0, mp1, mp2, w3)
    dw, dx, dy, dz = _working_frame_step(inertia[w1], inertia[w2], inertia[w3], s1 * m1, s2 * m2, s3 * m3, h, work)
    # back to principal components: the axis of D is C^T d, (C^T d)[w_i] = s_i d_i
    d0 = _scatter(s1 * dx, s2 * dy, s3 * dz, w1, w2, w3, 0)
    d1 = _scatter(s1 * dx, s2 * dy, s3 * dz, w1, w2, w3, 1)
    d2 = _scatter(s1 * dx, s2 * dy, s3 * dz, w1, w2, w3, 2)
    out = _quat_mul(w, x, y, z, dw, d0, d1, d2)
    norm = math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] + out[3] * out[3])
    q_out[0], q_out[1], q_out[2], q_out[3] = out[0] / norm, out[1] / norm, out[2] / norm, out[3] / norm


@numba.njit(cache=True)
def free_rotation_exact_batch(
    inertia: np.ndarray, q: np.ndarray, L: np.ndarray, h: float, q_out: np.ndarray, work: np.ndarray
) -> None:
    """``free_rotation_exact`` for every body: inertia (N, 3) principal [kg m^2], q (N, 4) wxyz
    world-from-principal, L (N, 3) world [kg m^2/s], time step h [s]; writes q_out (N, >= 4).
    work: (JACOBI_WORK_SIZE,) scratch, passed in so a step allocates nothing."""
    for i in range(q.shape[0]):
        _free_rotation_exact_work(inertia[i], q[i], L[i], h, q_out[i], work)
