"""The .rrd sink's display radius of a big particle cloud takes bounded memory. Found by
benchmarks/large_scenes.py: `rbsim run` of one 10^6-particle body to .rrd peaked at 16 GB, from one
(512, n, 3) array of distances (docs/robustness.md, Long and large)."""

from __future__ import annotations

import tracemalloc

import numpy as np

from rbcli.record.rerun_sink import particle_display_radius


def reference_radius(pts: np.ndarray, fallback: float) -> float:
    """The formula in one array: half the median distance from 512 probes to their nearest other particle."""
    probe = pts[np.linspace(0, len(pts) - 1, min(len(pts), 512)).astype(int)]
    d2 = ((probe[:, None, :] - pts[None, :, :]) ** 2).sum(axis=-1)
    d2[d2 == 0.0] = np.inf
    return float(0.5 * np.median(np.sqrt(d2.min(axis=1))))


def test_blocked_distances_give_the_same_radius():
    rng = np.random.default_rng(3)
    for n in (2, 7, 513, 2048, 2049, 5000):
        pts = rng.normal(size=(n, 3))
        assert particle_display_radius(pts, 0.1) == reference_radius(pts, 0.1)  # the same sums: bitwise


def test_memory_of_a_big_cloud_is_bounded():
    """50,000 particles: one (512, n, 3) array of differences was 614 MB (plus 205 MB of squared
    distances); blocks of 2,048 particles need ~35 MB, so 100 MB is a bound that the old code fails."""
    side = np.arange(37) * 0.01
    pts = np.stack(np.meshgrid(side, side, side, indexing="ij"), axis=-1).reshape(-1, 3)  # 50,653 points
    tracemalloc.start()
    try:
        radius = particle_display_radius(pts, 0.1)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert abs(radius - 0.005) < 1e-15  # half the lattice spacing (0.01 m, up to round-off)
    assert peak < 100 * 2**20, f"{peak / 2**20:.0f} MiB"
