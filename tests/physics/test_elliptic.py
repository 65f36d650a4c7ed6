"""Compiled elliptic functions (rbcli.physics.elliptic) against scipy.special, mpmath values and identities.

Tolerances are in units of EPS = 2.2e-16 and say where the size comes from: the functions are
well conditioned in their parameters except the Jacobi functions in their argument u (an input u
already carries |u| EPS, so sn, cn, dn can only be right to about EPS (1 + |u|) absolutely).
scipy is the reference wherever it is itself accurate; where it is not (Cephes ellpj for
m > 1 - 1e-10 and |u| > ~5, elliprj for p << x, y, z) the references are 22-digit mpmath values.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.special as sp
from scipy.integrate import quad

from rbcli.physics import elliptic as E

EPS = np.finfo(float).eps
RNG = np.random.default_rng(20240611)


def _vec(f, *args):
    return np.array([f(*a) for a in zip(*args, strict=True)])


def _parameters(n: int) -> np.ndarray:
    """m in [0, 1]: uniform, near 0 (down to 1e-16) and near 1 (down to 1 - 1e-15)."""
    return np.concatenate(
        [
            RNG.uniform(0.0, 1.0, n),
            10.0 ** RNG.uniform(-16, -1, n // 2),
            1.0 - 10.0 ** RNG.uniform(-15, -1, n // 2),
            [0.0, 1.0, 0.5, 1.0 - 1e-12],
        ]
    )


def test_ellipk_matches_scipy_including_m_near_1():
    # K(m) = pi / (2 AGM(1, sqrt(1 - m))); well conditioned in mc, and 1 - m is exact for m > 1/2,
    # so a few ulp relative (scipy's Cephes polynomial is itself good to ~1 ulp)
    m = _parameters(400)[:-3]  # m = 1 (inf) separately
    got = _vec(E.ellipk, m)
    assert np.max(np.abs(got / sp.ellipk(m) - 1.0)) < 8 * EPS
    assert E.ellipk(1.0) == math.inf and E.ellipk(0.0) == pytest.approx(math.pi / 2, rel=EPS)
    assert math.isnan(E.ellipk(-0.1)) and math.isnan(E.ellipk(1.1))


def test_carlson_rf_rc_rj_match_scipy():
    # duplication algorithms truncated at relative size ~1e-16 (Carlson 1995 error bound r/4):
    # R_F, R_C within a few ulp; R_J adds the sum of R_C terms, 1e-14 as the task asks
    x, y, z, p = (10.0 ** RNG.uniform(-6, 6, 1500) for _ in range(4))
    rel = np.abs(_vec(E.elliprf, x, y, z) / sp.elliprf(x, y, z) - 1.0)
    assert rel.max() < 8 * EPS
    rel = np.abs(_vec(E.elliprf, np.zeros_like(y), y, z) / sp.elliprf(0.0, y, z) - 1.0)
    assert rel.max() < 8 * EPS
    rel = np.abs(_vec(E.elliprc, x, y) / sp.elliprc(x, y) - 1.0)
    assert rel.max() < 8 * EPS
    rel = np.abs(_vec(E.elliprc, x, -y) / sp.elliprc(x, -y) - 1.0)  # Cauchy principal value
    assert rel.max() < 16 * EPS
    # p not far below min(x, y, z): scipy's own R_J loses up to 3e-14 for p << x, y, z (see below)
    lo, hi = np.log10(np.minimum(np.minimum(x, y), z)), np.log10(np.maximum(np.maximum(x, y), z))
    pp = 10.0 ** RNG.uniform(lo - 0.5, hi + 1.0)
    rel = np.abs(_vec(E.elliprj, x, y, z, pp) / sp.elliprj(x, y, z, pp) - 1.0)
    assert rel.max() < 1e-14
    # p < 0, Cauchy principal value (Carlson 1995 eq. 2.22): terms of both signs cancel near the pole,
    # so both implementations lose digits in the same places (mpmath spot checks: ours within 1.1e-13
    # where scipy is 2.7e-13 off); not used by the physics
    rel = np.abs(_vec(E.elliprj, x, y, z, -pp) / sp.elliprj(x, y, z, -pp) - 1.0)
    assert rel.max() < 1e-12
    assert E.elliprf(0.0, 0.0, 1.0) == math.inf and E.elliprj(0.0, 0.0, 1.0, 1.0) == math.inf


@pytest.mark.parametrize(
    "x, y, z, p, ref",
    [  # 40-digit mpmath elliprj; scipy 1.17 is off by 2e-14 .. 6e-14 relative on all but the second
        (80.56812497358926, 291.1219041096674, 41.96326586505432, 6.870807986197465e-08, 0.03069187416491295430204),
        (1e-6, 2.0, 3e5, 1e-9, 16.06568797416688914429),
        (0.08590379023727103, 1.465815217730621, 49.43113136226954, 1.1716605086588671e-07, 8.6820067982299710517),
        (0.9451698556724233, 2.5031157755427293, 0.004436521699827964, 4.816935874690781e-09, 218.87743362778602457),
        (2035.8334861217738, 92259.16838857859, 150.317071088841, 0.00021529394330034512, 0.00012807180705563044511),
        (13787.17406722282, 5828.0694702607625, 19.396670204298648, 2.7578990898642943e-05, 0.00055864951672549766092),
    ],
)
def test_carlson_rj_small_p_against_mpmath(x, y, z, p, ref):
    # p << x, y, z drives e_m -> -1 in R_C(1, 1 + e_m); 1 + e_m is formed as 2 sqrt(p)(p + lambda)/d_m
    # (no cancellation), so the result stays within a few ulp
    assert E.elliprj(x, y, z, p) == pytest.approx(ref, rel=4 * EPS)


def test_jacobi_functions_match_scipy_where_scipy_is_accurate():
    # |error| <= c EPS (1 + |u|): the ulp of u itself moves sn by up to |u| EPS |cn dn|
    m = _parameters(600)
    u = RNG.uniform(-60.0, 60.0, m.size)
    # Cephes ellpj uses a first-order series in 1 - m above 1 - 1e-10, good only for small |u|, and
    # its AGM/arcsin path loses ~30 ulp in dn for 1e-10 < 1 - m < 1e-6 (mpmath cases below); so
    # scipy is the reference for 1 - m >= 1e-6 at any u, and for 1 - m < 1e-10 at |u| <= 3
    series = m > 1.0 - 1e-10
    u[series] = RNG.uniform(-3.0, 3.0, series.sum())
    keep = series | (m <= 1.0 - 1e-6)
    got = _vec(E.ellipj, u[keep], m[keep])
    ref = np.array(sp.ellipj(u[keep], m[keep])).T
    scale = EPS * (1.0 + np.abs(u[keep]))
    for k in range(4):  # sn, cn, dn, am
        assert np.max(np.abs(got[:, k] - ref[:, k]) / scale) < 8.0, ("sn", "cn", "dn", "am")[k]


@pytest.mark.parametrize(
    "u, m, sn, cn, dn",
    [  # 40-digit mpmath ellipfun, m as the exact double shown
        (40.3, 0.999999999999, -0.9999999949285455884638, -0.0001007120092012506697996, 0.0001007169736202440545254),
        (-57.9, 0.999999999999, 0.9940499764767628020707, 0.1089249478611182070119, 0.1089249478656539608307),
        (25.0, 0.999999999999999, 0.9999999999595594622978, -8.993390651075897882956e-6, 8.993446202851354369549e-6),
        (13.7, 0.9999999, 0.9999380173684249749778, -0.01113379635629433807797, 0.01113828572569577781222),
        (
            -31.0707250419087,
            0.9999999845161882,
            0.9999999999688743673742,
            -7.889947100618784625964e-6,
            0.0001246838524131041494,
        ),  # fmt: skip
        (
            5.944336302354202,
            0.999999996298993,
            0.9999862655000151590046,
            0.005241069674521810558968,
            0.005241422730373429013996,
        ),  # fmt: skip
        (60.1, 0.5, 0.6714401027960751739626, 0.741058829214790479414, 0.8801045927494061212195),
    ],
)
def test_jacobi_functions_near_m_1_against_mpmath(u, m, sn, cn, dn):
    # the region scipy gets wrong (m > 1 - 1e-10, |u| > 5: its series gives |cn| ~ 1e8; and
    # 3.7e-15 / 2e-13 off in cn / dn on the two cases near 1 - 1e-8); absolute bound EPS (1 + |u|)
    got = E.ellipj(u, m)
    for value, ref in zip(got[:3], (sn, cn, dn), strict=True):
        assert abs(value - ref) < 4 * EPS * (1.0 + abs(u))


def test_jacobi_identities_and_inverse():
    # sn^2 + cn^2 = 1 and dn^2 + m sn^2 = 1 (DLMF 22.6.1) to rounding; F(am(u)|m) = u (am inverts F):
    # dF/dphi = 1/dn, so the check is scaled by the amplitude's ulp over dn
    m = _parameters(400)
    u = RNG.uniform(-60.0, 60.0, m.size)
    sn, cn, dn, am = _vec(E.ellipj, u, m).T
    assert np.max(np.abs(sn * sn + cn * cn - 1.0)) < 4 * EPS
    assert np.max(np.abs(dn * dn + m * sn * sn - 1.0)) < 4 * EPS
    finite = m < 1.0
    back = _vec(E.ellipf, am[finite], m[finite])
    err = np.abs(back - u[finite]) / (EPS * (1.0 + np.abs(u[finite])) * (1.0 + 1.0 / dn[finite]))
    assert err.max() < 16.0


def test_jacobi_limits_m_0_and_m_1_are_exact_forms():
    for u in (-30.0, -1.5, 0.0, 0.3, 7.0, 40.0):
        assert E.ellipj(u, 0.0) == (math.sin(u), math.cos(u), 1.0, u)
        sn, cn, dn, am = E.ellipj(u, 1.0)
        sech = 1.0 / math.cosh(u)
        assert (sn, cn, dn) == (math.tanh(u), sech, sech)
        assert am == pytest.approx(math.atan(math.sinh(u)), abs=2 * EPS)  # Gudermannian


def test_ellipf_matches_scipy_beyond_half_pi():
    # F(phi + j pi) = F(phi) + 2 j K; relative error a few ulp of the result plus phi's own ulp / dn
    m = _parameters(300)[:-3]
    phi = RNG.uniform(-20.0, 20.0, m.size)
    got = _vec(E.ellipf, phi, m)
    ref = sp.ellipkinc(phi, m)
    assert np.max(np.abs(got - ref) / (np.abs(ref) * 16 * EPS + EPS * np.abs(phi) / np.sqrt(1.0 - m))) < 1.0


def _pi_by_quadrature(n: float, phi: float, m: float) -> float:
    """Pi(n; phi|m) straight from its definition (adaptive quadrature, independent of Carlson)."""
    value, _ = quad(lambda t: 1.0 / ((1.0 - n * math.sin(t) ** 2) * math.sqrt(1.0 - m * math.sin(t) ** 2)),
                    0.0, phi, epsabs=0.0, epsrel=2e-14, limit=400)  # fmt: skip
    return value


def test_ellippi_against_quadrature_of_the_definition():
    # smooth integrands (|phi| <= 3, m <= 0.99, n in [-50, 0.9]): quad reaches ~1e-14 relative
    for _ in range(60):
        n = RNG.choice([RNG.uniform(-50.0, -1.0), RNG.uniform(-1.0, 0.9)])
        phi = RNG.uniform(-3.0, 3.0)
        m = RNG.uniform(0.0, 0.99)
        assert E.ellippi(n, phi, m) == pytest.approx(_pi_by_quadrature(n, phi, m), rel=2e-14, abs=1e-15)


@pytest.mark.parametrize(
    "n, phi, m, ref",
    [  # 40-digit mpmath ellippi
        (-5e8, 0.3, 0.24, 0.00007024175415300927092888),  # Carlson terms cancel by sqrt(5e8): DLMF 19.7.9 path
        (-3.0, 7.5, 0.999999, 10.97939340487904043623),  # beyond pi/2, near m = 1
        (0.9, 0.8, 0.5, 1.058058509195634182797),
        (-0.5, 20.0, 0.9999999999, 107.9756194444893169658),
        (-1000.0, -11.0, 0.999999999999, -0.4557582310837686988989),
    ],
)
def test_ellippi_against_mpmath(n, phi, m, ref):
    # conditioning in phi: dPi/dphi = 1 / ((1 - n sin^2) dn) times phi's ulp, plus a few ulp
    assert abs(E.ellippi(n, phi, m) - ref) < 8 * EPS * abs(ref) + 2 * EPS * abs(phi) / math.sqrt(1.0 - m)


def test_ellippi_periodicity_and_domain():
    # Pi(n; phi + j pi) = Pi(n; phi) + 2 j Pi(n|m) (DLMF 19.6), continuous through phi = pi/2
    n, m = -2.5, 0.7
    complete = E.ellippi(n, math.pi / 2, m)
    for j in (-3, 1, 4):
        assert E.ellippi(n, 0.4 + j * math.pi, m) == pytest.approx(E.ellippi(n, 0.4, m) + 2 * j * complete, rel=1e-14)
    below, above = E.ellippi(n, math.pi / 2 - 1e-9, m), E.ellippi(n, math.pi / 2 + 1e-9, m)
    assert abs(above - below) < 1e-8
    assert math.isnan(E.ellippi(2.0, 4.0, 0.5))  # n > 1 beyond pi/2: no finite complete integral


def test_prepared_jacobi_functions_are_bitwise_the_full_ones():
    # jacobi_prepare keeps the descending AGM (a function of mc alone): the ascending half then gives
    # the very bits of ellipj_mc_work, for mc from 1e-300 to 1 and the closed-form ends 0 and 1
    rng = np.random.default_rng(8)
    work, prepared = np.empty(E.JACOBI_WORK_SIZE), np.empty(E.JACOBI_PREPARED_SIZE)
    for mc in [0.0, 1.0, 5e-324, 1e-300, 1e-17, *(10.0 ** rng.uniform(-16, 0, 40))]:
        E.jacobi_prepare(mc, prepared)
        assert prepared[0] >= 0  # every level kept, even for the smallest double: ellipj_kept needs no work
        for u in [0.0, *rng.uniform(-3000.0, 3000.0, 20)]:
            full = E.ellipj_mc_work(u, mc, work)
            assert E.ellipj_prepared(u, mc, prepared, work) == full, (mc, u)
            assert E.ellipj_kept(u, mc, prepared) == full, (mc, u)
    E.jacobi_prepare(math.nan, prepared)
    assert all(math.isnan(v) for v in E.ellipj_kept(0.5, math.nan, prepared))
