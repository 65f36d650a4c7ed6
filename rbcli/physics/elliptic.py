"""Compiled (numba) elliptic functions and integrals for the exact torque-free rigid body.

Scalar float64 functions, pure math (no scipy), callable from other ``njit`` kernels and from Python.
Conventions follow DLMF chapters 19 and 22 and ``scipy.special``: parameter ``m = k^2`` with
``0 <= m <= 1``, complementary parameter ``mc = 1 - m``,

    K(m)        = int_0^{pi/2} dt / sqrt(1 - m sin^2 t)
    F(phi|m)    = int_0^phi dt / sqrt(1 - m sin^2 t)
    Pi(n;phi|m) = int_0^phi dt / ((1 - n sin^2 t) sqrt(1 - m sin^2 t))
    sn, cn, dn: sn(u|m) = sin(am(u|m)), am the inverse of F(.|m).

Every function that the physics needs near the separatrix (m -> 1) has a ``_mc`` twin that takes the
complementary parameter: there ``1 - m`` is the small, cancellation-prone quantity, and the caller can
often compute it directly (see ``free_rotation_exact``), so it is never formed as ``1 - m``.

Sources:
- Carlson 1995, "Numerical computation of real or complex elliptic integrals", Numer. Algorithms 10:
  duplication algorithms for R_F, R_C (Cauchy principal value for y < 0) and R_J (the form with
  d_m, e_m and R_C(1, 1 + e_m), as in DLMF 19.36(i)); R_J's principal value for p < 0 by the
  transformation of DLMF 19.20.14. R_F and R_J of the same x, y, z share one duplication loop
  (`_elliprf_rj`: their x, y, z sequences are the same); R_C(1, 1 + e_m) by its Maclaurin series
  sum (-e)^k / (2k + 1) once |e_m| < 0.01 (R_J's later steps: e_m shrinks ~64x per step). The stopping
  test Q = (3r)^(-1/6) max|A_0 - x| with r = 1e-16 is Carlson's, the same as an "ERRTOL" of 0.0025
  in his 1979 form (error ~ ERRTOL^6): a larger tolerance saves steps only by losing digits.
- DLMF 19.25.5 / 19.25.14: F and Pi through R_F and R_J; DLMF 19.7.9: Pi(n) + Pi(m/n) = F + R_C term
  (used for n < -1); DLMF 19.2.10 / 19.6: quasi-periodicity in phi.
- Bulirsch 1965, "Numerical calculation of elliptic integrals and elliptic functions" (Numer. Math. 7),
  algorithm ``sncndn``: sn, cn, dn from the descending Gauss transformation (AGM), taking mc as input.
- K by the arithmetic-geometric mean: K = pi / (2 AGM(1, sqrt(mc))) (DLMF 19.8.5).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics import kernel_cache

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources

# Carlson's series are truncated after degree 5 (R_F, R_J) or 7 (R_C); the iteration stops when the
# neglected terms are below about this relative size (Carlson 1995 eq. 2.2: error < r / (4 (1 - r))).
_CARLSON_TOL = 1.0e-16
# Q multipliers of Carlson 1995: (3r)^(-1/6) for R_F, (r/4)^(-1/6) for R_J, (3r)^(-1/8) for R_C
_RF_Q = (3.0 * _CARLSON_TOL) ** (-1.0 / 6.0)
_RJ_Q = (0.25 * _CARLSON_TOL) ** (-1.0 / 6.0)
_RC_Q = (3.0 * _CARLSON_TOL) ** (-1.0 / 8.0)
# AGM stops when |a - b| <= tol a; the next mean is then exact to about (tol/4)^2 relative
_AGM_TOL = 1.0e-9
_MAX_ITER = 64
# levels kept by the Jacobi-function AGM (13 suffice for mc down to the smallest subnormal)
_JACOBI_LEVELS = 24
JACOBI_WORK_SIZE = 2 * _JACOBI_LEVELS


@numba.njit(cache=True)
def elliprc(x: float, y: float) -> float:
    """Carlson R_C(x, y) = R_F(x, y, y), x >= 0, y != 0; Cauchy principal value for y < 0.

    Duplication algorithm of Carlson 1995 (eqs. 2.13-2.16) with the degree-7 series of eq. 2.16.
    """
    if x < 0.0 or y == 0.0 or math.isnan(x) or math.isnan(y):
        return math.nan
    scale = 1.0
    if y < 0.0:
        # Carlson 1995 eq. 2.14: R_C(x, y) = sqrt(x / (x - y)) R_C(x - y, -y)
        scale = math.sqrt(x / (x - y))
        x, y = x - y, -y
    a0 = (x + 2.0 * y) / 3.0
    y0 = y
    q = _RC_Q * abs(a0 - x)
    a = a0
    f = 1.0
    for _ in range(_MAX_ITER):
        if f * q < abs(a):
            break
        lam = 2.0 * math.sqrt(x) * math.sqrt(y) + y
        a = 0.25 * (a + lam)
        x = 0.25 * (x + lam)
        y = 0.25 * (y + lam)
        f *= 0.25
    s = (y0 - a0) * f / a  # Carlson's s = (y0 - A0) / (4^n A_n), not y_n - A_n (cancels)
    s2 = s * s
    poly = 1.0 + s2 * (0.3 + s * (1.0 / 7.0 + s * (0.375 + s * (9.0 / 22.0 + s * (159.0 / 208.0 + s * 1.125)))))
    return scale * poly / math.sqrt(a)


@numba.njit(cache=True)
def elliprf(x: float, y: float, z: float) -> float:
    """Carlson R_F(x, y, z) = 1/2 int_0^inf dt / sqrt((t+x)(t+y)(t+z)), x, y, z >= 0, at most one zero.

    Duplication algorithm of Carlson 1995 (eqs. 2.2-2.4); returns inf when two arguments are zero.
    """
    if x < 0.0 or y < 0.0 or z < 0.0 or math.isnan(x + y + z):
        return math.nan
    if (x == 0.0) + (y == 0.0) + (z == 0.0) >= 2:
        return math.inf
    a0 = (x + y + z) / 3.0
    q = _RF_Q * max(abs(a0 - x), abs(a0 - y), abs(a0 - z))
    a = a0
    x0, y0 = x, y
    f = 1.0
    for _ in range(_MAX_ITER):
        if f * q < abs(a):
            break
        sx, sy, sz = math.sqrt(x), math.sqrt(y), math.sqrt(z)
        lam = sx * sy + sx * sz + sy * sz
        a = 0.25 * (a + lam)
        x = 0.25 * (x + lam)
        y = 0.25 * (y + lam)
        z = 0.25 * (z + lam)
        f *= 0.25
    xx = (a0 - x0) * f / a
    yy = (a0 - y0) * f / a
    zz = -(xx + yy)
    e2 = xx * yy - zz * zz
    e3 = xx * yy * zz
    poly = 1.0 - 0.1 * e2 + e3 / 14.0 + e2 * e2 / 24.0 - 3.0 * e2 * e3 / 44.0
    return poly / math.sqrt(a)


@numba.njit(cache=True)
def _rc_one_plus(e: float, one_plus_e: float) -> float:
    """R_C(1, 1 + e) for e > -1, in closed form (DLMF 19.2.18-19.2.19).

    e > 0: atan(sqrt e) / sqrt e; e < 0: atanh(r) / r with r = sqrt(-e). Both are relatively accurate
    as e -> 0. As e -> -1, atanh(r) needs 1 - r = (1 + e) / (1 + r), so the caller passes 1 + e
    computed without cancellation.
    """
    if abs(e) < 0.01:
        # the Maclaurin series sum (-e)^k / (2k + 1) of both closed forms: truncated after e^7, the
        # error is below e^8 / 17 < 6e-18 relative; R_J's later duplication steps (e_m shrinks ~64x
        # per step) all land here, so they need no atan / atanh
        tail = 1.0 / 11.0 - e * (1.0 / 13.0 - e * (1.0 / 15.0))
        return 1.0 - e * (1.0 / 3.0 - e * (0.2 - e * (1.0 / 7.0 - e * (1.0 / 9.0 - e * tail))))
    if e > 0.0:
        r = math.sqrt(e)
        return math.atan(r) / r
    if e < 0.0:
        r = math.sqrt(-e)
        if r < 0.5:
            return math.atanh(r) / r
        return 0.5 * math.log((1.0 + r) * (1.0 + r) / one_plus_e) / r
    return 1.0


@numba.njit(cache=True)
def _elliprf_rj(x: float, y: float, z: float, p: float) -> tuple[float, float]:
    """(R_F(x, y, z), R_J(x, y, z, p)) for p > 0 in one duplication loop (Carlson 1995 eqs. 2.2-2.4 and
    2.36-2.39, d_m / e_m form as in DLMF 19.36.ii).

    x, y, z follow the same duplication x_{m+1} = (x_m + lambda_m) / 4 in both algorithms, so the
    square roots and lambda_m are shared (R_F alone costs as much again); the loop runs until both
    stopping tests of Carlson 1995 hold (more steps only make R_F more accurate).
    """
    a0 = (x + y + z + 2.0 * p) / 5.0
    af0 = (x + y + z) / 3.0
    delta = (p - x) * (p - y) * (p - z)
    q = _RJ_Q * max(abs(a0 - x), abs(a0 - y), abs(a0 - z), abs(a0 - p))
    qf = _RF_Q * max(abs(af0 - x), abs(af0 - y), abs(af0 - z))
    x0, y0, z0 = x, y, z
    a = a0
    af = af0
    f = 1.0  # 4^-m
    f3 = 1.0  # 4^-3m
    total = 0.0
    for _ in range(_MAX_ITER):
        if f * q < abs(a) and f * qf < abs(af):
            break
        sx, sy, sz, sp = math.sqrt(x), math.sqrt(y), math.sqrt(z), math.sqrt(p)
        lam = sx * sy + sx * sz + sy * sz
        d = (sp + sx) * (sp + sy) * (sp + sz)
        e = f3 * delta / (d * d)
        # 1 + e_m = 2 sqrt(p) (p + lambda) / d_m exactly (expand prod(sp + sx) + prod(sp - sx), as
        # delta_m = prod(sp - sx) d_m); forming 1 + e directly cancels when p << x, y, z (e -> -1)
        one_plus_e = 2.0 * sp * (p + lam) / d
        total += f * _rc_one_plus(e, one_plus_e) / d
        a = 0.25 * (a + lam)
        af = 0.25 * (af + lam)
        x = 0.25 * (x + lam)
        y = 0.25 * (y + lam)
        z = 0.25 * (z + lam)
        p = 0.25 * (p + lam)
        f *= 0.25
        f3 *= 1.0 / 64.0
    # R_F's degree-5 series (Carlson 1995 eq. 2.3)
    xf = (af0 - x0) * f / af
    yf = (af0 - y0) * f / af
    zf = -(xf + yf)
    e2f = xf * yf - zf * zf
    e3f = xf * yf * zf
    rf = (1.0 - 0.1 * e2f + e3f / 14.0 + e2f * e2f / 24.0 - 3.0 * e2f * e3f / 44.0) / math.sqrt(af)
    # R_J's (eq. 2.39)
    xx = (a0 - x0) * f / a
    yy = (a0 - y0) * f / a
    zz = (a0 - z0) * f / a
    pp = -0.5 * (xx + yy + zz)
    p2 = pp * pp
    xyz = xx * yy * zz
    e2 = xx * yy + xx * zz + yy * zz - 3.0 * p2
    e3 = xyz + 2.0 * e2 * pp + 4.0 * p2 * pp
    e4 = (2.0 * xyz + e2 * pp + 3.0 * p2 * pp) * pp
    e5 = xyz * p2
    poly = (
        1.0
        - 3.0 * e2 / 14.0
        + e3 / 6.0
        + 9.0 * e2 * e2 / 88.0
        - 3.0 * e4 / 22.0
        - 9.0 * e2 * e3 / 52.0
        + 3.0 * e5 / 26.0
    )
    return rf, f * poly / (a * math.sqrt(a)) + 6.0 * total


@numba.njit(cache=True)
def _elliprj_positive(x: float, y: float, z: float, p: float) -> float:
    """R_J for p > 0 (`_elliprf_rj`, whose R_F comes nearly free)."""
    return _elliprf_rj(x, y, z, p)[1]


@numba.njit(cache=True)
def elliprj(x: float, y: float, z: float, p: float) -> float:
    """Carlson R_J(x, y, z, p) = 3/2 int_0^inf dt / ((t+p) sqrt((t+x)(t+y)(t+z))).

    x, y, z >= 0 with at most one zero, p != 0; for p < 0 the Cauchy principal value
    (Carlson 1995 eq. 2.22 / DLMF 19.20.14, with x <= y <= z).
    """
    if x < 0.0 or y < 0.0 or z < 0.0 or p == 0.0 or math.isnan(x + y + z + p):
        return math.nan
    if (x == 0.0) + (y == 0.0) + (z == 0.0) >= 2:
        return math.inf
    if p > 0.0:
        return _elliprj_positive(x, y, z, p)
    # sort so that x <= y <= z (R_J is symmetric in its first three arguments)
    if x > y:
        x, y = y, x
    if y > z:
        y, z = z, y
    if x > y:
        x, y = y, x
    q = -p
    # DLMF 19.20.14 with the roles p -> q' (> 0) and q -> -p: (z + q) R_J(p) = (p' - z) R_J(p') - 3 R_F
    #   + 3 sqrt(x y z / (x y + p' q)) R_C(x y + p' q, p' q), where p' = (z (x + y + q) - x y) / (z + q)
    pp = (z * (x + y + q) - x * y) / (z + q)
    value = (pp - z) * _elliprj_positive(x, y, z, pp) - 3.0 * elliprf(x, y, z)
    value += 3.0 * math.sqrt(x * y * z / (x * y + pp * q)) * elliprc(x * y + pp * q, pp * q)
    return value / (z + q)


@numba.njit(cache=True)
def ellipk_mc(mc: float) -> float:
    """K as a function of the complementary parameter mc = 1 - m: pi / (2 AGM(1, sqrt(mc)))."""
    if mc < 0.0 or mc > 1.0 or math.isnan(mc):
        return math.nan
    if mc == 0.0:
        return math.inf
    a = 1.0
    b = math.sqrt(mc)
    for _ in range(_MAX_ITER):
        if abs(a - b) <= _AGM_TOL * a:
            break
        a, b = 0.5 * (a + b), math.sqrt(a * b)
    return 0.5 * math.pi / (0.5 * (a + b))


@numba.njit(cache=True)
def ellipk(m: float) -> float:
    """Complete elliptic integral of the first kind K(m), 0 <= m <= 1 (inf at m = 1)."""
    if m < 0.0 or m > 1.0 or math.isnan(m):
        return math.nan
    return ellipk_mc(1.0 - m)


@numba.njit(cache=True)
def ellipj_mc_work(u: float, mc: float, work: np.ndarray) -> tuple[float, float, float]:
    """(sn, cn, dn)(u | m) given mc = 1 - m in [0, 1]; Bulirsch 1965 ``sncndn``.

    Descending Gauss transformation: run the AGM of (1, sqrt(mc)) keeping its terms, take
    sin and cos of u times the limit, then climb back up with the Landen recurrences for
    c = cn/sn and dn. mc = 0 gives the limit sn = tanh, cn = dn = sech.
    Accuracy: a few ulp relative to max(1, |u|) (the argument itself carries |u| eps).
    work: scratch of at least ``JACOBI_WORK_SIZE`` floats for the AGM terms (kernels allocate it
    once per call instead of once per evaluation: the allocation costs more than the arithmetic).
    """
    if mc < 0.0 or mc > 1.0 or math.isnan(mc) or math.isnan(u):
        return math.nan, math.nan, math.nan
    if mc == 0.0:
        sech = 1.0 / math.cosh(u)
        return math.tanh(u), sech, sech
    if mc == 1.0:
        return math.sin(u), math.cos(u), 1.0
    a = 1.0
    emc = mc
    c = 1.0
    levels = 0
    # AGM of (1, sqrt(mc)): about log2(ln(1/mc)) + 3 levels, 13 at the smallest double
    for i in range(_JACOBI_LEVELS):
        levels = i + 1
        work[2 * i] = a
        emc = math.sqrt(emc)
        work[2 * i + 1] = emc
        c = 0.5 * (a + emc)
        if abs(a - emc) <= _AGM_TOL * a:
            break
        emc *= a
        a = c
    v = u * c
    sn = math.sin(v)
    cn = math.cos(v)
    dn = 1.0
    if sn != 0.0:
        a = cn / sn
        c *= a
        for ii in range(levels - 1, -1, -1):
            b = work[2 * ii]
            a *= c
            c *= dn
            dn = (work[2 * ii + 1] + a) / (b + a)
            a = c / b
        a = 1.0 / math.sqrt(c * c + 1.0)
        sn = a if sn >= 0.0 else -a
        cn = c * sn
    return sn, cn, dn


# what jacobi_prepare keeps of the AGM of (1, sqrt(mc)): levels, its limit c, then (a_i, sqrt term) pairs
# for at most 14 levels (13 reach the smallest double; one more for safety)
JACOBI_PREPARED_SIZE = 2 + 2 * 14


@numba.njit(cache=True)
def jacobi_prepare(mc: float, prepared: np.ndarray) -> None:
    """Keep the descending AGM of `ellipj_mc_work` for this mc (it depends on mc only) in `prepared`
    (JACOBI_PREPARED_SIZE,), so `ellipj_prepared` evaluates sn, cn, dn at any u without it, bitwise as
    `ellipj_mc_work` does. For mc = 0 or 1 (closed forms) or nan, levels is 0 and mc is kept instead."""
    prepared[0] = 0.0
    prepared[1] = mc
    if not (0.0 < mc < 1.0):
        return
    a = 1.0
    emc = mc
    c = 1.0
    for i in range(_JACOBI_LEVELS):
        if 2 + 2 * i + 1 >= prepared.shape[0]:
            prepared[0] = -1.0  # more levels than kept (not for a double mc): evaluate in full
            return
        prepared[0] = i + 1
        prepared[2 + 2 * i] = a
        emc = math.sqrt(emc)
        prepared[2 + 2 * i + 1] = emc
        c = 0.5 * (a + emc)
        if abs(a - emc) <= _AGM_TOL * a:
            break
        emc *= a
        a = c
    prepared[1] = c


@numba.njit(cache=True)
def ellipj_prepared(u: float, mc: float, prepared: np.ndarray, work: np.ndarray) -> tuple[float, float, float]:
    """(sn, cn, dn)(u | m) with the AGM that `jacobi_prepare(mc)` kept: the ascending half of Bulirsch's
    ``sncndn`` only, bitwise equal to `ellipj_mc_work(u, mc, work)` (work is used only where nothing
    was kept)."""
    if int(prepared[0]) < 0:
        return ellipj_mc_work(u, mc, work)
    return ellipj_kept(u, mc, prepared)


@numba.njit(cache=True)
def ellipj_kept(u: float, mc: float, prepared: np.ndarray) -> tuple[float, float, float]:
    """`ellipj_prepared` without a work array: the closed forms where jacobi_prepare kept no levels
    (mc = 0 or 1; nan or out of range: nan), nan where it could not keep them all (levels -1: not for a
    float64 mc, whose AGM stops within 12 levels at _AGM_TOL; tested)."""
    levels = int(prepared[0])
    if levels <= 0 or math.isnan(u):
        if levels < 0 or math.isnan(u) or not (0.0 <= mc <= 1.0):
            return math.nan, math.nan, math.nan
        if mc == 0.0:
            sech = 1.0 / math.cosh(u)
            return math.tanh(u), sech, sech
        return math.sin(u), math.cos(u), 1.0  # mc == 1 (jacobi_prepare keeps levels for 0 < mc < 1)
    c = prepared[1]
    v = u * c
    sn = math.sin(v)
    cn = math.cos(v)
    dn = 1.0
    if sn != 0.0:
        a = cn / sn
        c *= a
        for ii in range(levels - 1, -1, -1):
            b = prepared[2 + 2 * ii]
            a *= c
            c *= dn
            dn = (prepared[2 + 2 * ii + 1] + a) / (b + a)
            a = c / b
        a = 1.0 / math.sqrt(c * c + 1.0)
        sn = a if sn >= 0.0 else -a
        cn = c * sn
    return sn, cn, dn


@numba.njit(cache=True)
def ellipj_mc(u: float, mc: float) -> tuple[float, float, float]:
    """(sn, cn, dn)(u | m) given the complementary parameter mc = 1 - m in [0, 1] (see ellipj_mc_work)."""
    return ellipj_mc_work(u, mc, np.empty(JACOBI_WORK_SIZE))


@numba.njit(cache=True)
def _amplitude_from(u: float, sn: float, cn: float, k_complete: float) -> float:
    """am(u) from sn, cn and K: the continuous branch of atan2(sn, cn).

    am(u) = j pi + r with r = atan(sn / cn) in [-pi/2, pi/2]; |am(u) - pi u / (2K)| < pi/2 for all
    u (am is pi u/(2K) plus a 2K-periodic odd wiggle), so j = round((pi u/(2K) - r) / pi) is exact
    and consistent with the sign of r even where cn ~ 0 (u ~ (2j+1) K).
    """
    r = math.atan2(sn if cn >= 0.0 else -sn, abs(cn))
    if math.isinf(k_complete):
        return r
    j = round((0.5 * math.pi * u / k_complete - r) / math.pi)
    return j * math.pi + r


@numba.njit(cache=True)
def ellipj(u: float, m: float) -> tuple[float, float, float, float]:
    """(sn, cn, dn, am)(u | m) for 0 <= m <= 1, like ``scipy.special.ellipj``.

    m = 1: (tanh u, sech u, sech u, gd u); m = 0: (sin u, cos u, 1, u).
    """
    if m < 0.0 or m > 1.0 or math.isnan(m) or math.isnan(u):
        return math.nan, math.nan, math.nan, math.nan
    if m == 0.0:
        return math.sin(u), math.cos(u), 1.0, u
    mc = 1.0 - m
    sn, cn, dn = ellipj_mc(u, mc)
    return sn, cn, dn, _amplitude_from(u, sn, cn, ellipk_mc(mc))


@numba.njit(cache=True)
def _ellipf_sc(s: float, c: float, mc: float) -> float:
    """F(phi|m) for |phi| <= pi/2 given s = sin(phi), c = cos(phi) >= 0 (DLMF 19.25.5).

    F = s R_F(c^2, c^2 + mc s^2, 1); 1 - m s^2 is written as c^2 + mc s^2 (no cancellation as m -> 1).
    """
    c2 = c * c
    return s * elliprf(c2, c2 + mc * s * s, 1.0)


@numba.njit(cache=True)
def ellippi_sc(n: float, s: float, c: float, mc: float) -> float:
    """Pi(n; phi|m) for |phi| <= pi/2 given s = sin(phi), c = cos(phi) >= 0 and mc = 1 - m.

    DLMF 19.25.14: Pi = s R_F(c^2, D, 1) + (n/3) s^3 R_J(c^2, D, 1, 1 - n s^2), D = c^2 + mc s^2.
    Taking sin and cos (not phi) keeps c^2 relatively accurate where phi -> pi/2.
    For n < -1 the two terms are O(1) with opposite signs while Pi = O(|n|^(-1/2)), so instead
    (DLMF 19.7.9, the n -> m/n transformation, with R_C in closed form since its two arguments
    differ by exactly s^2 (1 - n)(1 - m/n)):
        Pi(n) = -(m/(3n)) s^3 R_J(c^2, D, 1, 1 - (m/n) s^2) + atan2(s w, c sqrt(D)) / w,
        w = sqrt((1 - n)(1 - m/n)).
    """
    c2 = c * c
    s2 = s * s
    d = c2 + mc * s2
    if n < -1.0:
        m_over_n = (1.0 - mc) / n
        w = math.sqrt((1.0 - n) * (1.0 - m_over_n))
        value = math.atan2(s * w, c * math.sqrt(d)) / w
        if m_over_n != 0.0 and s != 0.0:
            value -= m_over_n / 3.0 * s * s2 * elliprj(c2, d, 1.0, 1.0 - m_over_n * s2)
        return value
    if n == 0.0 or s == 0.0:
        return s * elliprf(c2, d, 1.0)
    p = 1.0 - n * s2
    if p > 0.0 and c2 >= 0.0 and (c2 != 0.0 or d != 0.0) and not math.isnan(p + d):
        rf, rj = _elliprf_rj(c2, d, 1.0, p)  # one duplication loop for both
        return s * rf + n / 3.0 * s * s2 * rj
    return s * elliprf(c2, d, 1.0) + n / 3.0 * s * s2 * elliprj(c2, d, 1.0, p)


@numba.njit(cache=True)
def ellippi_complete_mc(n: float, mc: float) -> float:
    """Complete Pi(n|m) = Pi(n; pi/2|m) for n < 1, given mc = 1 - m (inf for mc = 0)."""
    return ellippi_sc(n, 1.0, 0.0, mc)


@numba.njit(cache=True)
def _reduce_amplitude(phi: float) -> tuple[float, float, float]:
    """phi = j pi + r with |r| <= pi/2: returns (j, sin r, cos r), cos r >= 0."""
    j = round(phi / math.pi)
    r = phi - j * math.pi
    return j, math.sin(r), math.cos(r)


@numba.njit(cache=True)
def ellipf(phi: float, m: float) -> float:
    """Incomplete integral of the first kind F(phi|m), any real phi, 0 <= m <= 1.

    Quasi-periodic: F(phi + j pi|m) = F(phi|m) + 2 j K(m) (DLMF 19.2.10).
    """
    if m < 0.0 or m > 1.0 or math.isnan(m) or math.isnan(phi):
        return math.nan
    mc = 1.0 - m
    j, s, c = _reduce_amplitude(phi)
    value = _ellipf_sc(s, c, mc)
    if j != 0.0:
        value += 2.0 * j * ellipk_mc(mc)
    return value


@numba.njit(cache=True)
def ellippi(n: float, phi: float, m: float) -> float:
    """Incomplete integral of the third kind Pi(n; phi|m) (DLMF 19.2.7 convention, n as in 1 - n sin^2).

    Any real phi for n < 1 via Pi(n; phi + j pi|m) = Pi(n; phi|m) + 2 j Pi(n|m) (DLMF 19.6 / 19.2.10);
    for n >= 1 only |phi| <= pi/2 (principal value beyond the pole sin^2 phi = 1/n), else nan.
    """
    if m < 0.0 or m > 1.0 or math.isnan(m + n + phi):
        return math.nan
    mc = 1.0 - m
    j, s, c = _reduce_amplitude(phi)
    if j != 0.0 and n >= 1.0:
        return math.nan
    if n * s * s == 1.0:
        return math.inf if s > 0.0 else -math.inf
    value = ellippi_sc(n, s, c, mc)
    if j != 0.0:
        value += 2.0 * j * ellippi_complete_mc(n, mc)
    return value
