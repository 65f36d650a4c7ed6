"""The cheap tests in front of the contact kernels (physics/contact/primitive_search.py, narrow.py): each
may only skip work whose result is known, so each is checked against the code it stands in front of.

- `_sphere_may_touch` (a cloud's sphere against a primitive) and `_bounds_meet` (two primitives' bounding
  spheres) are never False where primitives.primitive_pair finds a contact, and are False where the
  shapes are clearly apart (else they would skip nothing);
- narrow._cell_box (the sphere grid's box from the extremes of the positions) is broad_phase.grid_box's
  grid tuple, NaN, infinite and huge coordinates included;
- narrow._sort orders the found pairs by their two keys, on both of its paths (insertion, radix).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import pytest

from rbcli.physics.contact.broad_phase import grid_box
from rbcli.physics.contact.manifold import make_manifold
from rbcli.physics.contact.narrow import _INSERTION_SORT, _cell_box, _sort
from rbcli.physics.contact.primitive_search import _bounds_meet, _sphere_may_touch
from rbcli.physics.contact.primitives import PRIMITIVE_BOX, PRIMITIVE_CAPSULE, PRIMITIVE_SPHERE, primitive_pair
from tests.physics.test_contact_primitives import random_shape

KINDS = (PRIMITIVE_SPHERE, PRIMITIVE_CAPSULE, PRIMITIVE_BOX)


def _shape(rng: np.random.Generator, kind: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A primitive of random size and rotation at the origin: (centre, R, size)."""
    shape = random_shape(rng, kind)
    return shape.c, shape.R, shape.size


def _touches(kind_a, ca, Ra, sa, kind_b, cb, Rb, sb) -> bool:  # noqa: ANN001
    return primitive_pair(kind_a, ca, Ra, sa, kind_b, cb, Rb, sb, make_manifold()) > 0


def _distance_scan(direction: np.ndarray, touch) -> float:  # noqa: ANN001
    """The distance along `direction` at which `touch(d)` turns False (bisection to rounding)."""
    lo, hi = 0.0, 10.0
    assert touch(lo * direction) and not touch(hi * direction)
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if touch(mid * direction):
            lo = mid
        else:
            hi = mid
    return hi


@pytest.mark.parametrize("kind", KINDS)
def test_a_sphere_is_kept_wherever_the_kernel_finds_its_contact(kind):
    rng = np.random.default_rng(kind)
    skipped = 0
    for _ in range(150):
        c, R, size = _shape(rng, kind)
        r = rng.uniform(0.005, 0.05)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        sphere = np.array([r, 0.0, 0.0])

        def kernel(d, c=c, R=R, size=size, r=r, sphere=sphere) -> bool:  # noqa: ANN001
            return _touches(PRIMITIVE_SPHERE, d, np.eye(3), sphere, kind, c, R, size)

        edge = _distance_scan(direction, kernel)  # the kernel's last contact along the ray
        # at the edge (both sides, to rounding) and inside: wherever the kernel touches, the pre-test does
        for scale in (0.0, 0.5, 0.999, 1.0 - 1e-12, 1.0, 1.0 + 1e-12):
            p = scale * edge * direction
            if kernel(p):
                assert _sphere_may_touch(kind, p[0], p[1], p[2], r, c, R, size)
        # clearly apart: skipped
        p = (edge + 1e-4) * direction
        assert not kernel(p)
        skipped += not _sphere_may_touch(kind, p[0], p[1], p[2], r, c, R, size)
    assert skipped == 150


@pytest.mark.parametrize("kind_a", KINDS)
@pytest.mark.parametrize("kind_b", KINDS)
def test_primitives_are_kept_wherever_the_kernel_finds_their_contact(kind_a, kind_b):
    rng = np.random.default_rng(10 * kind_a + kind_b)
    for _ in range(60):
        ca, Ra, sa = _shape(rng, kind_a)
        _, Rb, sb = _shape(rng, kind_b)
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)

        def kernel(d, ca=ca, Ra=Ra, sa=sa, Rb=Rb, sb=sb) -> bool:  # noqa: ANN001
            return _touches(kind_a, ca, Ra, sa, kind_b, d, Rb, sb)

        edge = _distance_scan(direction, kernel)
        for scale in (0.0, 0.5, 1.0 - 1e-12, 1.0, 1.0 + 1e-12):
            cb = scale * edge * direction
            if kernel(cb):
                assert _bounds_meet(kind_a, ca, sa, kind_b, cb, sb)
    # two spheres of radius 0.1 centres 0.2 + 1e-4 apart: their bounds do not meet
    small = np.array([0.1, 0.0, 0.0])
    assert not _bounds_meet(PRIMITIVE_SPHERE, np.zeros(3), small, PRIMITIVE_SPHERE, np.array([0.2001, 0, 0]), small)


class _Grid(NamedTuple):
    cell_size: float
    bucket_count: int


class _Spheres(NamedTuple):
    sphere_position: np.ndarray
    active_sphere: np.ndarray
    sphere_cell: np.ndarray


@pytest.mark.parametrize("case", ["dense", "spread", "nan", "inf", "huge", "one"])
def test_the_cell_box_from_the_extremes_is_the_grid_box(case):
    rng = np.random.default_rng(len(case))
    n = 1 if case == "one" else 300
    pos = rng.uniform(-0.5, 0.5, (n + 20, 3)) + np.array([3.0, -7.0, 0.25])
    if case == "spread":
        pos *= 1e4
    bad = {"nan": np.nan, "inf": np.inf, "huge": 3e19}.get(case)
    if bad is not None:  # some coordinates beyond the cells' range, on either side
        pos[5, 1], pos[17, 0], pos[40, 2] = bad, -bad, bad
    active = np.sort(rng.choice(n + 20, n, replace=False)).astype(np.int64)
    if bad is not None:
        active[:3] = [5, 17, 40]
    grid = _Grid(0.02, 4096)
    spheres = _Spheres(pos, active, np.zeros((n + 20, 3), dtype=np.int64))
    for hashed in (False, True):
        assert _cell_box(grid, spheres, n, hashed) == grid_box(grid, spheres, n, hashed)


class _Pairs(NamedTuple):
    pair_found: np.ndarray
    pair_key: np.ndarray
    pair_order: np.ndarray
    pair_radix: np.ndarray


@pytest.mark.parametrize("n", [0, 1, 2, 7, _INSERTION_SORT, _INSERTION_SORT + 1, 700])
def test_the_found_pairs_are_sorted_by_both_keys(n):
    rng = np.random.default_rng(n)
    # unique pairs of keys with many repeats of the first (a walker's several partners), keys up to 2^40
    first = rng.integers(0, 2**40, max(n // 3, 1))[rng.integers(0, max(n // 3, 1), n)]
    second = rng.permutation(np.arange(n, dtype=np.int64) * 7919 + rng.integers(0, 7919))
    keys = np.stack([first, second], axis=1).astype(np.int64)
    found = rng.integers(0, 10**6, (n, 2)).astype(np.int64)
    order_scratch, radix = np.zeros((2, max(n, 1)), dtype=np.int64), np.zeros((1 << 11) + 1, dtype=np.int64)
    work = _Pairs(found.copy(), keys.copy(), order_scratch, radix)
    _sort(work, n)
    order = np.lexsort((keys[:, 1], keys[:, 0]))
    np.testing.assert_array_equal(work.pair_found[:n], found[order])
