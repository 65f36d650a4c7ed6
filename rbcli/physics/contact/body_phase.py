"""The body level of the two-level broad phase (issue 28 item 2): which bodies can touch each other or a
plane, before any contact sphere is placed in the world.

    1. bounds: each colliding body's world box, the intersection of two boxes that hold all its
       contact spheres (radii included): its body-frame box of the spheres turned into the world,
       centre x + R c and half extents |R| e (|R|: elementwise absolute), and the cube of half side
       rho_max = max |offset| + r about its centre of mass (tight for a ball, whatever its rotation);
       padded by 1e-9 rho_max so a rounding of R cannot leave a sphere outside;
    2. body pairs by a hashed grid over bodies (the sphere grid's counting sort, broad_phase.py, one
       level up): cells as wide as the largest bound diameter 2 rho_max of the regular bodies, each body
       in the cell of its box centre, each tested against the later bodies of its cell and those of the
       13 cells of its half shell (two boxes that overlap have centres less than one cell apart on
       every axis); bodies more than LARGE_BODY times the median rho_max (a static slab among pebbles)
       would make every cell hold everything, so they are kept out of the grid and tested against
       every body. A pair of two bodies of infinite contact mass (static or kinematic) is skipped:
       their contact would change nothing. (Sort-and-sweep was tried first: in a pile shaped like a cube
       of n bodies a body's window along the sweep axis holds n^(2/3) bodies, some 1,800 of the
       10^5-ball pile: estimated, not run.)
       More than a few bodies keep their pairs between evaluations (`kept_box_pairs`): the pairs of their
       boxes padded by a tenth of a cell, found by the same grid, are tested again at each evaluation
       until a body leaves its padded box (a settled heap of 200 bodies: ~1,400 box tests a few ns each
       instead of a walk of ~4,400 at ~15 ns); the pairs go on in the bodies' order whichever way they
       were found, so no step depends on when they were kept.
    3. body-plane pairs: a box meets the half-space n . (p - p0) <= 0 when n . (c - p0) - |n| . h <= 0.
    4. once its spheres are placed (`place_spheres`), the box of a cloud in a body pair is shrunk to the
       box of its spheres (p +- r, padded as in step 1): the narrow phase (narrow.py) tests each body's
       spheres against the other's box, and a turned body's box from step 1 holds far more than its
       spheres (container_mix's tetrahedra: 8,200 sphere pair tests an evaluation, 3,300 with the
       spheres' boxes). Every sphere stays in its body's box, so every step after it finds the same.

A scene of bodies of about one sphere each (spheres <= 2 bodies: a pile of balls) skips steps 1-3: the
sphere grid is then a grid of the bodies already, and the body level only added its own cost (the
1,000-ball pile ran 2.5x slower with it); every body is flagged, every sphere tested against every plane.

Bodies in a body pair are flagged in `body_active` (bit 0), and each plane a body may touch in
`body_plane`; the sphere level (force.py) then places only the spheres of flagged bodies, tests plane
contacts only for flagged body-plane pairs, and builds the sphere grid only over bodies in body pairs:
every overlapping sphere pair of different bodies lies in a body pair (its spheres lie in both boxes),
so that grid finds exactly the contacts the grid over all spheres finds, in the same order where both
grids are dense (broad_phase.py: a dense grid orders spheres by cell, row-major, then by index, whatever
its origin; a subset of a dense box is dense).

Work: O(n + buckets) per evaluation for n bodies, plus the box tests of the grid's candidates (counted:
flat per body from 10^3 to 10^5 bodies at one density, tested), plus n per large body. No allocation:
the arrays are ContactWork's.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.contact.broad_phase import _PRIME_X, _PRIME_Y, _PRIME_Z, HALF_SHELL, _cell
from rbcli.physics.contact.tables import (
    ACTIVE_PAIR,
    ACTIVE_PLANE,
    FAT_AGE,
    FAT_PAIRS,
    FAT_WAIT,
    SWEEP_CHECKS,
    SWEEP_PAIRS,
    SWEEP_SPHERES,
)
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.rotation_kernels import rotate
from rbcli.physics.step import STEP_KERNEL

_FEW_BODIES = 8  # up to this many bodies every pair is tested (28 box tests): less than setting up the grid
_BOX_PAD = 1e-9  # of rho_max: far above R's rounding (~1e-16 rho), far below any contact's overlap


@numba.njit(cache=True, inline="always")
def _bounds(contact, work, x, q) -> None:  # noqa: ANN001
    """World box of every body (module docstring, step 1)."""
    lo, hi = work.body_lo, work.body_hi
    centre, half, rho = contact.body_box_centre, contact.body_box_half, contact.body_bound_radius
    for b in range(lo.shape[0]):
        if not rho[b] >= 0.0:  # no contact spheres: an empty box, never overlapping
            for k in range(3):
                lo[b, k], hi[b, k] = math.inf, -math.inf
            continue
        w, i, j, k = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        # R of the unit quaternion (w, i, j, k), rows r0, r1, r2
        r00, r01, r02 = 1.0 - 2.0 * (j * j + k * k), 2.0 * (i * j - w * k), 2.0 * (i * k + w * j)
        r10, r11, r12 = 2.0 * (i * j + w * k), 1.0 - 2.0 * (i * i + k * k), 2.0 * (j * k - w * i)
        r20, r21, r22 = 2.0 * (i * k - w * j), 2.0 * (j * k + w * i), 1.0 - 2.0 * (i * i + j * j)
        c0, c1, c2 = centre[b, 0], centre[b, 1], centre[b, 2]
        e0, e1, e2 = half[b, 0], half[b, 1], half[b, 2]
        pad = _BOX_PAD * rho[b]
        m0 = x[b, 0] + r00 * c0 + r01 * c1 + r02 * c2
        m1 = x[b, 1] + r10 * c0 + r11 * c1 + r12 * c2
        m2 = x[b, 2] + r20 * c0 + r21 * c1 + r22 * c2
        h0 = abs(r00) * e0 + abs(r01) * e1 + abs(r02) * e2
        h1 = abs(r10) * e0 + abs(r11) * e1 + abs(r12) * e2
        h2 = abs(r20) * e0 + abs(r21) * e1 + abs(r22) * e2
        s = rho[b] + pad
        lo[b, 0] = max(m0 - h0 - pad, x[b, 0] - s)
        lo[b, 1] = max(m1 - h1 - pad, x[b, 1] - s)
        lo[b, 2] = max(m2 - h2 - pad, x[b, 2] - s)
        hi[b, 0] = min(m0 + h0 + pad, x[b, 0] + s)
        hi[b, 1] = min(m1 + h1 + pad, x[b, 1] + s)
        hi[b, 2] = min(m2 + h2 + pad, x[b, 2] + s)


@numba.njit(cache=True, inline="always")
def body_phase(contact, work, x, q, pairs) -> int:  # noqa: ANN001
    """Steps 1-3 of the module docstring for the state (x, q): flags in work.body_active and
    work.body_plane, counts in work.body_sweep; the body pairs (a < b, each once) are also written to
    `pairs` (capacity, 2) up to its capacity (search.sphere_positions passes work.body_pair, whose pairs
    narrow.py searches; 0 rows where the body level is off). Returns the pair count."""
    active, near = work.body_active, work.body_plane
    inv_mass = contact.body_inv_contact_mass
    if contact.body_level_off:  # bodies of about one sphere: the sphere grid is the body grid already
        start = contact.body_sphere_start
        for b in range(active.shape[0]):
            movable = inv_mass[b] != 0.0 and start[b + 1] > start[b]
            active[b] = (ACTIVE_PAIR if start[b + 1] > start[b] else 0) | (ACTIVE_PLANE if movable else 0)
            near[b, :] = 1 if movable else 0
        work.body_sweep[SWEEP_PAIRS] = 0
        work.body_sweep[SWEEP_CHECKS] = 0
        return 0
    _bounds(contact, work, x, q)
    lo, hi = work.body_lo, work.body_hi
    active[:] = 0
    # body-plane pairs
    planes = contact.plane_point.shape[0]
    for b in range(lo.shape[0]):
        if not lo[b, 0] <= hi[b, 0] or inv_mass[b] == 0.0:
            continue
        c0, c1, c2 = 0.5 * (lo[b, 0] + hi[b, 0]), 0.5 * (lo[b, 1] + hi[b, 1]), 0.5 * (lo[b, 2] + hi[b, 2])
        h0, h1, h2 = 0.5 * (hi[b, 0] - lo[b, 0]), 0.5 * (hi[b, 1] - lo[b, 1]), 0.5 * (hi[b, 2] - lo[b, 2])
        for p in range(planes):
            if box_clearance(contact, p, c0, c1, c2, h0, h1, h2) <= 0.0:
                near[b, p] = 1
                active[b] |= ACTIVE_PLANE
            else:
                near[b, p] = 0
    # body pairs: every pair of a few bodies, else those of the pairs kept from an earlier evaluation (or
    # of the hashed grid of body box centres) whose boxes meet
    if lo.shape[0] <= _FEW_BODIES:
        count, checks = box_pairs(
            inv_mass, contact.body_large, contact.excluded_pair, lo, hi, contact.body_cell_size, active,
            work.body_cell, work.body_bucket, work.body_bucket_start, work.body_sorted, pairs, True,
        )  # fmt: skip
    else:
        count, checks = kept_box_pairs(
            inv_mass, contact.body_large, contact.excluded_pair, lo, hi, contact.body_cell_size, active,
            work.body_cell, work.body_bucket, work.body_bucket_start, work.body_sorted, pairs,
            work.fat_lo, work.fat_hi, work.fat_pair, work.fat_found, work.fat_start, work.fat_active,
            work.fat_state,
        )  # fmt: skip
    work.body_sweep[SWEEP_PAIRS] = count
    work.body_sweep[SWEEP_CHECKS] = checks
    return count


@numba.njit(cache=True, inline="always")
def box_clearance(contact, p, c0, c1, c2, h0, h1, h2) -> float:  # noqa: ANN001
    """How far [m] the box of centre c and half extents h lies above plane p along its normal: the
    height of its lowest corner (<= 0: the box meets the plane or lies beyond it)."""
    n0, n1, n2 = contact.plane_normal[p, 0], contact.plane_normal[p, 1], contact.plane_normal[p, 2]
    return (
        (c0 - contact.plane_point[p, 0]) * n0
        + (c1 - contact.plane_point[p, 1]) * n1
        + (c2 - contact.plane_point[p, 2]) * n2
        - (abs(n0) * h0 + abs(n1) * h1 + abs(n2) * h2)
    )


@numba.njit(cache=True, inline="always")
def bodies_meet(inv_mass, excluded_pair, lo, hi, a, b, flag) -> bool:  # noqa: ANN001
    """Whether the boxes of bodies a and b overlap on all three axes and one of them can move; flag
    False (quiet.py): also False for a pair that never collides (ContactTable.excluded_pair)."""
    meet = (
        lo[b, 0] <= hi[a, 0]
        and lo[a, 0] <= hi[b, 0]
        and lo[b, 1] <= hi[a, 1]
        and lo[a, 1] <= hi[b, 1]
        and lo[b, 2] <= hi[a, 2]
        and lo[a, 2] <= hi[b, 2]
        and (inv_mass[a] != 0.0 or inv_mass[b] != 0.0)
    )
    if meet and not flag and excluded_pair.shape[0]:
        meet = not excluded_key(excluded_pair, inv_mass.shape[0], a, b)
    return meet


@numba.njit(cache=True, inline="always")
def _boxes_meet(lo, hi, a, b) -> bool:  # noqa: ANN001
    """Whether the boxes of bodies a and b overlap on all three axes (every comparison made: no branch)."""
    return (
        (lo[b, 0] <= hi[a, 0]) & (lo[a, 0] <= hi[b, 0])
        & (lo[b, 1] <= hi[a, 1]) & (lo[a, 1] <= hi[b, 1])
        & (lo[b, 2] <= hi[a, 2]) & (lo[a, 2] <= hi[b, 2])
    )  # fmt: skip


@numba.njit(cache=True, inline="always")
def excluded(contact, bi, bj) -> bool:  # noqa: ANN001
    """Whether bodies bi and bj never collide (two bodies of a joint: ContactTable.excluded_pair)."""
    return excluded_key(contact.excluded_pair, contact.body_inv_contact_mass.shape[0], bi, bj)


@numba.njit(cache=True, inline="always")
def excluded_key(keys, body_count, bi, bj) -> bool:  # noqa: ANN001
    """`excluded` on the sorted keys min * body_count + max, by a binary search."""
    key = min(bi, bj) * body_count + max(bi, bj)
    k = np.searchsorted(keys, key)
    return k < keys.shape[0] and keys[k] == key


# a function of its own, not inlined: the body phase runs it once per evaluation (a call is nothing
# beside it), and inlined into the force stage, the recorded statistics and quiet.py's try it made each
# contact loop compile ~3 s longer per copy (numba's compile events)
@separately_compiled
@numba.njit(**STEP_KERNEL)
def box_pairs(inv_mass, large, excluded_pair, lo, hi, cell_size, active, cell, bucket, start, order, pairs, flag):  # noqa: ANN001, ANN201
    """Step 2 of the module docstring for the boxes (lo, hi) (empty: lo > hi), boxes of half extent at
    most cell_size / 2 but for the `large` bodies: (pairs found, box tests). flag True: each body of a
    pair flagged ACTIVE_PAIR in `active` and the pairs (a < b) written to `pairs` up to its capacity;
    False (quiet.py): nothing written, pairs that never collide (excluded_pair) skipped, and the search
    stops at the first pair (returns 1). cell, bucket, start, order: the grid's scratch (ContactWork's
    body_cell, body_bucket, body_bucket_start, body_sorted)."""
    n = lo.shape[0]
    count = 0
    if n <= _FEW_BODIES:
        for a in range(n):
            if not lo[a, 0] <= hi[a, 0]:
                continue
            for b in range(a + 1, n):
                if lo[b, 0] <= hi[b, 0] and bodies_meet(inv_mass, excluded_pair, lo, hi, a, b, flag):
                    if not flag:
                        return 1, n * (n - 1) // 2
                    active[a] |= ACTIVE_PAIR
                    active[b] |= ACTIVE_PAIR
                    if count < pairs.shape[0]:
                        pairs[count, 0], pairs[count, 1] = min(a, b), max(a, b)
                    count += 1
        return count, n * (n - 1) // 2
    inv_size = 1.0 / cell_size
    mask = np.int64(start.shape[0] - 2)  # buckets - 1, buckets a power of two
    start[:] = 0
    for b in range(n):
        if not lo[b, 0] <= hi[b, 0] or large[b]:
            bucket[b] = -1
            continue
        c0 = _cell(0.5 * (lo[b, 0] + hi[b, 0]), inv_size)
        c1 = _cell(0.5 * (lo[b, 1] + hi[b, 1]), inv_size)
        c2 = _cell(0.5 * (lo[b, 2] + hi[b, 2]), inv_size)
        cell[b, 0], cell[b, 1], cell[b, 2] = c0, c1, c2
        k = _hash(c0, c1, c2, mask)
        bucket[b] = k
        start[k] += 1
    running = 0
    for k in range(start.shape[0] - 1):  # inclusive prefix sum: start[k] = end of bucket k
        running += start[k]
        start[k] = running
    start[start.shape[0] - 1] = running
    for b in range(n - 1, -1, -1):
        k = bucket[b]
        if k >= 0:
            start[k] -= 1
            order[start[k]] = b
    checks = 0
    for s in range(running):
        a = order[s]
        ci, cj, ck = cell[a, 0], cell[a, 1], cell[a, 2]
        for m in range(-1, HALF_SHELL.shape[0]):
            if m < 0:  # the later bodies of its own bucket
                first, last, ni, nj, nk = s + 1, start[bucket[a] + 1], ci, cj, ck
            else:
                ni, nj, nk = ci + HALF_SHELL[m, 0], cj + HALF_SHELL[m, 1], ck + HALF_SHELL[m, 2]
                k = _hash(ni, nj, nk, mask)
                first, last = start[k], start[k + 1]
            for e in range(first, last):
                b = order[e]
                own = (cell[b, 0] == ni) & (cell[b, 1] == nj) & (cell[b, 2] == nk)  # else: another cell's
                checks += own
                if flag:
                    # without a branch on the outcome, which the predictor loses (a third of a pile's
                    # checks meet): the flags or'ed with 0 or ACTIVE_PAIR, the pair written and counted
                    # or left to be overwritten
                    meet = own & _boxes_meet(lo, hi, a, b) & ((inv_mass[a] != 0.0) | (inv_mass[b] != 0.0))
                    mark = ACTIVE_PAIR if meet else 0
                    active[a] |= mark
                    active[b] |= mark
                    if count < pairs.shape[0]:
                        pairs[count, 0], pairs[count, 1] = min(a, b), max(a, b)
                    count += meet
                elif own and bodies_meet(inv_mass, excluded_pair, lo, hi, a, b, flag):
                    return 1, checks
    for a in range(n):  # large bodies against every body (large pairs once)
        if not large[a] or not lo[a, 0] <= hi[a, 0]:
            continue
        for b in range(n):
            if b == a or not lo[b, 0] <= hi[b, 0] or (large[b] and b < a):
                continue
            checks += 1
            if bodies_meet(inv_mass, excluded_pair, lo, hi, a, b, flag):
                if not flag:
                    return 1, checks
                active[a] |= ACTIVE_PAIR
                active[b] |= ACTIVE_PAIR
                if count < pairs.shape[0]:
                    pairs[count, 0], pairs[count, 1] = min(a, b), max(a, b)
                count += 1
    return count, checks


# kept body pairs (kept_box_pairs): each body's box padded by this fraction of the body cell, so a resting
# or slowly moving heap finds its pairs again only when a body has moved that far (Box2D's "fat" boxes of
# its dynamic tree, b2_aabbMargin, and Bullet's dbvt margins keep pairs the same way)
_PAD = 0.1
# pairs kept for fewer evaluations than this before a body left its padded box: the bodies move faster
# than the pad pays for; the tight boxes are walked for _WAIT evaluations before pairs are kept again
_SHORTEST_KEEP, _WAIT = 4, 64


@separately_compiled
@numba.njit(**STEP_KERNEL)
def kept_box_pairs(inv_mass, large, excluded_pair, lo, hi, cell_size, active, cell, bucket, start, order, pairs,  # noqa: ANN001, ANN201
                   fat_lo, fat_hi, fat_pair, fat_found, fat_start, fat_active, fat_state):  # fmt: skip
    """box_pairs' answer (pairs found, box tests) for more than _FEW_BODIES bodies, the pairs written in
    ascending (a, b) order, from pairs kept between evaluations: while every body's box lies inside its
    box padded by _PAD body cells when the pairs were kept (fat_lo, fat_hi), every pair of boxes that
    meet now is among the kept pairs of padded boxes that met then, so testing the kept pairs (a few ns
    each) replaces the grid walk (~15 ns a box test and ~100 ns a body: profiled on a settled
    container of 200 bodies, where the walk was a fifth of the step). A body outside its padded box:
    the padded boxes and their pairs are found again (box_pairs on them, with cells wider by the pads).
    The order is that of the bodies, not of the grid, so the pairs handed on (and every sum over them)
    do not depend on when they were kept: a resumed run, whose kept pairs start empty, steps bitwise
    as the uninterrupted one (the kept arrays are not carried). Where keeping does not pay (pairs kept
    fewer than _SHORTEST_KEEP evaluations) or does not fit (more padded pairs than fat_found holds),
    the tight boxes are walked, and their pairs sorted into the same order."""
    n = lo.shape[0]
    kept = fat_state[FAT_PAIRS] >= 0
    if kept:
        for b in range(n):
            inside = (
                (lo[b, 0] >= fat_lo[b, 0]) & (lo[b, 1] >= fat_lo[b, 1]) & (lo[b, 2] >= fat_lo[b, 2])
                & (hi[b, 0] <= fat_hi[b, 0]) & (hi[b, 1] <= fat_hi[b, 1]) & (hi[b, 2] <= fat_hi[b, 2])
            )  # fmt: skip
            if not inside and lo[b, 0] <= hi[b, 0]:
                kept = False
                break
    checks = 0
    if not kept:
        if fat_state[FAT_PAIRS] >= 0 and fat_state[FAT_AGE] < _SHORTEST_KEEP:
            fat_state[FAT_WAIT] = _WAIT
        fat_state[FAT_PAIRS] = -1
        if fat_state[FAT_WAIT] > 0:
            fat_state[FAT_WAIT] -= 1
        else:
            pad = _PAD * cell_size
            for b in range(n):
                for k in range(3):
                    fat_lo[b, k], fat_hi[b, k] = lo[b, k] - pad, hi[b, k] + pad
            found, checks = box_pairs(inv_mass, large, excluded_pair, fat_lo, fat_hi, cell_size + 2.0 * pad,
                                      fat_active, cell, bucket, start, order, fat_found, True)  # fmt: skip
            if found <= fat_found.shape[0]:
                _sort_pairs(fat_found, found, fat_start, fat_pair)
                fat_state[FAT_PAIRS], fat_state[FAT_AGE] = found, 0
            else:  # too many to keep: walk the tight boxes for a while
                fat_state[FAT_WAIT] = _WAIT
    if fat_state[FAT_PAIRS] < 0:  # the tight boxes walked, their pairs in the same order
        found, walked = box_pairs(inv_mass, large, excluded_pair, lo, hi, cell_size, active, cell, bucket,
                                  start, order, fat_found, True)  # fmt: skip
        if found <= fat_found.shape[0] and found <= pairs.shape[0]:
            _sort_pairs(fat_found, found, fat_start, pairs)
        else:  # more than the buffer holds: its users take every pair themselves (primitive_search.py)
            found, walked = box_pairs(inv_mass, large, excluded_pair, lo, hi, cell_size, active, cell, bucket,
                                      start, order, pairs, True)  # fmt: skip
        return found, checks + walked
    fat_state[FAT_AGE] += 1
    count = 0
    for p in range(fat_state[FAT_PAIRS]):
        a, b = fat_pair[p, 0], fat_pair[p, 1]
        meet = _boxes_meet(lo, hi, a, b) & ((inv_mass[a] != 0.0) | (inv_mass[b] != 0.0))
        mark = ACTIVE_PAIR if meet else 0  # without a branch on the outcome (box_pairs says why)
        active[a] |= mark
        active[b] |= mark
        if count < pairs.shape[0]:
            pairs[count, 0], pairs[count, 1] = a, b
        count += meet
    return count, checks + fat_state[FAT_PAIRS]


@numba.njit(**STEP_KERNEL)
def _sort_pairs(found, count, start, out) -> None:  # noqa: ANN001
    """The pairs (a < b) found[:count] into out[:count] in ascending (a, b): counted by a (start: one
    more than the bodies), then each body's few partners sorted by insertion."""
    start[:] = 0
    for p in range(count):
        start[found[p, 0] + 1] += 1
    for a in range(1, start.shape[0]):
        start[a] += start[a - 1]
    for p in range(count):  # start[a] moves from the first slot of a's pairs to one past its last
        a = found[p, 0]
        out[start[a], 0], out[start[a], 1] = a, found[p, 1]
        start[a] += 1
    begin = 0
    for a in range(start.shape[0] - 1):
        end = start[a]
        for p in range(begin + 1, end):
            b = out[p, 1]
            slot = p
            while slot > begin and out[slot - 1, 1] > b:
                out[slot, 1] = out[slot - 1, 1]
                slot -= 1
            out[slot, 1] = b
        begin = end


def body_pairs_numpy(lo: np.ndarray, hi: np.ndarray, inv_mass: np.ndarray) -> set[tuple[int, int]]:
    """Reference: every pair (a < b) of boxes that overlap on all three axes, not both of infinite
    contact mass, by brute force O(n^2) (tests)."""
    overlap = np.all((lo[:, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[:, None, :]), axis=-1)
    overlap &= ~((inv_mass[:, None] == 0.0) & (inv_mass[None, :] == 0.0))
    a, b = np.nonzero(np.triu(overlap, k=1))
    return set(zip(a.tolist(), b.tolist(), strict=True))


@numba.njit(cache=True, inline="always")
def _hash(ci, cj, ck, mask):  # noqa: ANN001, ANN202
    return ((ci * _PRIME_X) ^ (cj * _PRIME_Y) ^ (ck * _PRIME_Z)) & mask


@numba.njit(cache=True, inline="always")
def place_spheres(contact, work, x, q) -> int:  # noqa: ANN001
    """World positions p = x_b + R r0 of the spheres of every flagged body (force._sphere_positions'
    formula, so the same bits), and the spheres of bodies in body pairs listed in work.active_sphere
    (ascending: bodies ascending, their spheres grouped), their body's box shrunk to them (module
    docstring, step 4); returns how many were listed."""
    pos, off, start = work.sphere_position, contact.sphere_offset, contact.body_sphere_start
    listed, lo, hi, radius = work.active_sphere, work.body_lo, work.body_hi, contact.sphere_radius
    count = 0
    for b in range(work.body_active.shape[0]):
        flags = work.body_active[b]
        if flags == 0 or contact.primitive_kind[b] >= 0:  # a primitive's spheres touch nothing (primitive_search.py)
            continue
        # the box of the spheres (step 4), for a cloud in a body pair (a box test per pair follows)
        shrink = (flags & ACTIVE_PAIR) != 0 and start[b + 1] - start[b] > 1
        l0 = l1 = l2 = math.inf
        h0 = h1 = h2 = -math.inf
        for i in range(start[b], start[b + 1]):
            o0, o1, o2 = off[i, 0], off[i, 1], off[i, 2]
            if o0 == 0.0 and o1 == 0.0 and o2 == 0.0:
                pos[i, 0], pos[i, 1], pos[i, 2] = x[b, 0], x[b, 1], x[b, 2]
            else:
                r0, r1, r2 = rotate(q[b, 0], q[b, 1], q[b, 2], q[b, 3], o0, o1, o2)
                pos[i, 0], pos[i, 1], pos[i, 2] = x[b, 0] + r0, x[b, 1] + r1, x[b, 2] + r2
            if flags & ACTIVE_PAIR:
                listed[count] = i
                count += 1
            if shrink:
                r = radius[i]
                l0, l1, l2 = min(l0, pos[i, 0] - r), min(l1, pos[i, 1] - r), min(l2, pos[i, 2] - r)
                h0, h1, h2 = max(h0, pos[i, 0] + r), max(h1, pos[i, 1] + r), max(h2, pos[i, 2] + r)
        if shrink and l0 <= h0 and l1 <= h1 and l2 <= h2:  # (NaN: the box of step 1 stays)
            pad = _BOX_PAD * contact.body_bound_radius[b]
            lo[b, 0], lo[b, 1], lo[b, 2] = max(lo[b, 0], l0 - pad), max(lo[b, 1], l1 - pad), max(lo[b, 2], l2 - pad)
            hi[b, 0], hi[b, 1], hi[b, 2] = min(hi[b, 0], h0 + pad), min(hi[b, 1], h1 + pad), min(hi[b, 2], h2 + pad)
    work.body_sweep[SWEEP_SPHERES] = count
    return count


@numba.njit(cache=True, inline="always")
def whole_grid_hashed(contact, work) -> bool:  # noqa: ANN001
    """Whether broad_phase.build_grid over every sphere would hash, judged from the body boxes (O(bodies)):
    sphere centres lie at least the smallest radius inside their body's box, so the cells of the boxes'
    union shrunk by it hold every centre's cell. The estimate is never denser than the truth, and equals it
    unless the spheres' cell box sits within a cell of the dense limit (4 cells per sphere)."""
    lo, hi = work.body_lo, work.body_hi
    l0 = l1 = l2 = math.inf
    h0 = h1 = h2 = -math.inf
    for b in range(lo.shape[0]):
        if lo[b, 0] <= hi[b, 0]:
            l0, l1, l2 = min(l0, lo[b, 0]), min(l1, lo[b, 1]), min(l2, lo[b, 2])
            h0, h1, h2 = max(h0, hi[b, 0]), max(h1, hi[b, 1]), max(h2, hi[b, 2])
    if not l0 <= h0:
        return False
    inv, r = 1.0 / contact.cell_size, contact.sphere_radius_min
    nx = _cell(h0 - r, inv) - _cell(l0 + r, inv) + 1
    ny = _cell(h1 - r, inv) - _cell(l1 + r, inv) + 1
    nz = _cell(h2 - r, inv) - _cell(l2 + r, inv) + 1
    buckets = contact.bucket_count
    return not (nx <= buckets and ny <= buckets and nz <= buckets and nx * ny <= buckets and nx * ny * nz <= buckets)
