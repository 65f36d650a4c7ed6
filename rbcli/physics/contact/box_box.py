"""Box against box: the 15 separating axes, then the reference face clipped by the incident face (up to 4
points) or the crossing edges (1 point); a compiled kernel writing a manifold (manifold.py; normal from
b to a). The axes, their preferences and the compile-time rules: primitive_boxes.py. docs/contact.md
"Primitive contact".
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.contact.manifold import (
    INLINE_KERNEL,
    MANIFOLD_POINTS,
    MANIFOLD_ROWS,
    emit,
    segment_closest,
    sign_of,
)
from rbcli.physics.contact.primitive_boxes import AXIS_PREFERENCE, EDGE_SINE2, TOUCH_FRACTION
from rbcli.physics.step import STEP_KERNEL

# box-box features: face contacts (reference face f = 6 (reference is b) + 2 axis + (side > 0)) are
# FACE_FEATURE f + the point's own code (< 32); an edge-edge contact is EDGE_FEATURE + 12 edge_a + edge_b
FACE_FEATURE, EDGE_FEATURE = 64, 1024


@numba.njit(**INLINE_KERNEL)
def _bit(side, k):  # noqa: ANN001, ANN201
    """1 << k where side > 0, else 0: a vertex index's bit k."""
    return (1 << k) if side > 0.0 else 0


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
        side = sign_of(toward * (R[0, m] * L0 + R[1, m] * L1 + R[2, m] * L2))
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


@numba.njit(**INLINE_KERNEL)
def _fresh(out, count, x0, x1, x2, touch) -> bool:  # noqa: ANN001
    """Whether no candidate so far lies within `touch` of x: the corners and crossings of faces whose edges
    coincide (boxes of one width stacked) are found twice, by the tests that take the outline's points."""
    for i in range(count):
        e0, e1, e2 = out.point[i, 0] - x0, out.point[i, 1] - x1, out.point[i, 2] - x2
        if e0 * e0 + e1 * e1 + e2 * e2 <= touch * touch:
            return False
    return True


@numba.njit(**STEP_KERNEL)
def _face_contact(cx, Rx, hx, k, cy, Ry, hy, reference_is_b, out) -> int:  # noqa: ANN001
    """Reference box x's face along axis k facing box y, clipped against y's incident face (box_box).
    On the reference face, (u, w) are the coordinates along its axes k1, k2 and z the height over it."""
    side = sign_of((cy[0] - cx[0]) * Rx[0, k] + (cy[1] - cx[1]) * Rx[1, k] + (cy[2] - cx[2]) * Rx[2, k])
    r0, r1, r2 = side * Rx[0, k], side * Rx[1, k], side * Rx[2, k]  # out of x towards y
    k1, k2 = (k + 1) % 3, (k + 2) % 3
    w1, w2 = hx[k1], hx[k2]
    # incident face: y's face whose outward normal is most against the reference normal
    m = _incident_axis(Ry, r0, r1, r2)
    out_m = -sign_of(Ry[0, m] * r0 + Ry[1, m] * r1 + Ry[2, m] * r2)
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
    touch = TOUCH_FRACTION * (w1 + w2)
    for c in range(4):  # reference corners inside the incident face's outline or on it
        su, sw = _corner_signs(c)
        u, w = su * w1, sw * w2
        positive, negative = 0, 0
        for e in range(4):
            a = _pick4(corner0, corner1, corner2, corner3, e)
            b = _pick4(corner0, corner1, corner2, corner3, (e + 1) % 4)
            cross = (b[3] - a[3]) * (w - a[4]) - (b[4] - a[4]) * (u - a[3])
            positive += cross > 0.0
            negative += cross < 0.0
        if positive and negative:
            continue
        z = fz - (nu * (u - fu) + nw * (w - fw)) / nz
        if z < 0.0:
            x0 = cx[0] + u * Rx[0, k1] + w * Rx[0, k2] + (hx[k] + z) * r0
            x1 = cx[1] + u * Rx[1, k1] + w * Rx[1, k2] + (hx[k] + z) * r1
            x2 = cx[2] + u * Rx[2, k1] + w * Rx[2, k2] + (hx[k] + z) * r2
            if _fresh(out, count, x0, x1, x2, touch):
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
            if not (0.0 < t < 1.0) or not abs(across + t * slope) <= limit:
                continue
            z = a[5] + t * (b[5] - a[5])
            if z < 0.0:
                x0, x1, x2 = a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), a[2] + t * (b[2] - a[2])
                if _fresh(out, count, x0, x1, x2, touch):
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
    """One of four corners by a variable index (selects: manifold.pick3)."""
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
