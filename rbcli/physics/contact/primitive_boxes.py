"""Contact of a box (centre c, rotation R, half extents h: primitives.py's form) with a sphere, a capsule
and another box: compiled kernels writing a manifold (manifold.py; normal from b to a). docs/contact.md
"Primitive contact".

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
first); a tuple indexed by a variable compiles to a switch per access (`_pick` selects instead). All
primitive kernels compiled in ~22 s of CPU before these rules, ~10 s after (docs/contact.md).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.contact.manifold import (
    INLINE_KERNEL,
    MANIFOLD_POINTS,
    MANIFOLD_ROWS,
    PARALLEL_SINE2,
    clamp,
    emit,
    segment_closest,
)
from rbcli.physics.step import STEP_KERNEL

# an edge axis replaces the best face axis (b's face a's) only if its overlap is below this fraction of it
AXIS_PREFERENCE = 0.95
# |axis|^2 of an edge cross product below this: parallel edges, no axis of their own (face axes cover
# them; Ericson 4.4.1)
EDGE_SINE2 = 1e-12
# a separation within this fraction of the shapes' size is touching: decided by the axes, not by closest
# points (whose direction is then rounding noise)
TOUCH_FRACTION = 1e-9
# box-box features: face contacts (reference face f = 6 (reference is b) + 2 axis + (side > 0)) are
# FACE_FEATURE f + the point's own code (< 32); an edge-edge contact is EDGE_FEATURE + 12 edge_a + edge_b
FACE_FEATURE, EDGE_FEATURE = 64, 1024


@numba.njit(**INLINE_KERNEL)
def _sign(x):  # noqa: ANN001, ANN201
    return 1.0 if x >= 0.0 else -1.0


@numba.njit(**INLINE_KERNEL)
def _bit(side, k):  # noqa: ANN001, ANN201
    """1 << k where side > 0, else 0: a vertex index's bit k."""
    return (1 << k) if side > 0.0 else 0


@numba.njit(**INLINE_KERNEL)
def _pick(t, m):  # noqa: ANN001, ANN201
    """t[m] of a 3-tuple: selects, which compile far faster than numba's indexing of a tuple by a variable."""
    return t[0] if m == 0 else (t[1] if m == 1 else t[2])


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
        if sb[m] - abs(_pick(p, m)) < inner:
            k, inner = m, sb[m] - abs(_pick(p, m))
    side = _sign(_pick(p, k))
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
        pm, um = _pick(p, m), _pick(u, m)
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
        pm, um = _pick(p, m), _pick(u, m)
        if not _pick((clip0, clip1, clip2), m):
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
        depth = r - (side * _pick((q0, q1, q2), k) - h[k])
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
        sep = abs(_pick(p, k)) - h[k] - ha * abs(_pick(u, k))
        if sep > face_sep:
            face_sep, face = sep, k
    edge_sep, edge = -math.inf, -1
    for j in range(3):
        j1, j2 = (j + 1) % 3, (j + 2) % 3
        p1, p2, u1, u2 = _pick(p, j1), _pick(p, j2), _pick(u, j1), _pick(u, j2)
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
            return _capsule_face(out, cb, Rb, p, u, ha, r, h, k, _sign(_pick(e, k)), s)
        if free == 1:
            j = _first(free0, free1)
            if 1.0 - _pick(u, j) * _pick(u, j) < PARALLEL_SINE2:  # along the edge: its closest points are a segment
                lo, hi = _clip_to_slabs(p, u, ha, h, j == 0, j == 1, j == 2)
                if hi - lo > touch:
                    count = _capsule_point(out, np.int64(0), cb, Rb, p, u, lo, r, h, np.int64(0))
                    return _capsule_point(out, count, cb, Rb, p, u, hi, r, h, np.int64(1))
        return _capsule_point(out, np.int64(0), cb, Rb, p, u, s, r, h, _end_feature(s, ha))
    if edge < 0 or edge_sep <= AXIS_PREFERENCE * face_sep + touch:
        side = _sign(_pick(p, face))
        deepest = -ha if side * _pick(u, face) > 0.0 else ha  # the segment's point deepest into that face
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
        0.0 if j == 0 else _sign(L[0]) * h[0],
        0.0 if j == 1 else _sign(L[1]) * h[1],
        0.0 if j == 2 else _sign(L[2]) * h[2],
    )
    s, t = segment_closest(p[0] - e[0], p[1] - e[1], p[2] - e[2], u[0], u[1], u[2], ha, w[0], w[1], w[2], h[j])
    q0, q1, q2 = e[0] + t * w[0], e[1] + t * w[1], e[2] + t * w[2]
    gap = (p[0] + s * u[0] - q0) * L[0] + (p[1] + s * u[1] - q1) * L[1] + (p[2] + s * u[2] - q2) * L[2]
    if r - gap <= 0.0:
        return 0
    return _box_point(out, 0, cb, Rb, q0, q1, q2, L[0], L[1], L[2], r - gap, _end_feature(s, ha))


@numba.njit(**STEP_KERNEL)
def _dot(A, i, B, j):  # noqa: ANN001, ANN201
    """A[:, i] . B[:, j]: the cosine between axis i of one box and axis j of the other."""
    return A[0, i] * B[0, j] + A[1, i] * B[1, j] + A[2, i] * B[2, j]


@numba.njit(**STEP_KERNEL)
def _along(A, i, t0, t1, t2):  # noqa: ANN001, ANN201
    """A[:, i] . t."""
    return A[0, i] * t0 + A[1, i] * t1 + A[2, i] * t2


@numba.njit(**STEP_KERNEL)
def _box_faces(Ra, sa, Rb, sb, t0, t1, t2):  # noqa: ANN001, ANN201
    """(largest separation, its axis) of boxes a and b (centres t apart) along a's face normals a_i:
    |t . a_i| - h_a,i - sum_j h_b,j |a_i . b_j|."""
    best, axis = -math.inf, 0
    for i in range(3):
        reach = 0.0
        for j in range(3):
            reach += sb[j] * abs(_dot(Ra, i, Rb, j))
        sep = abs(_along(Ra, i, t0, t1, t2)) - sa[i] - reach
        if sep > best:
            best, axis = sep, i
    return best, axis


@numba.njit(**STEP_KERNEL)
def _box_edges(Ra, sa, Rb, sb, t0, t1, t2):  # noqa: ANN001, ANN201
    """(largest separation, i, j) of boxes a and b along the axes a_i x b_j (parallel pairs skipped;
    none: -inf, -1, -1). With C_ij = a_i . b_j: a_i x b_j = C_i1j a_i2 - C_i2j a_i1, and b_j1 . (a_i x
    b_j) = C_ij2, b_j2 . (a_i x b_j) = -C_ij1 (i1, i2 and j1, j2 the next axes in cyclic order)."""
    best, edge_i, edge_j = -math.inf, -1, -1
    for i in range(3):
        i1, i2 = (i + 1) % 3, (i + 2) % 3
        for j in range(3):
            j1, j2 = (j + 1) % 3, (j + 2) % 3
            cij = _dot(Ra, i, Rb, j)
            length2 = 1.0 - cij * cij  # |a_i x b_j|^2
            if length2 < EDGE_SINE2:
                continue
            c1, c2 = _dot(Ra, i1, Rb, j), _dot(Ra, i2, Rb, j)
            along = _along(Ra, i2, t0, t1, t2) * c1 - _along(Ra, i1, t0, t1, t2) * c2
            reach_a = sa[i1] * abs(c2) + sa[i2] * abs(c1)
            reach_b = sb[j1] * abs(_dot(Ra, i, Rb, j2)) + sb[j2] * abs(_dot(Ra, i, Rb, j1))
            sep = (abs(along) - reach_a - reach_b) / math.sqrt(length2)
            if sep > best:
                best, edge_i, edge_j = sep, i, j
    return best, edge_i, edge_j


@numba.njit(**STEP_KERNEL)
def box_box(ca, Ra, sa, cb, Rb, sb, out) -> int:  # noqa: ANN001
    """Box a against box b: the 15 separating axes (module docstring), then

    - a face axis: the face of that box facing the other is the reference, the other box's face most
      against it the incident face; the incident face clipped to the reference face's rectangle (its
      corners inside it, the reference corners inside it, the crossings of their edges: the intersection
      polygon, Sutherland-Hodgman's result without its buffers) gives the candidate points below the
      reference face, depth their distance below it; more than 4 are cut to 4 (`_keep_four`). As ODE's
      dBoxBox, Bullet's btBoxBoxDetector and Box2D's b2ClipPolygons. Features FACE_FEATURE f + the
      incident corner's vertex index (0-7), 8 + the reference corner's, or 16 + 4 incident edge + side;
    - an edge axis: one point, the closest points of the two edges that lie deepest along it
      (EDGE_FEATURE + 12 edge_a + edge_b, an edge 4 axis + its two signs).
    A face axis whose clip leaves nothing below the face (a corner of the preference) falls back to the
    best edge axis."""
    t0, t1, t2 = ca[0] - cb[0], ca[1] - cb[1], ca[2] - cb[2]  # (C_ij = a_i . b_j, ta_i = t . a_i)
    touch = TOUCH_FRACTION * (sa[0] + sa[1] + sa[2] + sb[0] + sb[1] + sb[2])
    best_a, face_a = _box_faces(Ra, sa, Rb, sb, t0, t1, t2)
    best_b, face_b = _box_faces(Rb, sb, Ra, sa, t0, t1, t2)
    if best_a > 0.0 or best_b > 0.0:
        return 0
    best_e, edge_i, edge_j = _box_edges(Ra, sa, Rb, sb, t0, t1, t2)
    if best_e > 0.0:
        return 0
    # a's or b's face: the clearly shallower one, else (a near tie, as of a box resting on another) the
    # larger face, so a-b and b-a agree and a small box on a big one shows its own corners (stable ids)
    on_b = best_b > AXIS_PREFERENCE * best_a + touch
    if not on_b and not best_a > AXIS_PREFERENCE * best_b + touch:
        area_a = sa[(face_a + 1) % 3] * sa[(face_a + 2) % 3]
        on_b = sb[(face_b + 1) % 3] * sb[(face_b + 2) % 3] > area_a
    best_face = best_b if on_b else best_a
    if edge_i >= 0 and best_e > AXIS_PREFERENCE * best_face + touch:
        return _edge_contact(ca, Ra, sa, cb, Rb, sb, edge_i, edge_j, out)
    cx, Rx, hx, k, cy, Ry, hy = (cb, Rb, sb, face_b, ca, Ra, sa) if on_b else (ca, Ra, sa, face_a, cb, Rb, sb)
    count = _face_contact(cx, Rx, hx, k, cy, Ry, hy, on_b, out)
    if count == 0 and edge_i >= 0:
        return _edge_contact(ca, Ra, sa, cb, Rb, sb, edge_i, edge_j, out)
    return count


@numba.njit(**STEP_KERNEL)
def _edge_code(R, size, axis, L0, L1, L2, toward):  # noqa: ANN001, ANN201
    """The box edge along `axis` lying farthest along toward * L: its centre offset from the box centre
    (world) and its code 4 axis + (side along axis + 1 > 0) + 2 (side along axis + 2 > 0)."""
    o0, o1, o2, code = 0.0, 0.0, 0.0, 4 * axis
    for bit in range(2):
        m = (axis + 1 + bit) % 3
        side = _sign(toward * (R[0, m] * L0 + R[1, m] * L1 + R[2, m] * L2))
        o0, o1, o2 = o0 + side * size[m] * R[0, m], o1 + side * size[m] * R[1, m], o2 + side * size[m] * R[2, m]
        code += _bit(side, bit)
    return o0, o1, o2, code


@numba.njit(**STEP_KERNEL)
def _edge_contact(ca, Ra, sa, cb, Rb, sb, i, j, out) -> int:  # noqa: ANN001
    """Edge-edge: axis L = a_i x b_j towards a; a's edge along a_i deepest towards b (-L), b's along b_j
    deepest towards a (+L); their closest points p_a, p_b, d = (p_b - p_a) . L."""
    x0 = Ra[1, i] * Rb[2, j] - Ra[2, i] * Rb[1, j]
    x1 = Ra[2, i] * Rb[0, j] - Ra[0, i] * Rb[2, j]
    x2 = Ra[0, i] * Rb[1, j] - Ra[1, i] * Rb[0, j]
    length = math.sqrt(x0 * x0 + x1 * x1 + x2 * x2)
    if x0 * (ca[0] - cb[0]) + x1 * (ca[1] - cb[1]) + x2 * (ca[2] - cb[2]) < 0.0:
        length = -length
    L0, L1, L2 = x0 / length, x1 / length, x2 / length
    oa0, oa1, oa2, code_a = _edge_code(Ra, sa, i, L0, L1, L2, -1.0)
    ob0, ob1, ob2, code_b = _edge_code(Rb, sb, j, L0, L1, L2, 1.0)
    ea0, ea1, ea2 = ca[0] + oa0, ca[1] + oa1, ca[2] + oa2
    eb0, eb1, eb2 = cb[0] + ob0, cb[1] + ob1, cb[2] + ob2
    s, t = segment_closest(ea0 - eb0, ea1 - eb1, ea2 - eb2, Ra[0, i], Ra[1, i], Ra[2, i], sa[i],
                           Rb[0, j], Rb[1, j], Rb[2, j], sb[j])  # fmt: skip
    pb0, pb1, pb2 = eb0 + t * Rb[0, j], eb1 + t * Rb[1, j], eb2 + t * Rb[2, j]
    depth = (pb0 - ea0 - s * Ra[0, i]) * L0 + (pb1 - ea1 - s * Ra[1, i]) * L1 + (pb2 - ea2 - s * Ra[2, i]) * L2
    if depth <= 0.0:
        return 0
    return emit(out, 0, pb0, pb1, pb2, L0, L1, L2, depth, EDGE_FEATURE + 12 * code_a + code_b)


@numba.njit(**INLINE_KERNEL)
def _candidate(out, count, x0, x1, x2, depth, feature) -> int:  # noqa: ANN001
    """A clip candidate: the incident surface point x (world) and its depth below the reference face."""
    if count >= MANIFOLD_ROWS:
        return count
    out.point[count, 0], out.point[count, 1], out.point[count, 2] = x0, x1, x2
    out.depth[count] = depth
    out.feature[count] = feature
    return count + 1


@numba.njit(**STEP_KERNEL)
def _face_contact(cx, Rx, hx, k, cy, Ry, hy, reference_is_b, out) -> int:  # noqa: ANN001
    """Reference box x's face along axis k facing box y, clipped against y's incident face (box_box).
    On the reference face, (u, w) are the coordinates along its axes k1, k2 and z the height over it."""
    side = _sign((cy[0] - cx[0]) * Rx[0, k] + (cy[1] - cx[1]) * Rx[1, k] + (cy[2] - cx[2]) * Rx[2, k])
    r0, r1, r2 = side * Rx[0, k], side * Rx[1, k], side * Rx[2, k]  # out of x towards y
    k1, k2 = (k + 1) % 3, (k + 2) % 3
    w1, w2 = hx[k1], hx[k2]
    # incident face: y's face whose outward normal is most against the reference normal
    m = _incident_axis(Ry, r0, r1, r2)
    out_m = -_sign(Ry[0, m] * r0 + Ry[1, m] * r1 + Ry[2, m] * r2)
    frame = (k, k1, k2, r0, r1, r2, m, out_m)  # what `_corner` needs besides the boxes
    corner0 = _corner(cx, Rx, hx, cy, Ry, hy, frame, np.int64(0))
    corner1 = _corner(cx, Rx, hx, cy, Ry, hy, frame, np.int64(1))
    corner2 = _corner(cx, Rx, hx, cy, Ry, hy, frame, np.int64(2))
    corner3 = _corner(cx, Rx, hx, cy, Ry, hy, frame, np.int64(3))
    count = np.int64(0)
    for c in range(4):  # incident corners over the reference face
        x0, x1, x2, u, w, z, vertex = _pick4(corner0, corner1, corner2, corner3, c)
        if abs(u) <= w1 and abs(w) <= w2 and z < 0.0:
            count = _candidate(out, count, x0, x1, x2, -z, int(vertex))
    # the incident plane's height over the reference face: z = z_f - (N_u (u - u_f) + N_w (w - w_f)) / N_z,
    # N its outward normal, f its centre
    n0, n1, n2 = out_m * Ry[0, m], out_m * Ry[1, m], out_m * Ry[2, m]
    nu = n0 * Rx[0, k1] + n1 * Rx[1, k1] + n2 * Rx[2, k1]
    nw = n0 * Rx[0, k2] + n1 * Rx[1, k2] + n2 * Rx[2, k2]
    nz = n0 * r0 + n1 * r1 + n2 * r2  # <= -1/sqrt(3): the incident face is the one most against it
    g0, g1, g2 = (
        cy[0] + out_m * hy[m] * Ry[0, m] - cx[0],
        cy[1] + out_m * hy[m] * Ry[1, m] - cx[1],
        cy[2] + out_m * hy[m] * Ry[2, m] - cx[2],
    )
    fu = g0 * Rx[0, k1] + g1 * Rx[1, k1] + g2 * Rx[2, k1]
    fw = g0 * Rx[0, k2] + g1 * Rx[1, k2] + g2 * Rx[2, k2]
    fz = g0 * r0 + g1 * r1 + g2 * r2 - hx[k]
    for c in range(4):  # reference corners strictly inside the incident face's outline
        su, sw = _corner_signs(c)
        u, w = su * w1, sw * w2
        positive, negative = 0, 0
        for e in range(4):
            a = _pick4(corner0, corner1, corner2, corner3, e)
            b = _pick4(corner0, corner1, corner2, corner3, (e + 1) % 4)
            cross = (b[3] - a[3]) * (w - a[4]) - (b[4] - a[4]) * (u - a[3])
            positive += cross > 0.0
            negative += cross < 0.0
        if positive != 4 and negative != 4:
            continue
        z = fz - (nu * (u - fu) + nw * (w - fw)) / nz
        if z < 0.0:
            x0 = cx[0] + u * Rx[0, k1] + w * Rx[0, k2] + (hx[k] + z) * r0
            x1 = cx[1] + u * Rx[1, k1] + w * Rx[1, k2] + (hx[k] + z) * r1
            x2 = cx[2] + u * Rx[2, k1] + w * Rx[2, k2] + (hx[k] + z) * r2
            count = _candidate(out, count, x0, x1, x2, -z, 8 + (_bit(side, k) | _bit(su, k1) | _bit(sw, k2)))
    for e in range(4):  # incident edges crossing the reference face's sides u = -+w1 (0, 1), w = -+w2 (2, 3)
        a = _pick4(corner0, corner1, corner2, corner3, e)
        b = _pick4(corner0, corner1, corner2, corner3, (e + 1) % 4)
        for edge_side in range(4):
            if edge_side < 2:
                start, span, across, slope, bound, limit = a[3], b[3] - a[3], a[4], b[4] - a[4], w1, w2
            else:
                start, span, across, slope, bound, limit = a[4], b[4] - a[4], a[3], b[3] - a[3], w2, w1
            if span == 0.0:
                continue
            t = ((bound if edge_side % 2 else -bound) - start) / span
            if not (0.0 < t < 1.0) or not abs(across + t * slope) < limit:
                continue
            z = a[5] + t * (b[5] - a[5])
            if z < 0.0:
                x0, x1, x2 = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])
                count = _candidate(out, count, x0, x1, x2, -z, 16 + 4 * e + edge_side)
    if count > MANIFOLD_POINTS:
        count = _keep_four(out, count, r0, r1, r2)
    face = FACE_FEATURE * ((6 if reference_is_b else 0) + 2 * k + (1 if side > 0.0 else 0))
    n0, n1, n2 = (r0, r1, r2) if reference_is_b else (-r0, -r1, -r2)
    for i in range(count):  # halfway: the incident point moved d/2 towards the reference face
        half = 0.5 * out.depth[i]
        out.point[i, 0] += half * r0
        out.point[i, 1] += half * r1
        out.point[i, 2] += half * r2
        out.normal[i, 0], out.normal[i, 1], out.normal[i, 2] = n0, n1, n2
        out.feature[i] += face
    return int(count)


@numba.njit(**STEP_KERNEL)
def _incident_axis(Ry, r0, r1, r2):  # noqa: ANN001, ANN201
    """The axis of box y most along r (the incident face's)."""
    m, best = 0, -1.0
    for i in range(3):
        along = abs(Ry[0, i] * r0 + Ry[1, i] * r1 + Ry[2, i] * r2)
        if along > best:
            m, best = i, along
    return m


@numba.njit(**INLINE_KERNEL)
def _pick4(t0, t1, t2, t3, i):  # noqa: ANN001, ANN201
    """One of four corners by a variable index (selects: see `_pick`)."""
    return t0 if i == 0 else (t1 if i == 1 else (t2 if i == 2 else t3))


@numba.njit(**INLINE_KERNEL)
def _corner_signs(c):  # noqa: ANN001, ANN201
    """The signs along a face's two axes of its corner c: (+, +), (-, +), (-, -), (+, -), in order round."""
    return (1.0 if c == 0 or c == 3 else -1.0), (1.0 if c < 2 else -1.0)


@numba.njit(**STEP_KERNEL)
def _corner(cx, Rx, hx, cy, Ry, hy, frame, c):  # noqa: ANN001, ANN201
    """Corner c of y's incident face (along y's axis m, outward out_m): (x0, x1, x2, u, w, z, vertex
    index of y), its world position and its coordinates over x's reference face (`_face_contact`)."""
    k, k1, k2, r0, r1, r2, m, out_m = frame
    m1, m2 = (m + 1) % 3, (m + 2) % 3
    s1, s2 = _corner_signs(c)
    d0 = out_m * hy[m] * Ry[0, m] + s1 * hy[m1] * Ry[0, m1] + s2 * hy[m2] * Ry[0, m2]
    d1 = out_m * hy[m] * Ry[1, m] + s1 * hy[m1] * Ry[1, m1] + s2 * hy[m2] * Ry[1, m2]
    d2 = out_m * hy[m] * Ry[2, m] + s1 * hy[m1] * Ry[2, m1] + s2 * hy[m2] * Ry[2, m2]
    x0, x1, x2 = cy[0] + d0, cy[1] + d1, cy[2] + d2
    g0, g1, g2 = x0 - cx[0], x1 - cx[1], x2 - cx[2]
    u = g0 * Rx[0, k1] + g1 * Rx[1, k1] + g2 * Rx[2, k1]
    w = g0 * Rx[0, k2] + g1 * Rx[1, k2] + g2 * Rx[2, k2]
    z = g0 * r0 + g1 * r1 + g2 * r2 - hx[k]
    return x0, x1, x2, u, w, z, float(_bit(out_m, m) | _bit(s1, m1) | _bit(s2, m2))


@numba.njit(**INLINE_KERNEL)
def _row(out, i):  # noqa: ANN001, ANN201
    return out.point[i, 0], out.point[i, 1], out.point[i, 2], out.depth[i], out.feature[i]


@numba.njit(**INLINE_KERNEL)
def _put(out, i, row) -> int:  # noqa: ANN001
    out.point[i, 0], out.point[i, 1], out.point[i, 2], out.depth[i], out.feature[i] = row
    return i + 1


@numba.njit(**STEP_KERNEL)
def _keep_four(out, count, n0, n1, n2) -> int:  # noqa: ANN001
    """Cut `count` > 4 candidates to at most 4 spanning the most area: the deepest, the one farthest from
    it, then the ones of largest signed area on either side of the line through those two (n: the face
    normal), as Bullet's btPersistentManifold and Jolt's PruneContactPoints choose."""
    i0 = 0
    for i in range(1, count):
        if out.depth[i] > out.depth[i0]:
            i0 = i
    i1, far = -1, -1.0
    for i in range(count):
        d0, d1, d2 = (
            out.point[i, 0] - out.point[i0, 0],
            out.point[i, 1] - out.point[i0, 1],
            out.point[i, 2] - out.point[i0, 2],
        )
        dist2 = d0 * d0 + d1 * d1 + d2 * d2
        if i != i0 and dist2 > far:
            i1, far = i, dist2
    a0, a1, a2 = (
        out.point[i1, 0] - out.point[i0, 0],
        out.point[i1, 1] - out.point[i0, 1],
        out.point[i1, 2] - out.point[i0, 2],
    )
    i2, i3, most, least = -1, -1, 0.0, 0.0
    for i in range(count):
        d0, d1, d2 = (
            out.point[i, 0] - out.point[i0, 0],
            out.point[i, 1] - out.point[i0, 1],
            out.point[i, 2] - out.point[i0, 2],
        )
        area = (a1 * d2 - a2 * d1) * n0 + (a2 * d0 - a0 * d2) * n1 + (a0 * d1 - a1 * d0) * n2
        if area > most:
            i2, most = i, area
        if area < least:
            i3, least = i, area
    row0, row1 = _row(out, i0), _row(out, i1)
    row2, row3 = _row(out, max(i2, 0)), _row(out, max(i3, 0))
    kept = _put(out, 0, row0)
    kept = _put(out, kept, row1)
    if i2 >= 0:
        kept = _put(out, kept, row2)
    if i3 >= 0:
        kept = _put(out, kept, row3)
    return kept
