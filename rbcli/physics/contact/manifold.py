"""The contact manifold a pair of primitives writes (primitives.py, primitive_boxes.py): its arrays, and
the pieces every primitive kernel shares (writing a point, closest points of two segments, small
selections).

A manifold is up to MANIFOLD_POINTS contact points between shapes a and b, row i of each array:
    point   [m] (MANIFOLD_ROWS, 3), world: halfway between the two surfaces
    normal  (MANIFOLD_ROWS, 3), world, unit, from b to a (law.py's convention: a is the owner)
    depth   [m] (MANIFOLD_ROWS,): the overlap along the normal, > 0
    feature int64 (MANIFOLD_ROWS,): which features of a and b made the point (each kernel's docstring),
            distinct within a manifold and the same while the contact persists, so the tangential
            spring of a point can be carried from step to step (the friction history per manifold point)
Each point is the contact of one pair of surface points: b's s_b and a's s_a = s_b - depth n, the point
s_b - depth / 2 n (search.py's sphere contact is the same rule: p_j + (r_j - d / 2) n). The caller gives
MANIFOLD_ROWS rows: box-box gathers up to 8 candidate points before it keeps 4.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.step import STEP_KERNEL

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources

# the primitive kernels are step kernels (step.py: no reference counting of the arrays passed, IEEE
# division); their small helpers are inlined into them
INLINE_KERNEL: dict[str, Any] = {**STEP_KERNEL, "inline": "always"}

MANIFOLD_POINTS = 4
MANIFOLD_ROWS = 8

# 1 - (u_a . u_b)^2 below this: the two segments are parallel to rounding (their closest points are not
# unique; Ericson's rule then starts from a's first end)
PARALLEL_SINE2 = 1e-12


class Manifold(NamedTuple):
    """The caller's arrays a primitive kernel writes its points into (module docstring); `make_manifold`."""

    point: np.ndarray
    normal: np.ndarray
    depth: np.ndarray
    feature: np.ndarray


def make_manifold() -> Manifold:
    """Zeroed arrays of MANIFOLD_ROWS rows (allocate once, outside the kernels)."""
    rows = MANIFOLD_ROWS
    return Manifold(np.zeros((rows, 3)), np.zeros((rows, 3)), np.zeros(rows), np.zeros(rows, dtype=np.int64))


@numba.njit(**INLINE_KERNEL)
def emit(out, count, b0, b1, b2, n0, n1, n2, depth, feature) -> int:  # noqa: ANN001
    """Row `count` of `out`: b's surface point s_b, normal n (b to a), depth d and feature; the point is
    s_b - d / 2 n. Returns count + 1."""
    half = 0.5 * depth
    out.point[count, 0], out.point[count, 1], out.point[count, 2] = b0 - half * n0, b1 - half * n1, b2 - half * n2
    out.normal[count, 0], out.normal[count, 1], out.normal[count, 2] = n0, n1, n2
    out.depth[count] = depth
    out.feature[count] = feature
    return count + 1


@numba.njit(**INLINE_KERNEL)
def clamp(x, lo, hi):  # noqa: ANN001, ANN201
    return lo if x < lo else (hi if x > hi else x)


@numba.njit(**INLINE_KERNEL)
def segment_closest(r0, r1, r2, u0, u1, u2, ha, v0, v1, v2, hb):  # noqa: ANN001, ANN201
    """(s, t) minimising |r + s u - t v| over |s| <= ha, |t| <= hb: the closest points c_a + s u and
    c_b + t v of two segments with centres r = c_a - c_b apart, unit directions u, v and half-lengths ha,
    hb (Ericson, Real-Time Collision Detection 5.1.9: the lines' closest s clamped, t from it, and where t
    clamps, s again from the clamped t; exact for this convex quadratic over a rectangle). Parallel (1 -
    (u.v)^2 < PARALLEL_SINE2): s starts at -ha, so the pair is at an end of the segments' overlap."""
    b = u0 * v0 + u1 * v1 + u2 * v2
    c = u0 * r0 + u1 * r1 + u2 * r2
    f = v0 * r0 + v1 * r1 + v2 * r2
    denom = 1.0 - b * b
    s = clamp((b * f - c) / denom, -ha, ha) if denom > PARALLEL_SINE2 else -ha
    t = f + b * s
    if t < -hb:
        t = -hb
        s = clamp(b * t - c, -ha, ha)
    elif t > hb:
        t = hb
        s = clamp(b * t - c, -ha, ha)
    return s, t


@numba.njit(**INLINE_KERNEL)
def round_contact(out, count, a0, a1, a2, ra, b0, b1, b2, rb, f0, f1, f2, feature) -> int:  # noqa: ANN001
    """Sphere a (centre a, radius ra) against sphere b: the point of a sphere-sphere contact (also the
    contact of any two points of swept shapes, capsule cores) written at row `count` if they overlap;
    coincident centres take the fallback normal f. Returns the new count."""
    d0, d1, d2 = a0 - b0, a1 - b1, a2 - b2
    dist = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    depth = ra + rb - dist
    if depth <= 0.0:
        return count
    if dist > 0.0:
        n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist
    else:
        n0, n1, n2 = f0, f1, f2
    return emit(out, count, b0 + rb * n0, b1 + rb * n1, b2 + rb * n2, n0, n1, n2, depth, feature)


@numba.njit(**INLINE_KERNEL)
def sign_of(x):  # noqa: ANN001, ANN201
    """+1.0 for x >= 0, else -1.0."""
    return 1.0 if x >= 0.0 else -1.0


@numba.njit(**INLINE_KERNEL)
def pick3(t, m):  # noqa: ANN001, ANN201
    """t[m] of a 3-tuple: selects, which compile far faster than numba's indexing of a tuple by a variable."""
    return t[0] if m == 0 else (t[1] if m == 1 else t[2])
