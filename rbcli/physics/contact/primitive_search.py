"""Body-body contact of primitives (docs/contact.md "Primitive contact"): each body pair of the body level
(body_phase.py) in which a body touches as its primitive, handed to the sink point by point.

    both primitives   primitives.primitive_pair of the two (sphere, capsule, box in either order): each
                      manifold point a contact of its own, normal from b to a (a < b, the owner)
    one primitive     each contact sphere of the other body (a cloud, a sphere shape, a mesh) whose
                      sphere meets the primitive's body box, as a sphere against the primitive (sphere-X)

The same force law, friction history, statistics and points as a sphere contact (search.contact_found).
History: a manifold point of bodies a < b is kept in a's sphere row start[a] + key % n_a with partner
b's row start[b] + (key // n_a) % n_b (key: `_feature_key`, < FEATURE_KEYS), so each (body pair,
feature) keeps its own tangential spring, unique while n_a n_b >= FEATURE_KEYS (a box's lattice has far
more); the primitive's own rows hold no sphere contacts (its spheres touch nothing: body_phase.is_primitive).
A cloud sphere i against primitive b: owner i, partner start[b].
Materials mix as for two spheres (tables.py): a primitive body's body_stiffness is its stiffness per
manifold point and its body_inv_contact_mass 1 / M (scene/compile_contact.py); a manifold of n points
shares the pair's reduced mass, so each point's damping ratio is zeta / sqrt(n): n springs k with dashpots
2 (zeta / sqrt(n)) sqrt(k M_r) damp the pair's n k, M_r at zeta.
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.contact.body_phase import bodies_meet, excluded
from rbcli.physics.contact.found import contact_found
from rbcli.physics.contact.manifold import INLINE_KERNEL, Manifold
from rbcli.physics.contact.primitives import PRIMITIVE_CAPSULE, PRIMITIVE_SPHERE, primitive_pair
from rbcli.physics.contact.tables import SWEEP_PAIRS
from rbcli.physics.step import STEP_KERNEL

# box-box features (box_box.py: 64 face + code < 32, 1024 + 12 edge_a + edge_b) packed densely below this
FEATURE_KEYS = 528
# the pre-tests' slack (squared distances): far beyond their roundings, so they never drop a contact the
# pair kernel would find
_LOOSE = 1.0 + 1e-6


@numba.njit(**INLINE_KERNEL)
def feature_key(feature):  # noqa: ANN001, ANN201
    """A manifold feature (manifold.py; box-box's up to 1167) as a key 0 .. FEATURE_KEYS - 1, one to one:
    face features 32 face + code, edge features 384 + 12 edge_a + edge_b; the others (< 64) unchanged."""
    if feature >= 1024:
        return 384 + feature - 1024
    if feature >= 64:
        return (feature >> 6) * 32 + (feature & 31)
    return feature


@numba.njit(**INLINE_KERNEL)
def _bound(kind, size):  # noqa: ANN001, ANN201
    """The radius [m] of the sphere about a primitive's centre that holds it (module primitives.py's sizes)."""
    if kind == PRIMITIVE_SPHERE:
        return size[0]
    if kind == PRIMITIVE_CAPSULE:
        return size[0] + size[1]
    return math.sqrt(size[0] * size[0] + size[1] * size[1] + size[2] * size[2])


@numba.njit(**INLINE_KERNEL)
def _bounds_meet(kind_a, ca, sa, kind_b, cb, sb):  # noqa: ANN001, ANN201
    """Whether the bounding spheres (`_bound`) of two primitives may meet (False: no contact; loosened by
    _LOOSE against rounding, so the pair kernel decides every case near touching)."""
    reach = _bound(kind_a, sa) + _bound(kind_b, sb)
    d0, d1, d2 = ca[0] - cb[0], ca[1] - cb[1], ca[2] - cb[2]
    return d0 * d0 + d1 * d1 + d2 * d2 <= reach * reach * _LOOSE


@numba.njit(**INLINE_KERNEL)
def _sphere_may_touch(kind, p0, p1, p2, r, c, R, size):  # noqa: ANN001, ANN201
    """Whether a sphere (centre p, radius r) may touch a primitive (kind, centre c, rotation R, size):
    its centre within r of the primitive's surface or inside it, by the pair kernel's own distance
    (sphere: to the centre; capsule: to the segment; box: to the clamped point in the box's frame),
    loosened by _LOOSE, so the kernel decides every case near touching. Tested in place: a call of the
    pair kernel passes ~80 numbers, and most of a cloud's spheres in a primitive's box touch nothing
    (container_mix: ~620 calls an evaluation for ~150 contacts)."""
    d0, d1, d2 = p0 - c[0], p1 - c[1], p2 - c[2]
    if kind == PRIMITIVE_SPHERE:
        reach = r + size[0]
        return d0 * d0 + d1 * d1 + d2 * d2 <= reach * reach * _LOOSE
    if kind == PRIMITIVE_CAPSULE:
        u0, u1, u2, h = R[0, 2], R[1, 2], R[2, 2], size[1]
        s = min(max(u0 * d0 + u1 * d1 + u2 * d2, -h), h)
        e0, e1, e2 = d0 - s * u0, d1 - s * u1, d2 - s * u2
        reach = r + size[0]
        return e0 * e0 + e1 * e1 + e2 * e2 <= reach * reach * _LOOSE
    dist2 = 0.0
    for k in range(3):  # the centre in the box's frame, its distance outside the box
        local = R[0, k] * d0 + R[1, k] * d1 + R[2, k] * d2
        outside = abs(local) - size[k]
        if outside > 0.0:
            dist2 += outside * outside
    return dist2 <= r * r * _LOOSE


@numba.njit(**STEP_KERNEL)
def primitive_pairs(contact, work, sink) -> None:  # noqa: ANN001
    """The contacts of the body pairs with a primitive (module docstring) handed to the sink. Called by
    search.pairs_of_bodies only where the work has primitive arrays (a scene without primitives compiles
    none of it). The pairs are the body level's buffer (body_phase.py); where the level found more than
    the buffer holds (16 a body + 64: a dense heap of long shapes beside small ones), every pair of
    boxes that meet is taken here instead, O(bodies^2) for that evaluation, so no contact is lost (the
    spheres' own pairs go to the walk then: narrow.py). One loop over either source: the pair's code
    once, in place (a call per pair passing the tables cost a heap of capsules ~40 % of its step)."""
    out = Manifold(work.manifold_point, work.manifold_normal, work.manifold_depth, work.manifold_feature)
    start, kind, shape = contact.body_sphere_start, contact.primitive_kind, work.primitive_shape
    centre, frame, lo, hi = work.primitive_centre, work.primitive_frame, work.body_lo, work.body_hi
    sphere = shape.shape[0] - 1  # the scratch row of a cloud sphere's size (r, 0, 0)
    found, bodies = work.body_sweep[SWEEP_PAIRS], kind.shape[0]
    buffered = found <= work.body_pair.shape[0]
    p, a, b = 0, 0, 0
    while True:
        if buffered:
            if p == found:
                break
            a, b = work.body_pair[p, 0], work.body_pair[p, 1]
            p += 1
        else:  # the next pair (a, b > a) whose boxes meet
            b += 1
            if b >= bodies:
                a += 1
                b = a + 1
                if b >= bodies:
                    break
            if not (lo[a, 0] <= hi[a, 0] and lo[b, 0] <= hi[b, 0]):  # an empty box touches nothing
                continue
            if not bodies_meet(contact.body_inv_contact_mass, contact.excluded_pair, lo, hi, a, b, True):
                continue
        if kind[a] < 0 and kind[b] < 0:
            continue
        if contact.excluded_pair.shape[0] and excluded(contact, a, b):
            continue
        ka, kb = contact.body_stiffness[a], contact.body_stiffness[b]
        k = ka if ka == kb else 2.0 * ka * kb / (ka + kb)
        zeta = min(contact.body_damping_ratio[a], contact.body_damping_ratio[b])
        mu = contact.body_friction_root[a] * contact.body_friction_root[b]
        if kind[a] >= 0 and kind[b] >= 0:
            if not _bounds_meet(kind[a], centre[a], shape[a], kind[b], centre[b], shape[b]):
                continue
            count = primitive_pair(kind[a], centre[a], frame[a], shape[a], kind[b], centre[b], frame[b],
                                   shape[b], out)  # fmt: skip
            if count == 0:
                continue
            shared = zeta / math.sqrt(count)
            na, nb = start[a + 1] - start[a], start[b + 1] - start[b]
            for i in range(count):
                key = feature_key(out.feature[i])
                contact_found(sink, contact, work, start[a] + key % na, start[b] + (key // na) % nb, a, b,
                              out.normal[i, 0], out.normal[i, 1], out.normal[i, 2], out.depth[i],
                              out.point[i, 0], out.point[i, 1], out.point[i, 2], k, shared, mu)  # fmt: skip
            continue
        cloud, prim = (a, b) if kind[a] < 0 else (b, a)
        pos, radius = work.sphere_position, contact.sphere_radius
        for i in range(start[cloud], start[cloud + 1]):
            r = radius[i]
            if not (
                (pos[i, 0] + r >= lo[prim, 0]) & (pos[i, 0] - r <= hi[prim, 0])
                & (pos[i, 1] + r >= lo[prim, 1]) & (pos[i, 1] - r <= hi[prim, 1])
                & (pos[i, 2] + r >= lo[prim, 2]) & (pos[i, 2] - r <= hi[prim, 2])
            ):  # fmt: skip
                continue
            if not _sphere_may_touch(kind[prim], pos[i, 0], pos[i, 1], pos[i, 2], r, centre[prim], frame[prim],
                                     shape[prim]):  # fmt: skip
                continue
            shape[sphere, 0] = r
            count = primitive_pair(PRIMITIVE_SPHERE, pos[i], frame[prim], shape[sphere], kind[prim],
                                   centre[prim], frame[prim], shape[prim], out)  # fmt: skip
            if count:  # sphere-X: one point, normal from the primitive to the sphere (the owner)
                contact_found(sink, contact, work, i, start[prim], cloud, prim,
                              out.normal[0, 0], out.normal[0, 1], out.normal[0, 2], out.depth[0],
                              out.point[0, 0], out.point[0, 1], out.point[0, 2], k, zeta, mu)  # fmt: skip
