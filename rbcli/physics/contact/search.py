"""The contact search: every sphere overlapping a plane and every overlapping pair of contact spheres of
different bodies, with its geometry and mixed material, handed to a sink. The force stage (force.py),
the recorded contact points (points.py) and the recorded state's contact statistics (state.py) are its
sinks: one search, so what they report is the same set of contacts with the same numbers.

Per contact, with d the overlap and n the unit normal towards the owner:
    plane p, sphere i (owner i, partner PLANE_PARTNER_BASE - p):  d = r_i - (p_i - p0) . n,  n the plane's
    spheres i < j (owner i, partner j):  d = r_i + r_j - |p_i - p_j|,  n = (p_i - p_j) / |p_i - p_j|
and the contact point c halfway through the overlap (plane: p_i - (r_i - d / 2) n; pair:
p_j + (r_j - d / 2) n). The owner is the lower sphere index whichever sphere's walk found the pair
(p_i - p_j is exactly -(p_j - p_i) in floating point, so the numbers do not depend on the finder).
Materials mix as tables.py says: k in series (a plane: the body's plane stiffness), the smaller zeta,
mu = sqrt(mu_a) sqrt(mu_b). Skipped: spheres of one body, pairs of two bodies that cannot move
(static or kinematic: inverse contact mass 0), pairs of two bodies a joint connects (unless it says
`collide: true`: ContactTable.excluded_pair), coincident centres (no normal).

Which spheres are searched comes first from the body level (body_phase.py, through sphere_positions):
planes only for spheres of bodies whose box meets them, pairs only among spheres of bodies whose boxes
meet another's (the same contacts, in the same order where the whole grid would be dense or is hashed).
In scenes of bodies of many spheres (the body level on), the pairs are first sought among the
spheres of the body pairs (narrow.py: each pair's spheres that meet the other body's box, tested
against each other) and sorted into the walk's order: the same contacts handed on in the same order,
with far fewer checks (a pile of 13-sphere clouds: ~220,000 instead of ~640,000); where that would cost
more than the walk, or the grid is hashed, the walk runs. Otherwise pairs come from the grid of
broad_phase.py: each sphere looks at the later spheres of its own bucket
and at every sphere of the 13 cells of its half shell, so each pair is found once; a hashed bucket may
hold several cells, so a candidate of another cell is skipped by comparing cells (a dense bucket is one
cell). The walk reads the bucket-ordered copies (sorted_*: build_grid), so the distance checks of the
candidates touch neighbouring memory; sphere and body arrays are read only for real overlaps.

Sinks: `contact_found(sink, ...)` is a stub; a sink module registers a numba `overload` of it for its
sink type (a NamedTuple). The force stage, the statistics and the contact points share one type,
sink.ContactSink, whose `purpose` chooses at run time, so a scene compiles the search once for all
three (sink.py says why); the threaded search's record blocks have their own (threaded.py).
`find_contacts` is a compiled function of its own (one per sink type), called only when the body phase
flagged some body: inlined into each caller at numba's IR level, as it was, the search was ~4-5 s of
each caller's first compile (numba's pass events), and a call passes the contact table and work by
value (~100 ns: the far case of benchmarks/bench_contact.py), which only a search with something to
find now pays. `sphere_positions` stays inlined: it runs on every evaluation.
"""

from __future__ import annotations

import math
from typing import Any

import numba
from numba.core import types
from numba.extending import overload

from rbcli.physics.contact.body_phase import body_phase, excluded, place_spheres, whole_grid_hashed
from rbcli.physics.contact.broad_phase import HALF_SHELL, bucket_of, build_grid_of
from rbcli.physics.contact.found import contact_found
from rbcli.physics.contact.manifold import Manifold
from rbcli.physics.contact.narrow import pair_candidates, pair_candidates_threaded
from rbcli.physics.contact.primitive_search import primitive_pairs
from rbcli.physics.contact.primitives import primitive_plane
from rbcli.physics.contact.tables import ACTIVE_PLANE, PLANE_PARTNER_BASE, SWEEP_SPHERES
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL

_OPTIONS: Any = STEP_KERNEL  # typed Any: numba's stubs type jit_options as a TypedDict without `_nrt`


@numba.njit(cache=True, inline="always")
def sphere_positions(contact, work, x, q) -> int:  # noqa: ANN001
    """The two-level broad phase's first half (body_phase.py): the bodies whose boxes meet another's or
    a plane's flagged, and p = x_b + R r0 of their contact spheres into work.sphere_position (no rotation
    for a sphere at its body's centre); the spheres of bodies in body pairs listed for the grid. The
    other spheres keep stale positions: find_contacts reads only flagged ones. Returns the number of
    flagged bodies: with none, find_contacts has nothing to find and its callers skip it."""
    body_phase(contact, work, x, q, work.body_pair)
    place_spheres(contact, work, x, q)
    place_primitives(contact, work, x, q)
    flagged = 0
    for b in range(work.body_active.shape[0]):
        if work.body_active[b]:
            flagged += 1
    return flagged


@separately_compiled
@numba.njit(**STEP_KERNEL)
def find_contacts(contact, work, sink) -> int:  # noqa: ANN001
    """Every contact of the sphere positions in work.sphere_position, plane contacts first (by sphere,
    then plane), then the pairs in walk order, each handed to `contact_found(sink, ...)`; returns the
    candidate pairs tested (distance checks)."""
    plane_contacts(contact, work, sink)
    gridded = work.body_sweep[SWEEP_SPHERES]  # the spheres of bodies in body pairs (sphere_positions)
    tested = pairs_of_bodies(contact, work, sink, gridded, False)  # (narrow.py; -1: the walk runs)
    if tested >= 0:
        return tested
    grid = grid_of_gridded(contact, work, gridded)
    return walk_pairs(contact, work, sink, grid, 0, gridded)


def pairs_of_bodies(contact, work, sink, gridded, threaded) -> int:  # noqa: ANN001
    """The sphere pairs of the body pairs (narrow.py; on threads when `threaded`, a literal) handed to
    the sink in the walk's order; returns the tests made, or -1 when the walk must run instead. Kernels
    only; compiled to -1 where the work has no pair buffers (the body level off), so those scenes
    compile none of it, and for sinks that do not ask for it (class attribute PAIRS_OF_BODIES:
    sink.ContactSink asks, whatever its purpose; the threaded search's record blocks do not). In a scene
    with primitives it first hands on the contacts of the body pairs with a primitive (primitive_search.py),
    whichever way the sphere pairs are then found."""
    raise TypeError("pairs_of_bodies runs in compiled kernels only")


@overload(pairs_of_bodies, jit_options=_OPTIONS, prefer_literal=True)
def _pairs_of_bodies(contact, work, sink, gridded, threaded):  # noqa: ANN001, ANN202
    fields = dict(zip(work.fields, work.types, strict=True))
    found = fields["pair_found"]
    wanted = getattr(getattr(sink, "instance_class", None), "PAIRS_OF_BODIES", False)
    # the body pairs with a primitive go first (primitive_search.py); here, so that a scene without
    # primitives compiles no function for them
    primitives = not isinstance(fields["primitive_centre"], types.NoneType)
    if isinstance(found, types.NoneType) or not wanted:
        if not primitives:
            return lambda contact, work, sink, gridded, threaded: -1

        def primitives_only(contact, work, sink, gridded, threaded):  # noqa: ANN001, ANN202
            primitive_pairs(contact, work, sink)
            return -1

        return primitives_only
    search = pair_candidates_threaded if getattr(threaded, "literal_value", False) else pair_candidates

    def search_and_emit(contact, work, sink, gridded, threaded):  # noqa: ANN001, ANN202
        found = search(contact, work, gridded)
        if found < 0:
            return -1
        emit_pairs(contact, work, sink, 0, found)
        return work.pair_tests[0]

    if not primitives:
        return search_and_emit

    def primitives_then_search(contact, work, sink, gridded, threaded):  # noqa: ANN001, ANN202
        primitive_pairs(contact, work, sink)
        found = search(contact, work, gridded)
        if found < 0:
            return -1
        emit_pairs(contact, work, sink, 0, found)
        return work.pair_tests[0]

    return primitives_then_search


@numba.njit(cache=True, inline="always")
def emit_pairs(contact, work, sink, first, last) -> None:  # noqa: ANN001
    """The contacts first .. last - 1 narrow.pair_candidates found (walker, partner: overlapping),
    handed to the sink as the walk hands them on (d = p_walker - p_partner)."""
    pos, radius, found = work.sphere_position, contact.sphere_radius, work.pair_found
    for r in range(first, last):
        w, p = found[r, 0], found[r, 1]
        d0, d1, d2 = pos[w, 0] - pos[p, 0], pos[w, 1] - pos[p, 1], pos[w, 2] - pos[p, 2]
        _pair(contact, work, sink, w, p, d0, d1, d2, d0 * d0 + d1 * d1 + d2 * d2, radius[w] + radius[p])


@numba.njit(**STEP_KERNEL)
def walk_range(contact, work, sink, grid, first, last) -> int:  # noqa: ANN001
    """`walk_pairs` as a compiled function of its own (the threaded search walks a block again with it)."""
    return walk_pairs(contact, work, sink, grid, first, last)


@numba.njit(cache=True, inline="always")
def grid_of_gridded(contact, work, gridded):  # noqa: ANN001, ANN201
    """The sphere grid over the `gridded` spheres sphere_positions listed (broad_phase.build_grid_of),
    hashed where the grid over every sphere would be (the walk order of the whole kept)."""
    hashed = whole_grid_hashed(contact, work) if gridded and not contact.body_level_off else False
    return build_grid_of(contact, work, gridded, hashed)


@numba.njit(cache=True, inline="always")
def walk_pairs(contact, work, sink, grid, first, last) -> int:  # noqa: ANN001
    """The pairs found by the walkers first .. last - 1 (bucket order) of `grid`, each handed to
    `contact_found(sink, ...)` in walk order; returns the candidate pairs tested (distance checks).

    Each walker looks at the later spheres of its own bucket (its cell) and at every sphere of the 13
    cells of its half shell. In a dense grid those are 5 runs of consecutive buckets (buckets are cells
    row-major): its own cell's later spheres and the cell after it; the row (j + 1, k) from i - 1 to
    i + 1; the rows (j - 1 .. j + 1, k + 1) likewise. Walked as runs they are the same candidates in the
    same order as cell by cell (HALF_SHELL's order is row-major too), with 5 bounds computations in
    place of 14 bucket lookups, most of them of cells holding 0 or 1 sphere. A hashed grid is walked
    cell by cell (a bucket may hold several cells: a candidate of another cell is skipped)."""
    cell, sp, order, start = work.sorted_cell, work.sorted_position, work.sorted_sphere, work.bucket_start
    dense, i0, j0, k0, nx, ny, nz, _ = grid
    runs = 5 if dense else HALF_SHELL.shape[0] + 1
    candidates = 0
    for a in range(first, last):
        ci, cj, ck = cell[a, 0], cell[a, 1], cell[a, 2]
        p0, p1, p2, ra = sp[a, 0], sp[a, 1], sp[a, 2], sp[a, 3]
        i, j, k = ci - i0, cj - j0, ck - k0  # dense: the cell's place in the grid's box
        i_lo = i - 1 if i > 0 else i
        i_hi = i + 1 if i + 1 < nx else i
        # one walk with one call of the pair's code: each call inlines the sink's (the force law), and
        # two copies of it doubled the search's compile time for every sink
        for n in range(runs):
            ni, nj, nk = ci, cj, ck
            if dense:
                if n == 0:  # the own cell's later spheres, then the cell i + 1
                    first_e, last_e = a + 1, start[(k * ny + j) * nx + i_hi + 1]
                else:  # the row (j + 1, k), then the rows (j - 1, k + 1), (j, k + 1), (j + 1, k + 1)
                    rj, rk = (j + 1, k) if n == 1 else (j + n - 3, k + 1)
                    if rj < 0 or rj >= ny or rk >= nz:
                        continue
                    row = (rk * ny + rj) * nx
                    first_e, last_e = start[row + i_lo], start[row + i_hi + 1]
            elif n == 0:  # n = 0: the later spheres of its own bucket
                first_e, last_e = a + 1, start[work.sphere_bucket[order[a]] + 1]
            else:  # the cell n - 1 of the half shell
                ni, nj, nk = ci + HALF_SHELL[n - 1, 0], cj + HALF_SHELL[n - 1, 1], ck + HALF_SHELL[n - 1, 2]
                b = bucket_of(ni, nj, nk, grid)
                first_e, last_e = start[b], start[b + 1]
            for e in range(first_e, last_e):
                # dense: runs of the right cells; hashed: other cells may share the bucket
                if dense or (cell[e, 0] == ni and cell[e, 1] == nj and cell[e, 2] == nk):
                    candidates += 1
                    d0, d1, d2 = p0 - sp[e, 0], p1 - sp[e, 1], p2 - sp[e, 2]
                    reach = ra + sp[e, 3]
                    dist2 = d0 * d0 + d1 * d1 + d2 * d2
                    if dist2 < reach * reach and dist2 > 0.0:  # coincident centres: no normal, skipped
                        _pair(contact, work, sink, order[a], order[e], d0, d1, d2, dist2, reach)
    return candidates


@numba.njit(cache=True, inline="always")
def plane_contacts(contact, work, sink) -> None:  # noqa: ANN001
    """Every sphere against every plane its body's box meets (body_phase.py), spheres in index order and
    planes in theirs for each, as a test of every sphere against every plane would find them."""
    pos = work.sphere_position
    planes = contact.plane_point.shape[0]
    start, active, near = contact.body_sphere_start, work.body_active, work.body_plane
    for b in range(active.shape[0]):
        if not active[b] & ACTIVE_PLANE:
            continue
        if primitive_planes(contact, work, sink, b):  # a shape body touches planes as its primitive
            continue
        for i in range(start[b], start[b + 1]):
            r = contact.sphere_radius[i]
            for p in range(planes):
                if near[b, p] == 0:
                    continue
                n0, n1, n2 = contact.plane_normal[p, 0], contact.plane_normal[p, 1], contact.plane_normal[p, 2]
                dist = (
                    (pos[i, 0] - contact.plane_point[p, 0]) * n0
                    + (pos[i, 1] - contact.plane_point[p, 1]) * n1
                    + (pos[i, 2] - contact.plane_point[p, 2]) * n2
                )
                overlap = r - dist
                if overlap <= 0.0:
                    continue
                back = r - 0.5 * overlap  # contact point: halfway through the overlap
                c0, c1, c2 = pos[i, 0] - back * n0, pos[i, 1] - back * n1, pos[i, 2] - back * n2
                k = contact.body_plane_stiffness[b]
                zeta = min(contact.body_damping_ratio[b], contact.plane_damping_ratio[p])
                mu = contact.body_friction_root[b] * contact.plane_friction_root[p]
                contact_found(sink, contact, work, i, PLANE_PARTNER_BASE - p, b, -1, n0, n1, n2, overlap,
                              c0, c1, c2, k, zeta, mu)  # fmt: skip


def place_primitives(contact, work, x, q) -> None:  # noqa: ANN001
    """The world centre c = x_b + R r0 and rotation R R0 of the primitive of every flagged body (near a
    plane or in a body pair: work.primitive_centre, primitive_frame), once per evaluation. Kernels only;
    compiled to nothing where the work has no primitive arrays (a scene without primitives)."""
    raise TypeError("place_primitives runs in compiled kernels only")


@overload(place_primitives, jit_options=_OPTIONS)
def _place_primitives(contact, work, x, q):  # noqa: ANN001, ANN202
    if isinstance(dict(zip(work.fields, work.types, strict=True))["primitive_centre"], types.NoneType):
        return lambda contact, work, x, q: None

    def place(contact, work, x, q):  # noqa: ANN001, ANN202
        centre, frame = work.primitive_centre, work.primitive_frame
        off, rot = contact.primitive_offset, contact.primitive_rotation
        for b in range(work.body_active.shape[0]):
            if work.body_active[b] == 0 or contact.primitive_kind[b] < 0:  # planes and body pairs read it
                continue
            w, i, j, k = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
            r00, r01, r02 = 1.0 - 2.0 * (j * j + k * k), 2.0 * (i * j - w * k), 2.0 * (i * k + w * j)
            r10, r11, r12 = 2.0 * (i * j + w * k), 1.0 - 2.0 * (i * i + k * k), 2.0 * (j * k - w * i)
            r20, r21, r22 = 2.0 * (i * k - w * j), 2.0 * (j * k + w * i), 1.0 - 2.0 * (i * i + j * j)
            o0, o1, o2 = off[b, 0], off[b, 1], off[b, 2]
            centre[b, 0] = x[b, 0] + r00 * o0 + r01 * o1 + r02 * o2
            centre[b, 1] = x[b, 1] + r10 * o0 + r11 * o1 + r12 * o2
            centre[b, 2] = x[b, 2] + r20 * o0 + r21 * o1 + r22 * o2
            for m in range(3):
                a0, a1, a2 = rot[b, 0, m], rot[b, 1, m], rot[b, 2, m]
                frame[b, 0, m] = r00 * a0 + r01 * a1 + r02 * a2
                frame[b, 1, m] = r10 * a0 + r11 * a1 + r12 * a2
                frame[b, 2, m] = r20 * a0 + r21 * a1 + r22 * a2

    return place


def primitive_planes(contact, work, sink, b) -> bool:  # noqa: ANN001
    """Body b's primitive against each plane its box meets (primitives.primitive_plane), each manifold
    point handed to the sink as a contact of its own: owner the body's sphere start[b] + feature (a history
    row of the shape per feature: its tangential spring persists while the feature touches), partner the
    plane, the body's plane stiffness (per manifold point), the materials mixed as a sphere's. Returns
    False for a body without a primitive (its spheres are tested instead). Kernels only; compiled to False
    where the work has no primitive arrays."""
    raise TypeError("primitive_planes runs in compiled kernels only")


@overload(primitive_planes, jit_options=_OPTIONS)
def _primitive_planes(contact, work, sink, b):  # noqa: ANN001, ANN202
    if isinstance(dict(zip(work.fields, work.types, strict=True))["primitive_centre"], types.NoneType):
        return lambda contact, work, sink, b: False

    def touch(contact, work, sink, b):  # noqa: ANN001, ANN202
        kind = contact.primitive_kind[b]
        if kind < 0:
            return False
        out = Manifold(work.manifold_point, work.manifold_normal, work.manifold_depth, work.manifold_feature)
        c, R, size = work.primitive_centre[b], work.primitive_frame[b], contact.primitive_size[b]
        first = contact.body_sphere_start[b]
        for p in range(contact.plane_point.shape[0]):
            if work.body_plane[b, p] == 0:
                continue
            count = primitive_plane(kind, c, R, size, contact.plane_point[p], contact.plane_normal[p], out)
            if count == 0:
                continue
            k = contact.body_plane_stiffness[b]
            zeta = min(contact.body_damping_ratio[b], contact.plane_damping_ratio[p])
            mu = contact.body_friction_root[b] * contact.plane_friction_root[p]
            for i in range(count):
                contact_found(sink, contact, work, first + out.feature[i], PLANE_PARTNER_BASE - p, b, -1,
                              out.normal[i, 0], out.normal[i, 1], out.normal[i, 2], out.depth[i],
                              out.point[i, 0], out.point[i, 1], out.point[i, 2], k, zeta, mu)  # fmt: skip
        return True

    return touch


@numba.njit(cache=True, inline="always")
def _pair(contact, work, sink, i, j, d0, d1, d2, dist2, reach) -> None:  # noqa: ANN001
    """The contact of spheres i and j, overlapping (d = p_i - p_j, |d|^2 = dist2 < reach^2)."""
    pos = work.sphere_position
    bi, bj = contact.sphere_body[i], contact.sphere_body[j]
    if bi == bj:
        return
    if contact.body_inv_contact_mass[bi] == 0.0 and contact.body_inv_contact_mass[bj] == 0.0:
        return
    if contact.excluded_pair.shape[0] and excluded(contact, bi, bj):
        return
    if j < i:  # the owner is the lower index: one history per pair whichever sphere found it
        i, j, bi, bj = j, i, bj, bi
        d0, d1, d2 = -d0, -d1, -d2
    dist = math.sqrt(dist2)
    overlap = reach - dist
    n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist
    forward = contact.sphere_radius[j] - 0.5 * overlap
    c0, c1, c2 = pos[j, 0] + forward * n0, pos[j, 1] + forward * n1, pos[j, 2] + forward * n2
    ka, kb = contact.body_stiffness[bi], contact.body_stiffness[bj]
    k = ka if ka == kb else 2.0 * ka * kb / (ka + kb)
    zeta = min(contact.body_damping_ratio[bi], contact.body_damping_ratio[bj])
    mu = contact.body_friction_root[bi] * contact.body_friction_root[bj]
    contact_found(sink, contact, work, i, j, bi, bj, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu)
