"""Contact of a box (centre c, rotation R, half extents h: primitives.py's form) with a sphere and a
capsule: compiled kernels writing a manifold (manifold.py; normal from b to a); box-box is box_box.py.
docs/contact.md "Primitive contact".

Separating axes (Gottschalk's OBB test, Ericson 4.4.1): two convex polytopes overlap iff their
projections overlap on every candidate axis, their face normals and the cross products of their edge
directions (box-box: 3 + 3 + 9; segment-box: 3 + 3), and the axis of least overlap is the direction and
depth that part them. An edge axis takes over from the best face axis only where it is clearly
shallower (AXIS_PREFERENCE), as ODE's dBoxBox and Box2D's b2CollidePolygons favour faces: a face gives a
manifold that does not flicker between steps, and an edge axis within a few % of a face axis is the
same contact seen from a corner. Between a's and b's best faces the clearly shallower wins, and in a
near tie the larger face (so a-b and b-a agree).

Compile time: numba compiles a called kernel once per type of its arguments, and a constant argument (a
literal 0) is a type of its own, so calls pass np.int64(0) where a constant would do, and helpers return
the axes they pick (an index that starts as a constant and changes in a loop is typed as that constant
first); a tuple indexed by a variable compiles to a switch per access (manifold.pick3 selects). All
primitive kernels compiled in ~22 s of CPU before these rules, ~10 s after (docs/contact.md).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.contact.manifold import (
    INLINE_KERNEL,
    PARALLEL_SINE2,
    clamp,
    emit,
    pick3,
    segment_closest,
    sign_of,
)
from rbcli.physics.step import STEP_KERNEL

# an edge axis replaces the best face axis (and b's face a's) only if its overlap is below this fraction
# of that axis's
AXIS_PREFERENCE = 0.95
# |axis|^2 of an edge cross product below this: parallel edges, no axis of their own (face axes cover
# them; Ericson 4.4.1)
EDGE_SINE2 = 1e-12
# a separation within this fraction of the shapes' size is touching: decided by the axes, not by closest
# points (whose direction is then rounding noise)
TOUCH_FRACTION = 1e-9


@numba.njit(**INLINE_KERNEL)
def _to_box(R, d0, d1, d2):  # noqa: ANN001, ANN201
    """R^T d: a world vector in the box's frame."""
    return (
        R[0, 0] * d0 + R[1, 0] * d1 + R[2, 0] * d2,
        R[0, 1] * d0 + R[1, 1] * d1 + R[2, 1] * d2,
        R[0, 2] * d0 + R[1, 2] * d1 + R[2, 2] * d2,
    )


@numba.njit(**INLINE_KERNEL)
def _box_point(out, count, c, R, q0, q1, q2, m0, m1, m2, depth, feature) -> int:  # noqa: ANN001
    """emit with b's surface point q and the normal m given in the box's (b's) frame."""
    b0 = c[0] + R[0, 0] * q0 + R[0, 1] * q1 + R[0, 2] * q2
    b1 = c[1] + R[1, 0] * q0 + R[1, 1] * q1 + R[1, 2] * q2
    b2 = c[2] + R[2, 0] * q0 + R[2, 1] * q1 + R[2, 2] * q2
    n0 = R[0, 0] * m0 + R[0, 1] * m1 + R[0, 2] * m2
    n1 = R[1, 0] * m0 + R[1, 1] * m1 + R[1, 2] * m2
    n2 = R[2, 0] * m0 + R[2, 1] * m1 + R[2, 2] * m2
    return emit(out, count, b0, b1, b2, n0, n1, n2, depth, feature)


@numba.njit(**STEP_KERNEL)
def sphere_box(ca, Ra, sa, cb, Rb, sb, out) -> int:  # noqa: ANN001
    """Sphere a against box b, in b's frame: outside, the closest box point q = clamp(p, -h, h) of the
    centre p, d = r - |p - q|, n along p - q; inside (p = q), the nearest face k, d = r + h_k - |p_k|,
    n its normal (Box2D's b2CollidePolygonAndCircle does the same in 2D). Feature 0."""
    r = sa[0]
    p = _to_box(Rb, ca[0] - cb[0], ca[1] - cb[1], ca[2] - cb[2])
    q0, q1, q2 = clamp(p[0], -sb[0], sb[0]), clamp(p[1], -sb[1], sb[1]), clamp(p[2], -sb[2], sb[2])
    e0, e1, e2 = p[0] - q0, p[1] - q1, p[2] - q2
    dist2 = e0 * e0 + e1 * e1 + e2 * e2
    if dist2 > 0.0:
        if dist2 >= r * r:
            return 0
        dist = math.sqrt(dist2)
        return _box_point(out, 0, cb, Rb, q0, q1, q2, e0 / dist, e1 / dist, e2 / dist, r - dist, 0)
    k, inner = 0, sb[0] - abs(p[0])
    for m in range(1, 3):
        if sb[m] - abs(pick3(p, m)) < inner:
            k, inner = m, sb[m] - abs(pick3(p, m))
    side = sign_of(pick3(p, k))
    q0, q1, q2 = (side * sb[0] if k == 0 else q0), (side * sb[1] if k == 1 else q1), (side * sb[2] if k == 2 else q2)
    m0, m1, m2 = (side if k == 0 else 0.0), (side if k == 1 else 0.0), (side if k == 2 else 0.0)
    return _box_point(out, 0, cb, Rb, q0, q1, q2, m0, m1, m2, r + inner, 0)


@numba.njit(**STEP_KERNEL)
def _segment_slope(p, u, h, s):  # noqa: ANN001, ANN201
    """d/ds of |q(s) - clamp(q(s), -h, h)|^2 / 2 at q(s) = p + s u: sum u_m (q_m - clamp(q_m))."""
    q0, q1, q2 = p[0] + s * u[0], p[1] + s * u[1], p[2] + s * u[2]
    return (
        u[0] * (q0 - clamp(q0, -h[0], h[0]))
        + u[1] * (q1 - clamp(q1, -h[1], h[1]))
        + u[2] * (q2 - clamp(q2, -h[2], h[2]))
    )


@numba.njit(**STEP_KERNEL)
def _segment_box_closest(p, u, ha, h):  # noqa: ANN001, ANN201
    """The s in [-ha, ha] minimising the distance from p + s u to the box |x_m| <= h_m (box frame).

    f(s) = |q - clamp(q)|^2 / 2 is convex and piecewise quadratic, with breakpoints where q_m(s) = +-h_m
    (at most 6); its slope f' is continuous, piecewise linear and non-decreasing. So: an end whose slope
    points outward is the answer; else bracket the root of f' between the breakpoints (no sort: each one
    narrows the bracket from the side its slope's sign says) and interpolate linearly: exact."""
    lo, hi = -ha, ha
    g_lo = _segment_slope(p, u, h, lo)
    if g_lo >= 0.0:
        return lo
    g_hi = _segment_slope(p, u, h, hi)
    if g_hi <= 0.0:
        return hi
    for m in range(3):
        pm, um = pick3(p, m), pick3(u, m)
        if um == 0.0:
            continue
        for end in range(2):
            s = ((h[m] if end else -h[m]) - pm) / um
            if lo < s < hi:
                g = _segment_slope(p, u, h, s)
                if g == 0.0:
                    return s
                if g < 0.0:
                    lo, g_lo = s, g
                else:
                    hi, g_hi = s, g
    return lo - g_lo * (hi - lo) / (g_hi - g_lo)


@numba.njit(**STEP_KERNEL)
def _clip_to_slabs(p, u, ha, h, clip0, clip1, clip2):  # noqa: ANN001, ANN201
    """The part [lo, hi] of s in [-ha, ha] where |p_m + s u_m| <= h_m for each axis m flagged clip_m
    (lo > hi: none)."""
    lo, hi = -ha, ha
    for m in range(3):
        pm, um = pick3(p, m), pick3(u, m)
        if not pick3((clip0, clip1, clip2), m):
            continue
        if um == 0.0:
            if abs(pm) > h[m]:
                return ha, -ha
            continue
        s0, s1 = (-h[m] - pm) / um, (h[m] - pm) / um
        lo, hi = max(lo, min(s0, s1)), min(hi, max(s0, s1))
    return lo, hi


@numba.njit(**INLINE_KERNEL)
def _end_feature(s, ha):  # noqa: ANN001, ANN201
    """A capsule-box point's feature: 0 at the end -ha, 1 at +ha, 2 inside the segment."""
    return 0 if s <= -ha else (1 if s >= ha else 2)


@numba.njit(**STEP_KERNEL)
def _capsule_point(out, count, c, R, p, u, s, r, h, feature) -> int:  # noqa: ANN001
    """The segment's point x = p + s u (box frame, outside the box) against the box: its closest box point
    q = clamp(x, -h, h), d = r - |x - q|, n along x - q; written where it overlaps."""
    x0, x1, x2 = p[0] + s * u[0], p[1] + s * u[1], p[2] + s * u[2]
    q0, q1, q2 = clamp(x0, -h[0], h[0]), clamp(x1, -h[1], h[1]), clamp(x2, -h[2], h[2])
    e0, e1, e2 = x0 - q0, x1 - q1, x2 - q2
    dist = math.sqrt(e0 * e0 + e1 * e1 + e2 * e2)
    if dist <= 0.0 or dist >= r:
        return count
    return _box_point(out, count, c, R, q0, q1, q2, e0 / dist, e1 / dist, e2 / dist, r - dist, feature)


@numba.njit(**STEP_KERNEL)
def _capsule_face(out, c, R, p, u, ha, r, h, k, side, fallback) -> int:  # noqa: ANN001
    """A capsule (segment p + s u, |s| <= ha, box frame) over face `side` e_k of the box: the segment
    clipped to the face's slab (|q_m| <= h_m, m != k), a point at each end of it, depth r minus its
    height over the face (its distance to the box there), features 0 (the end towards -ha) and 1; an
    empty or point-like clip: one point at s = fallback (feature `_end_feature`)."""
    lo, hi = _clip_to_slabs(p, u, ha, h, k != 0, k != 1, k != 2)
    if hi - lo <= TOUCH_FRACTION * (ha + h[0] + h[1] + h[2]):
        lo = hi = fallback
    count = 0
    for end in range(2):
        s = lo if end == 0 else hi
        if end == 1 and hi == lo:
            break
        q0, q1, q2 = p[0] + s * u[0], p[1] + s * u[1], p[2] + s * u[2]
        depth = r - (side * pick3((q0, q1, q2), k) - h[k])
        if depth <= 0.0:
            continue
        feature = end if hi > lo else _end_feature(s, ha)
        q0, q1, q2 = clamp(q0, -h[0], h[0]), clamp(q1, -h[1], h[1]), clamp(q2, -h[2], h[2])
        q0, q1, q2 = (side * h[0] if k == 0 else q0), (side * h[1] if k == 1 else q1), (side * h[2] if k == 2 else q2)
        m0, m1, m2 = (side if k == 0 else 0.0), (side if k == 1 else 0.0), (side if k == 2 else 0.0)
        count = _box_point(out, count, c, R, q0, q1, q2, m0, m1, m2, depth, feature)
    return count


@numba.njit(**INLINE_KERNEL)
def _first(flag0, flag1):  # noqa: ANN001, ANN201
    """0, 1 or 2: the first of three flags set, the third taken as set."""
    return 0 if flag0 else (1 if flag1 else 2)


@numba.njit(**STEP_KERNEL)
def _segment_box_axes(p, u, ha, h):  # noqa: ANN001, ANN201
    """(face separation, its axis, edge separation, its axis or -1): the largest separations of segment
    p +- ha u and the box |x_m| <= h_m (box frame) along the box's face normals e_k and along u x e_j."""
    face_sep, face = -math.inf, 0
    for k in range(3):
        sep = abs(pick3(p, k)) - h[k] - ha * abs(pick3(u, k))
        if sep > face_sep:
            face_sep, face = sep, k
    edge_sep, edge = -math.inf, -1
    for j in range(3):
        j1, j2 = (j + 1) % 3, (j + 2) % 3
        p1, p2, u1, u2 = pick3(p, j1), pick3(p, j2), pick3(u, j1), pick3(u, j2)
        length2 = u1 * u1 + u2 * u2  # |u x e_j|^2
        if length2 < EDGE_SINE2:
            continue
        sep = (abs(p1 * u2 - p2 * u1) - h[j1] * abs(u2) - h[j2] * abs(u1)) / math.sqrt(length2)
        if sep > edge_sep:
            edge_sep, edge = sep, j
    return face_sep, face, edge_sep, edge


@numba.njit(**STEP_KERNEL)
def capsule_box(ca, Ra, sa, cb, Rb, sb, out) -> int:  # noqa: ANN001
    """Capsule a (radius r, segment c_a +- ha u) against box b, in b's frame.

    Segment outside the box: its exact closest point to the box (`_segment_box_closest`), d = r -
    distance, n from the box point to it. Where that box point is on a face (the difference along one
    axis), the segment clipped to the face's slab gives a point at each end (a capsule lying on a face:
    both ends, each at its own height); where it is on an edge and the segment runs along that edge,
    the segment clipped to the edge's slab likewise (each end's own closest point). Segment touching or
    inside the box: the separating axis of least overlap (3 faces, u x the 3 edge directions): a face
    gives the clipped points as above, an edge the closest points of the segment and the box's edge
    along it, d = r + overlap. Features 0 and 1 (the points towards -ha and +ha), 2 for one point
    inside the segment."""
    r, ha, h = sa[0], sa[1], sb
    p = _to_box(Rb, ca[0] - cb[0], ca[1] - cb[1], ca[2] - cb[2])
    u = _to_box(Rb, Ra[0, 2], Ra[1, 2], Ra[2, 2])
    face_sep, face, edge_sep, edge = _segment_box_axes(p, u, ha, h)
    if max(face_sep, edge_sep) >= r:
        return 0
    touch = TOUCH_FRACTION * (ha + h[0] + h[1] + h[2])
    if max(face_sep, edge_sep) > touch:  # the segment is outside the box: exact closest points
        s = _segment_box_closest(p, u, ha, h)
        e = (p[0] + s * u[0], p[1] + s * u[1], p[2] + s * u[2])
        e = (e[0] - clamp(e[0], -h[0], h[0]), e[1] - clamp(e[1], -h[1], h[1]), e[2] - clamp(e[2], -h[2], h[2]))
        # the closest box feature: a face along the one axis the difference has (within rounding), an
        # edge along the one it lacks
        free0, free1, free2 = abs(e[0]) <= touch, abs(e[1]) <= touch, abs(e[2]) <= touch
        free = (1 if free0 else 0) + (1 if free1 else 0) + (1 if free2 else 0)
        if free == 2:
            k = _first(not free0, not free1)
            return _capsule_face(out, cb, Rb, p, u, ha, r, h, k, sign_of(pick3(e, k)), s)
        if free == 1:
            j = _first(free0, free1)
            if 1.0 - pick3(u, j) * pick3(u, j) < PARALLEL_SINE2:  # along the edge: its closest points are a segment
                lo, hi = _clip_to_slabs(p, u, ha, h, j == 0, j == 1, j == 2)
                if hi - lo > touch:
                    count = _capsule_point(out, np.int64(0), cb, Rb, p, u, lo, r, h, np.int64(0))
                    return _capsule_point(out, count, cb, Rb, p, u, hi, r, h, np.int64(1))
        return _capsule_point(out, np.int64(0), cb, Rb, p, u, s, r, h, _end_feature(s, ha))
    if edge < 0 or edge_sep <= AXIS_PREFERENCE * face_sep + touch:
        side = sign_of(pick3(p, face))
        deepest = -ha if side * pick3(u, face) > 0.0 else ha  # the segment's point deepest into that face
        return _capsule_face(out, cb, Rb, p, u, ha, r, h, face, side, deepest)
    j = edge
    w = (1.0 if j == 0 else 0.0, 1.0 if j == 1 else 0.0, 1.0 if j == 2 else 0.0)
    L0, L1, L2 = u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]  # u x e_j
    length = math.sqrt(L0 * L0 + L1 * L1 + L2 * L2)
    if p[0] * L0 + p[1] * L1 + p[2] * L2 < 0.0:  # towards the capsule
        length = -length
    L = (L0 / length, L1 / length, L2 / length)
    # the box's edge along e_j deepest towards the capsule
    e = (
        0.0 if j == 0 else sign_of(L[0]) * h[0],
        0.0 if j == 1 else sign_of(L[1]) * h[1],
        0.0 if j == 2 else sign_of(L[2]) * h[2],
    )
    s, t = segment_closest(p[0] - e[0], p[1] - e[1], p[2] - e[2], u[0], u[1], u[2], ha, w[0], w[1], w[2], h[j])
    q0, q1, q2 = e[0] + t * w[0], e[1] + t * w[1], e[2] + t * w[2]
    gap = (p[0] + s * u[0] - q0) * L[0] + (p[1] + s * u[1] - q1) * L[1] + (p[2] + s * u[2] - q2) * L[2]
    if r - gap <= 0.0:
        return 0
    return _box_point(out, 0, cb, Rb, q0, q1, q2, L[0], L[1], L[2], r - gap, _end_feature(s, ha))
