"""The exact torque-free flow from an anchor: constants prepared once, then one cheap evaluation per time.

`free_rotation_exact` computes q(t0 + h) from (q(t0), L) in one call. The `exact` integrator evaluates
the flow of a body many times from the same anchor state (each recorded frame, each step's end), and
most of that call depends on the anchor only: the body momentum m0 = R^T L, the working frame, the
amplitudes, lambda, the parameter mc, u_0 = F(phi_0|m) (a Carlson R_F), Pi(-N; phi_0|m) (R_F + R_J),
K, the complete Pi (R_F + R_J again), the descending AGM of the Jacobi functions (it depends on mc
only), the rotation P(m0) and its product with q(t0). `anchor_prepare` computes them once into
ANCHOR_CONSTANTS floats (a row of the integrator's scratch); `anchor_evaluate` then needs the
ascending half of the Jacobi functions at u_0 + lambda h, psi, and the quaternion products. The
equations, branches and accuracy are those of `free_rotation_exact`'s docstring, split at the anchor,
with two differences in how psi is evaluated (both measured against the 50-digit reference in the tests):

- psi by a Fourier series in u (`_prepare_fourier`): psi' is a 2K-periodic function of u, so psi is
  its mean rate times h plus a periodic part kept as at most FOURIER_TERMS sine coefficients at the
  anchor: one cosine/sine pair and a Clenshaw sum per evaluation instead of the incomplete Pi (two
  Carlson integrals) and an arctangent. Used where the coefficients fall below EPS within that many
  terms (97% of the benchmark's random bodies); near the separatrix and for N >> 1 the closed form
  with Pi stays (its half-turn count now round(u / 2K), no arctangent of the amplitude).
- the short-arc and thin-rod quadratures read the kept AGM (`ellipj_kept`), so no work array is needed.

Cost (benchmarks/bench_exact.py, 10,000 bodies): see docs/integrators.md.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.elliptic import (
    JACOBI_PREPARED_SIZE,
    ellipj_kept,
    ellipk_mc,
    ellippi_complete_mc,
    ellippi_sc,
    elliprf,
    jacobi_prepare,
)
from rbcli.physics.free_rotation_exact import (
    _GL_MAX,
    _GL_W,
    _GL_X,
    _pick,
    _psi_rate,
    _quat_e3_to,
    _quat_mul,
    _scatter,
    working_frame,
)
from rbcli.physics.step import STEP_KERNEL

# what the body does, constant 0 of a prepared row
KIND_FIXED = 0.0  # L = 0: q stays
KIND_SPHERE = 1.0  # equal moments: q(h) = exp(h omega / 2) q, omega = L / I
KIND_STEADY = 2.0  # m is an eigenvector (a principal-axis spin): m stays, psi grows at a constant rate
KIND_PRECESSION = 3.0  # two equal moments (I_1 = I_2 in the working frame): regular precession
KIND_ELLIPTIC = 4.0  # the general case: Jacobi functions and Pi (or quadrature of psi')

# columns of a prepared row
_KIND = 0
_A = 1  # (4) q(t0) for FIXED / SPHERE; q(t0) C^T P(m0) C (the anchor's rotation into the L frame) otherwise
_AXIS = 5  # (3) working axes w1, w2, w3 (principal indices); SPHERE: omega (3) [rad/s], world
_SIGN = 8  # (3) their signs s1, s2, s3
_RATE = 11  # psi' [rad/s] of STEADY / PRECESSION
_LAM, _U0, _MC, _A1, _A2, _A3, _G, _TWO_E, _C3, _DIST = range(12, 22)
_QUADRATURE = 22  # 1.0: psi by quadrature always (the closed form is ill-conditioned for this body)
_NN, _SQ, _PI0, _TH0, _K, _PIC, _COEF, _G_I3, _PERIOD, _WHOLE = range(23, 33)
_M = 33  # (3) STEADY: the fixed working-frame momentum
# psi by its Fourier series in u (_prepare_fourier): the mean rate [rad/s], psi's periodic part at u_0
# [rad], the number of terms (0: none, use Pi), pi / K, then the sine coefficients [rad]
_RATE_MEAN, _P0, _TERMS, _PI_K, _FOURIER = range(36, 41)
FOURIER_TERMS = 16  # at most this many coefficients are kept (more: Pi instead)
_SAMPLES = 64  # samples of psi' over one period 2K for them (aliasing: coefficient 64 - k, negligible)
# cos(2 pi i / S): the cosines of the discrete cosine sums, taken once (the same libm cos and operations
# as math.cos in a kernel, so the same bits; 660 cos calls were 5 of the 7 us of an anchor's preparation)
_COS = np.array([math.cos(2.0 * math.pi * i / _SAMPLES) for i in range(_SAMPLES)])
_SLOTS = FOURIER_TERMS + 4  # the coefficients' columns: 4 more to test the tail while preparing
_JACOBI = _FOURIER + _SLOTS  # (JACOBI_PREPARED_SIZE) the Jacobi functions' AGM (elliptic.jacobi_prepare)
ANCHOR_CONSTANTS = _JACOBI + JACOBI_PREPARED_SIZE


@numba.njit(cache=True, inline="always")
def _set4(c: np.ndarray, at: int, w: float, x: float, y: float, z: float) -> None:
    c[at], c[at + 1], c[at + 2], c[at + 3] = w, x, y, z


@numba.njit(cache=True, inline="always")
def _quat_e3_to_norm(m1: float, m2: float, m3: float, g: float) -> tuple[float, float, float, float]:
    """`_quat_e3_to` given g = |m| (the constant G along the flow: one square root fewer)."""
    w = g + m3
    inverse = 1.0 / math.sqrt(w * w + m1 * m1 + m2 * m2)
    return w * inverse, -m2 * inverse, m1 * inverse, 0.0


@numba.njit(**STEP_KERNEL)
def anchor_prepare(inertia: np.ndarray, q: np.ndarray, L: np.ndarray, c: np.ndarray) -> None:
    """Write into c (ANCHOR_CONSTANTS,) what the flow from (q, L) needs at every time (module docstring).

    inertia: principal moments (3,) [kg m^2]; q: wxyz world-from-principal (normalised here); L: world
    angular momentum [kg m^2/s]."""
    qn = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    w, x, y, z = q[0] / qn, q[1] / qn, q[2] / qn, q[3] / qn
    lx, ly, lz = L[0], L[1], L[2]
    _set4(c, _A, w, x, y, z)
    c[_KIND] = KIND_FIXED
    if lx == 0.0 and ly == 0.0 and lz == 0.0:
        return
    mp0 = (1.0 - 2.0 * (y * y + z * z)) * lx + 2.0 * (x * y + w * z) * ly + 2.0 * (x * z - w * y) * lz
    mp1 = 2.0 * (x * y - w * z) * lx + (1.0 - 2.0 * (x * x + z * z)) * ly + 2.0 * (y * z + w * x) * lz
    mp2 = 2.0 * (x * z + w * y) * lx + 2.0 * (y * z - w * x) * ly + (1.0 - 2.0 * (x * x + y * y)) * lz
    sphere, big_a, w1, w2, w3, s1, s2, s3 = working_frame(inertia, mp0, mp1, mp2)
    if sphere:
        c[_KIND] = KIND_SPHERE
        c[_AXIS], c[_AXIS + 1], c[_AXIS + 2] = lx / big_a, ly / big_a, lz / big_a
        return
    m1, m2, m3 = _pick(mp0, mp1, mp2, w1), _pick(mp0, mp1, mp2, w2), _pick(mp0, mp1, mp2, w3)
    c[_AXIS], c[_AXIS + 1], c[_AXIS + 2] = w1, w2, w3
    c[_SIGN], c[_SIGN + 1], c[_SIGN + 2] = s1, s2, s3
    m1, m2, m3 = s1 * m1, s2 * m2, s3 * m3
    i1, i2, i3 = inertia[w1], inertia[w2], inertia[w3]
    # A = q(t0) C^T P(m0) C: the working-frame rotation P(m0) taken back to principal axes
    pw, px, py, pz = _quat_e3_to(m1, m2, m3)
    ex, ey, ez = s1 * px, s2 * py, s3 * pz
    a = _quat_mul(w, x, y, z, pw, _scatter(ex, ey, ez, w1, w2, w3, 0), _scatter(ex, ey, ez, w1, w2, w3, 1),
                  _scatter(ex, ey, ez, w1, w2, w3, 2))  # fmt: skip
    _set4(c, _A, a[0], a[1], a[2], a[3])
    _prepare_working(i1, i2, i3, m1, m2, m3, c)


@numba.njit(**STEP_KERNEL)
def _prepare_working(i1: float, i2: float, i3: float, m1: float, m2: float, m3: float, c: np.ndarray) -> None:
    """The working-frame constants (free_rotation_exact._working_frame_step's anchor half)."""
    g = math.sqrt(m1 * m1 + m2 * m2 + m3 * m3)
    d21, d32, d31 = abs(i2 - i1), abs(i3 - i2), abs(i3 - i1)
    big_d1 = m2 * m2 * d21 / i2 + m3 * m3 * d31 / i3
    big_d3 = m1 * m1 * d31 / i1 + m2 * m2 * d32 / i2
    lam = math.sqrt(d32 * big_d1 / (i1 * i2 * i3))
    c[_M], c[_M + 1], c[_M + 2] = m1, m2, m3
    c[_G] = g  # |m| along the whole flow (every kind below reads it)
    c[_KIND] = KIND_STEADY
    c[_RATE] = _psi_rate(i1, i2, i3, m1, m2, m3)
    if lam == 0.0:
        return
    k2 = d21 * big_d3 / (d32 * big_d1)
    d2 = m3 * m3 * d32 / i3 - m1 * m1 * d21 / i1
    mc = max(d31 * d2 / (d32 * big_d1), 0.0)
    if k2 <= 0.5:
        mc = 1.0 - k2
    mc = min(mc, 1.0)
    r = i1 * d32 / (i2 * d31)
    a1 = math.sqrt(m1 * m1 + r * m2 * m2)
    a2 = math.sqrt(m1 * m1 / r + m2 * m2)
    a3 = math.sqrt(m3 * m3 + m2 * m2 * i3 * d21 / (i2 * d31))
    sgn = 1.0 if i3 > i1 else -1.0
    sphi = sgn * m2 * math.sqrt(r)
    cphi = m1
    rho = math.hypot(sphi, cphi)
    if rho == 0.0:
        sphi, cphi = 0.0, 1.0
    else:
        sphi, cphi = sphi / rho, cphi / rho
    if cphi == 0.0 and mc == 0.0:
        return  # the intermediate-axis equilibrium: steady
    c2 = cphi * cphi
    nn = i3 * d21 / (i1 * d32)
    two_e = m1 * m1 / i1 + m2 * m2 / i2 + m3 * m3 / i3
    c[_LAM], c[_MC], c[_A1], c[_A2], c[_A3], c[_G], c[_TWO_E] = lam, mc, a1, sgn * a2, a3, g, two_e
    c[_U0] = sphi * elliprf(c2, c2 + mc * sphi * sphi, 1.0)
    c[_C3] = g * a3 / i3
    if nn == 0.0 and mc == 1.0:
        c[_KIND] = KIND_PRECESSION
        c[_RATE] = a3 / i3 + a1 * a1 / ((g + a3) * i1)
        return
    c[_KIND] = KIND_ELLIPTIC
    jacobi_prepare(mc, c[_JACOBI:ANCHOR_CONSTANTS])
    c[_DIST] = min(1.0, math.atan(1.0 / math.sqrt(nn))) if nn > 0.0 else 1.0
    amplification = g * g / two_e * max(1.0 / i3, abs(1.0 / i1 - 1.0 / i3))
    c[_QUADRATURE] = 1.0 if amplification > 16.0 else 0.0
    sq = math.sqrt(1.0 + nn)
    c[_NN], c[_SQ] = nn, sq
    c[_PI0] = ellippi_sc(-nn, sphi, cphi, mc)
    c[_TH0] = math.atan2(sq * sphi, cphi)
    kk = ellipk_mc(mc) if mc > 0.0 else math.inf
    c[_K] = kk
    c[_PIC] = ellippi_complete_mc(-nn, mc) if mc > 0.0 else math.inf
    c[_COEF] = (i3 - i1) / (i1 * i3 * lam)
    c[_G_I3] = g / i3
    c[_PERIOD] = 2.0 * kk
    c[_WHOLE] = math.nan
    c[_TERMS] = 0.0
    if mc > 0.0:
        _prepare_fourier(c)
    if c[_QUADRATURE] == 1.0 and mc > 0.0:
        # psi' integrated over one whole period by the trapezoidal rule (free_rotation_exact._quadrature_psi)
        points = int(math.ceil(14.7 * kk / c[_DIST])) + 1
        if points <= 4000:
            whole = 0.0
            for k in range(points):
                _, _, dn = ellipj_kept(c[_U0] + k * 2.0 * kk / points, mc, c[_JACOBI:ANCHOR_CONSTANTS])
                whole += (two_e + c[_C3] * dn) / (g + a3 * dn)
            c[_WHOLE] = whole * 2.0 * kk / points


@numba.njit(**STEP_KERNEL)
def _gauss_legendre_psi(c: np.ndarray, ua: float, span: float) -> float:
    """free_rotation_exact._gauss_legendre_psi with this anchor's constants and kept Jacobi AGM (bitwise
    the same sum: ellipj_kept equals ellipj_mc_work)."""
    if span <= 0.0:
        return 0.0
    two_e, c3, g, a3, mc, dist = c[_TWO_E], c[_C3], c[_G], c[_A3], c[_MC], c[_DIST]
    panels = int(math.ceil(span / (0.5 * dist)))
    length = span / panels
    x = 1.6 * dist / length
    rho = x + math.sqrt(x * x + 1.0)
    n = min(_GL_MAX, max(1, int(math.ceil(20.7 / math.log(rho)))))
    total = 0.0
    for p in range(panels):
        centre = ua + (p + 0.5) * length
        for i in range(n):
            _, _, dn = ellipj_kept(centre + 0.5 * length * _GL_X[n, i], mc, c[_JACOBI:ANCHOR_CONSTANTS])
            total += _GL_W[n, i] * (two_e + c3 * dn) / (g + a3 * dn)
    return 0.5 * length * total


@numba.njit(**STEP_KERNEL)
def _prepare_fourier(c: np.ndarray) -> None:
    """psi's integrand in u, f(u) = (2E + G a3 dn u / I3) / (G + a3 dn u) (positive terms), is even and
    2K-periodic, so f = f_0 + sum_k a_k cos(k pi u / K) and, with P(u) = sum_k b_k sin(k pi u / K),
    b_k = a_k K / (k pi):  psi(u1) - psi(u0) = [f_0 (u1 - u0) + P(u1) - P(u0)] / lambda.
    f is analytic in the strip |Im u| < y_N (sn^2 = -1/N there, the zero of G + a3 dn), so a_k falls
    like exp(-k pi y_N / K): a few terms away from the separatrix (K small) and for moderate N. The a_k
    are the discrete cosine sums of _SAMPLES values of f over one period (the trapezoidal rule, exact
    up to the aliased a_{S-k}, a_{S+k}); the series is kept when the four coefficients after the last
    kept one are below EPS lambda / 4 (truncation then moves psi by < EPS / 2 rad), else (near the
    separatrix, N >> 1) the closed form with Pi is used. Jacobi functions' Fourier series and strips
    of analyticity: DLMF 22.11; the pole distance: free_rotation_exact._gauss_legendre_psi's dist."""
    two_e, c3, g, a3, mc, kk = c[_TWO_E], c[_C3], c[_G], c[_A3], c[_MC], 0.5 * c[_PERIOD]
    kept = c[_JACOBI:ANCHOR_CONSTANTS]
    # a_k (k = 1 .. _SLOTS) summed in place, then turned into the sine coefficients b_k = a_k K / (k pi).
    # f(2K - u) = f(u): samples j and S - j are equal, so half a period of samples suffices. Each
    # cos(2 pi j k / S) is a correctly taken table entry (a recurrence in k would add rounding growing with k).
    half = _SAMPLES // 2
    for k in range(_SLOTS):
        c[_FOURIER + k] = 0.0
    # the mean rate multiplies the whole elapsed time (2e5 rad at 2000 s for the fast spin): summed with
    # Neumaier's compensation (Kahan-Babuska), 3e-17 relative there instead of 2e-16 plainly summed
    mean, compensation = 0.0, 0.0
    for j in range(half + 1):
        _, _, dn = ellipj_kept(j * c[_PERIOD] / _SAMPLES, mc, kept)
        f = (two_e + c3 * dn) / (g + a3 * dn)
        weight = 1.0 if j == 0 or j == half else 2.0
        total = mean + weight * f
        if abs(mean) >= abs(weight * f):
            compensation += (mean - total) + weight * f
        else:
            compensation += (weight * f - total) + mean
        mean = total
        for k in range(_SLOTS):
            c[_FOURIER + k] += weight * f * _COS[(j * (k + 1)) % _SAMPLES]
    for k in range(_SLOTS):
        c[_FOURIER + k] *= 2.0 / _SAMPLES * kk / ((k + 1) * math.pi)
    # truncation moves psi by at most 2 sum_(k > terms) |b_k| / lambda: keep that below EPS / 2 rad
    tol = 2.0**-52 * c[_LAM] / 4.0
    for terms in range(FOURIER_TERMS + 1):
        tail = abs(c[_FOURIER + terms]) + abs(c[_FOURIER + terms + 1]) + abs(c[_FOURIER + terms + 2])
        if tail + abs(c[_FOURIER + terms + 3]) <= tol:
            c[_TERMS] = terms
            c[_RATE_MEAN] = (mean + compensation) / _SAMPLES  # f_0 span / lambda = f_0 h
            c[_PI_K] = math.pi / kk
            c[_P0] = _fourier_sum(c, c[_U0])
            return


@numba.njit(cache=True, inline="always")
def _fourier_sum(c: np.ndarray, u: float) -> float:
    """P(u) = sum_k b_k sin(k pi u / K) (_prepare_fourier) by Clenshaw's recurrence, u reduced mod 2K."""
    r = u - c[_PERIOD] * round(u / c[_PERIOD])
    theta = r * c[_PI_K]
    two_cos = 2.0 * math.cos(theta)
    y1, y2 = 0.0, 0.0
    for k in range(int(c[_TERMS]) - 1, -1, -1):
        y1, y2 = c[_FOURIER + k] + two_cos * y1 - y2, y1
    return y1 * math.sin(theta)


@numba.njit(**STEP_KERNEL)
def _psi_by_quadrature(c: np.ndarray, span: float) -> float:
    """int of psi' over u in [u0, u0 + span] (whole periods from the prepared sum); nan when too costly."""
    sign, start = 1.0, c[_U0]
    if span < 0.0:
        start, span, sign = start + span, -span, -1.0
    count = 0.0
    if c[_MC] > 0.0:
        count = math.floor(span / c[_PERIOD])
    if count > 0.0 and math.isnan(c[_WHOLE]):
        return math.nan
    rest = span - count * c[_PERIOD]
    if 10.0 * math.ceil(rest / (0.5 * c[_DIST])) > 4000.0:
        return math.nan
    whole = count * c[_WHOLE] if count > 0.0 else 0.0
    rest_integral = _gauss_legendre_psi(c, start, rest)
    return sign * (whole + rest_integral)


@numba.njit(**STEP_KERNEL)
def anchor_evaluate(c: np.ndarray, h: float, q_out: np.ndarray) -> None:
    """q_out (4,) = the orientation h [s] after the anchor whose constants c `anchor_prepare` wrote."""
    kind = c[_KIND]
    if kind == KIND_FIXED:
        _set4(q_out, 0, c[_A], c[_A + 1], c[_A + 2], c[_A + 3])
        return
    if kind == KIND_SPHERE:
        ox, oy, oz = c[_AXIS], c[_AXIS + 1], c[_AXIS + 2]
        rate = math.sqrt(ox * ox + oy * oy + oz * oz)
        sh = math.sin(0.5 * rate * h) / rate
        out = _quat_mul(math.cos(0.5 * rate * h), sh * ox, sh * oy, sh * oz, c[_A], c[_A + 1], c[_A + 2], c[_A + 3])
        _set4(q_out, 0, out[0], out[1], out[2], out[3])
        return
    if kind == KIND_STEADY:
        m1n, m2n, m3n = c[_M], c[_M + 1], c[_M + 2]
        dpsi = h * c[_RATE]
    elif kind == KIND_PRECESSION:
        u1 = c[_U0] + c[_LAM] * h
        m1n, m2n, m3n = c[_A1] * math.cos(u1), c[_A2] * math.sin(u1), c[_A3]
        dpsi = h * c[_RATE]
    else:
        span = c[_LAM] * h
        u1 = c[_U0] + span
        mc = c[_MC]
        sn, cn, dn = ellipj_kept(u1, mc, c[_JACOBI:ANCHOR_CONSTANTS])
        m1n, m2n, m3n = c[_A1] * cn, c[_A2] * sn, c[_A3] * dn
        dpsi = math.nan
        if abs(span) <= 0.5 * c[_DIST] or c[_QUADRATURE] == 1.0:
            dpsi = _psi_by_quadrature(c, span) / c[_LAM]
        if math.isnan(dpsi) and c[_TERMS] > 0.0:
            dpsi = h * c[_RATE_MEAN] + (_fourier_sum(c, u1) - c[_P0]) / c[_LAM]
        if math.isnan(dpsi):
            nn, sq = c[_NN], c[_SQ]
            # am u1 = j pi + r1, |r1| <= pi/2: am is increasing with am((2j + 1) K) = (2j + 1) pi / 2, so
            # j = round(u1 / 2K), and then sin r1 = (-1)^j sn, cos r1 = (-1)^j cn >= 0. Where u1 / 2K
            # rounds to the neighbouring half-turn (cn ~ 0), r1 = -+pi/2 on that side is the same am, and
            # c1 = |cn| absorbs the rounding of cn's sign. (No atan2 of the amplitude, no hypot: sn^2 + cn^2
            # = 1 to rounding as the Jacobi functions return them.)
            j = round(u1 / c[_PERIOD]) if mc > 0.0 else 0.0
            s1 = -sn if j - 2.0 * math.floor(0.5 * j) == 1.0 else sn
            c1 = abs(cn)
            pi1 = ellippi_sc(-nn, s1, c1, mc)
            th1 = math.atan2(sq * s1, c1)
            if j != 0.0:
                pi1 += 2.0 * j * c[_PIC]
                th1 += j * math.pi
            bracket = c[_G] * (pi1 - c[_PI0]) - c[_A3] * (th1 - c[_TH0]) / sq
            dpsi = c[_G_I3] * h + c[_COEF] * bracket
    # D' = Rz(dpsi) P(m1)^T in the working frame, taken to principal axes, after A
    pw, px, py, pz = _quat_e3_to_norm(m1n, m2n, m3n, c[_G])
    half = 0.5 * dpsi
    cw, sz = math.cos(half), math.sin(half)
    dw, dx, dy, dz = _quat_mul(cw, 0.0, 0.0, sz, pw, -px, -py, -pz)
    w1, w2, w3 = int(c[_AXIS]), int(c[_AXIS + 1]), int(c[_AXIS + 2])
    ex, ey, ez = c[_SIGN] * dx, c[_SIGN + 1] * dy, c[_SIGN + 2] * dz
    out = _quat_mul(c[_A], c[_A + 1], c[_A + 2], c[_A + 3], dw, _scatter(ex, ey, ez, w1, w2, w3, 0),
                    _scatter(ex, ey, ez, w1, w2, w3, 1), _scatter(ex, ey, ez, w1, w2, w3, 2))  # fmt: skip
    inverse = 1.0 / math.sqrt(out[0] * out[0] + out[1] * out[1] + out[2] * out[2] + out[3] * out[3])
    _set4(q_out, 0, out[0] * inverse, out[1] * inverse, out[2] * inverse, out[3] * inverse)
