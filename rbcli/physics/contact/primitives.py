"""Contact of primitives as their exact surfaces: sphere, capsule and box against each other and against
a plane, each pair a compiled kernel writing a manifold of up to 4 points (manifold.py: point halfway
between the surfaces, unit normal from b to a, depth > 0, feature id). Used against planes by search.py
and between bodies by primitive_search.py: docs/contact.md "Primitive contact".

A primitive is given as MuJoCo gives a geom (engine_collision_primitive.c): its centre c [m, world], its
rotation R (3, 3) (columns: its axes in the world frame, rotation_kernels.quat_to_matrix_nb) and its
size (3,) [m]:
    sphere   (radius, -, -)                       PRIMITIVE_SPHERE
    capsule  (radius, half-length, -), axis R[:, 2]   PRIMITIVE_CAPSULE: the points within radius of the
             segment c +- half-length R[:, 2]
    box      half extents along R[:, 0..2]        PRIMITIVE_BOX (primitive_boxes.py, box_box.py)
A plane is a point on it and its unit normal (out of the solid), as in the contact table. Every kernel
returns the number of points written; the kernels of a pair in the other order are `primitive_pair`'s.
A particle sphere of a cloud is a sphere here, so sphere-X is also how a cloud touches a primitive.
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.contact.box_box import box_box
from rbcli.physics.contact.manifold import INLINE_KERNEL, clamp, emit, round_contact, segment_closest
from rbcli.physics.contact.primitive_boxes import capsule_box, sphere_box
from rbcli.physics.step import STEP_KERNEL

PRIMITIVE_SPHERE, PRIMITIVE_CAPSULE, PRIMITIVE_BOX = 0, 1, 2

# capsule-capsule: a second point closer to the first than this fraction of the segments' length is the
# same point (two coincident points would count the contact twice)
SPAN_FRACTION = 1e-9


@numba.njit(**INLINE_KERNEL)
def perpendicular(u0, u1, u2):  # noqa: ANN001, ANN201
    """A unit vector perpendicular to unit u: u x e with e the world axis least along u."""
    a0, a1, a2 = abs(u0), abs(u1), abs(u2)
    if a0 <= a1 and a0 <= a2:  # e = x
        p0, p1, p2 = 0.0, u2, -u1
    elif a1 <= a2:  # e = y
        p0, p1, p2 = -u2, 0.0, u0
    else:  # e = z
        p0, p1, p2 = u1, -u0, 0.0
    length = math.sqrt(p0 * p0 + p1 * p1 + p2 * p2)
    return p0 / length, p1 / length, p2 / length


@numba.njit(**STEP_KERNEL)
def sphere_sphere(ca, Ra, sa, cb, Rb, sb, out) -> int:  # noqa: ANN001
    """d = r_a + r_b - |c_a - c_b|, n = (c_a - c_b) / |c_a - c_b| (coincident centres: +z); feature 0."""
    return round_contact(out, 0, ca[0], ca[1], ca[2], sa[0], cb[0], cb[1], cb[2], sb[0], 0.0, 0.0, 1.0, 0)


@numba.njit(**STEP_KERNEL)
def sphere_capsule(ca, Ra, sa, cb, Rb, sb, out) -> int:  # noqa: ANN001
    """Sphere a against the sphere of b's radius at the point of b's segment closest to c_a,
    c_b + clamp(u . (c_a - c_b), -h, h) u; feature 0."""
    u0, u1, u2, h = Rb[0, 2], Rb[1, 2], Rb[2, 2], sb[1]
    s = clamp(u0 * (ca[0] - cb[0]) + u1 * (ca[1] - cb[1]) + u2 * (ca[2] - cb[2]), -h, h)
    f0, f1, f2 = perpendicular(u0, u1, u2)  # centre on the axis: any normal across it
    return round_contact(out, 0, ca[0], ca[1], ca[2], sa[0], cb[0] + s * u0, cb[1] + s * u1, cb[2] + s * u2,
                         sb[0], f0, f1, f2, 0)  # fmt: skip


@numba.njit(**INLINE_KERNEL)
def _end_code(s, h, first):  # noqa: ANN001, ANN201
    """first (s = -h) or first + 1 (s = +h) for a segment parameter clamped at an end, else -1."""
    if s <= -h:
        return first
    if s >= h:
        return first + 1
    return -1


@numba.njit(**STEP_KERNEL)
def capsule_capsule(ca, Ra, sa, cb, Rb, sb, out) -> int:  # noqa: ANN001
    """The segments' closest points (manifold.segment_closest) as a sphere-sphere contact; then, unless
    that pair is two crossing interiors, a second point: of the segment ends whose foot on the other
    segment is not clamped (the ends that bound the segments' overlap), the one farthest from the first
    pair, where it overlaps too. Parallel capsules side by side thus get two points, at the overlap's
    ends (MuJoCo's mjc_CapsuleCapsule adds them at exact parallelism only, Box2D's b2CollideCapsules
    clips the segments); the choice does not depend on which capsule is a. Each point's depth is exact
    for its pair of segment points; the first is the deepest. Features: the segment end a point comes
    from, a's ends 0 (-h) and 1 (+h), b's 2 and 3; 4 for crossing interiors."""
    ra, ha, rb, hb = sa[0], sa[1], sb[0], sb[1]
    u0, u1, u2 = Ra[0, 2], Ra[1, 2], Ra[2, 2]
    v0, v1, v2 = Rb[0, 2], Rb[1, 2], Rb[2, 2]
    r0, r1, r2 = ca[0] - cb[0], ca[1] - cb[1], ca[2] - cb[2]
    s, t = segment_closest(r0, r1, r2, u0, u1, u2, ha, v0, v1, v2, hb)
    f0, f1, f2 = u1 * v2 - u2 * v1, u2 * v0 - u0 * v2, u0 * v1 - u1 * v0  # crossing segments: across both
    length = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
    if length > 1e-6:
        f0, f1, f2 = f0 / length, f1 / length, f2 / length
    else:
        f0, f1, f2 = perpendicular(u0, u1, u2)
    first = _end_code(s, ha, 0)
    if first < 0:
        first = _end_code(t, hb, 2)
    count = round_contact(out, 0, ca[0] + s * u0, ca[1] + s * u1, ca[2] + s * u2, ra,
                          cb[0] + t * v0, cb[1] + t * v1, cb[2] + t * v2, rb, f0, f1, f2,
                          first if first >= 0 else 4)  # fmt: skip
    if count == 0 or first < 0:
        return count
    # the second point: of the segment ends whose closest point on the other segment is not clamped (the
    # ends bounding the overlap), the one farthest from the first pair that overlaps too
    b = u0 * v0 + u1 * v1 + u2 * v2
    c = u0 * r0 + u1 * r1 + u2 * r2
    f = v0 * r0 + v1 * r1 + v2 * r2
    span = SPAN_FRACTION * (ha + hb)
    far, s2, t2, code = span * span, 0.0, 0.0, -1
    for end in range(4):
        if end < 2:  # a's end -ha or +ha, and its foot on b
            se = ha if end else -ha
            te = f + b * se
            inside = -hb <= te <= hb
        else:  # b's end -hb or +hb, and its foot on a
            te = hb if end == 3 else -hb
            se = b * te - c
            inside = -ha <= se <= ha
        d0 = r0 + se * u0 - te * v0
        d1 = r1 + se * u1 - te * v1
        d2 = r2 + se * u2 - te * v2
        if not inside or d0 * d0 + d1 * d1 + d2 * d2 >= (ra + rb) * (ra + rb):
            continue
        # distance from the first pair, of both points: the same whichever shape is a
        moved = (se - s) * (se - s) + (te - t) * (te - t)
        if moved > far:
            far, s2, t2, code = moved, se, te, end
    if code < 0:
        return count
    return round_contact(out, count, ca[0] + s2 * u0, ca[1] + s2 * u1, ca[2] + s2 * u2, ra,
                         cb[0] + t2 * v0, cb[1] + t2 * v1, cb[2] + t2 * v2, rb, f0, f1, f2, code)  # fmt: skip


@numba.njit(**STEP_KERNEL)
def sphere_plane(c, R, size, plane_point, plane_normal, out) -> int:  # noqa: ANN001
    """d = r - (c - p0) . n, normal n (the plane is b); feature 0."""
    n0, n1, n2 = plane_normal[0], plane_normal[1], plane_normal[2]
    return _ball_plane(out, 0, c[0], c[1], c[2], size[0], plane_point, n0, n1, n2, 0)


@numba.njit(**INLINE_KERNEL)
def _ball_plane(out, count, c0, c1, c2, r, plane_point, n0, n1, n2, feature) -> int:  # noqa: ANN001
    """A ball of radius r at c against the plane: its point at `count` if it overlaps; the new count."""
    dist = (c0 - plane_point[0]) * n0 + (c1 - plane_point[1]) * n1 + (c2 - plane_point[2]) * n2
    depth = r - dist
    if depth <= 0.0:
        return count
    return emit(out, count, c0 - dist * n0, c1 - dist * n1, c2 - dist * n2, n0, n1, n2, depth, feature)


@numba.njit(**STEP_KERNEL)
def capsule_plane(c, R, size, plane_point, plane_normal, out) -> int:  # noqa: ANN001
    """The balls at the segment's two ends against the plane (its deepest points: up to 2, both when it
    lies flat), as MuJoCo's mjc_PlaneCapsule; feature 0 (the end at -h) and 1 (+h)."""
    r, h = size[0], size[1]
    u0, u1, u2 = h * R[0, 2], h * R[1, 2], h * R[2, 2]
    n0, n1, n2 = plane_normal[0], plane_normal[1], plane_normal[2]
    count = _ball_plane(out, 0, c[0] - u0, c[1] - u1, c[2] - u2, r, plane_point, n0, n1, n2, 0)
    return _ball_plane(out, count, c[0] + u0, c[1] + u1, c[2] + u2, r, plane_point, n0, n1, n2, 1)


@numba.njit(**STEP_KERNEL)
def box_plane(c, R, size, plane_point, plane_normal, out) -> int:  # noqa: ANN001
    """The box's vertices below the plane, the 4 deepest where more are (a box deeper than its own
    thickness), as MuJoCo's mjc_PlaneBox (which keeps the first 4). Feature: the vertex index, bit k set
    where the vertex is at +size[k] along R[:, k]."""
    n0, n1, n2 = plane_normal[0], plane_normal[1], plane_normal[2]
    count = 0
    for v in range(8):
        x0, x1, x2 = c[0], c[1], c[2]
        for k in range(3):
            h = size[k] if (v >> k) & 1 else -size[k]
            x0, x1, x2 = x0 + h * R[0, k], x1 + h * R[1, k], x2 + h * R[2, k]
        dist = (x0 - plane_point[0]) * n0 + (x1 - plane_point[1]) * n1 + (x2 - plane_point[2]) * n2
        if dist >= 0.0:
            continue
        row = count
        if count == 4:  # full: replace the shallowest if this vertex is deeper
            row = 0
            for i in range(1, 4):
                if out.depth[i] < out.depth[row]:
                    row = i
            if -dist <= out.depth[row]:
                continue
        emit(out, row, x0 - dist * n0, x1 - dist * n1, x2 - dist * n2, n0, n1, n2, -dist, v)
        count = min(count + 1, 4)
    return count


@numba.njit(**STEP_KERNEL)
def primitive_pair(kind_a, ca, Ra, sa, kind_b, cb, Rb, sb, out) -> int:  # noqa: ANN001
    """The manifold of primitives a and b (kinds PRIMITIVE_*; module docstring), normals from b to a.
    A pair in the other order (box-sphere) runs its kernel as b-a and turns the normals round: the
    same points, depths and features.

    One call between the primitive search and the pair's kernel: each call passes the primitives' arrays
    and the manifold by value (~80 numbers), and a second level of dispatch (kinds put in order, then
    the kernel chosen) was ~5 % of a settled container_mix's step (perf). Inlined into the search
    (numba's inline) the dispatch made a primitive scene's first run ~11 s longer (box_drop 92.3 against
    81.1 CPU-s on an empty cache, 2026-12-06) for 11 % less on container_mix: not kept."""
    if kind_a == PRIMITIVE_SPHERE:
        if kind_b == PRIMITIVE_SPHERE:
            return sphere_sphere(ca, Ra, sa, cb, Rb, sb, out)
        if kind_b == PRIMITIVE_CAPSULE:
            return sphere_capsule(ca, Ra, sa, cb, Rb, sb, out)
        return sphere_box(ca, Ra, sa, cb, Rb, sb, out)
    if kind_a == PRIMITIVE_CAPSULE:
        if kind_b == PRIMITIVE_CAPSULE:
            return capsule_capsule(ca, Ra, sa, cb, Rb, sb, out)
        if kind_b == PRIMITIVE_BOX:
            return capsule_box(ca, Ra, sa, cb, Rb, sb, out)
        count = sphere_capsule(cb, Rb, sb, ca, Ra, sa, out)
    elif kind_b == PRIMITIVE_BOX:
        return box_box(ca, Ra, sa, cb, Rb, sb, out)
    elif kind_b == PRIMITIVE_CAPSULE:
        count = capsule_box(cb, Rb, sb, ca, Ra, sa, out)
    else:
        count = sphere_box(cb, Rb, sb, ca, Ra, sa, out)
    for i in range(count):  # b-a's normals point from a to b
        out.normal[i, 0], out.normal[i, 1], out.normal[i, 2] = -out.normal[i, 0], -out.normal[i, 1], -out.normal[i, 2]
    return count


@numba.njit(**STEP_KERNEL)
def primitive_plane(kind, c, R, size, plane_point, plane_normal, out) -> int:  # noqa: ANN001
    """The manifold of a primitive (a) against a plane (b), normal the plane's."""
    if kind == PRIMITIVE_SPHERE:
        return sphere_plane(c, R, size, plane_point, plane_normal, out)
    if kind == PRIMITIVE_CAPSULE:
        return capsule_plane(c, R, size, plane_point, plane_normal, out)
    return box_plane(c, R, size, plane_point, plane_normal, out)
