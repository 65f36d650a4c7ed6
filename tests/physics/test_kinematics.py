"""The small-angle cos/sin of split2's turns agrees with libm to about an ulp."""

import math

import numpy as np

from rbcli.physics.integrators.kinematics import small_angle_cos_sin


def test_small_angle_cos_sin_matches_libm_within_two_ulp():
    angles = np.concatenate([np.linspace(-0.07, 0.07, 20001), np.random.default_rng(0).uniform(-0.0625, 0.0625, 20000),
                             [0.0, 1e-300, -1e-12, 0.0625, -0.0625, 0.5, 3.0]])  # fmt: skip
    for a in angles:
        c, s = small_angle_cos_sin(a)
        assert abs(c - math.cos(a)) <= 2 * math.ulp(math.cos(a)), a
        assert abs(s - math.sin(a)) <= 2 * math.ulp(math.sin(a)) + 1e-320, a
