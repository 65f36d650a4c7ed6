"""The sphere pairs of the body pairs: the contacts the sphere grid's walk finds (search.walk_pairs),
found from the body level's pairs instead and then put in the walk's order, for scenes of bodies of
many spheres (issue 28: the cloud pile).

Why: in a pile of 13-sphere clouds the walk tests ~50 candidates per sphere (its half shell holds
~14 cells of ~3.6 spheres), most of them spheres of its own body (42,000 overlapping pairs of one body
per evaluation, against ~3,200 contacts) or of bodies it cannot reach: 643,000 distance checks, ~2.6 ms
of a ~3.3 ms step. The body level already knows which bodies' boxes meet (body_phase.py). For each such
pair (A, B), only the spheres of A whose box meets B's box can touch a sphere of B, and the other way
round (B's spheres lie in B's box, padded against rounding), so testing those against each other finds
every contact between A and B: ~220,000 tests for the pile (130,000 of a sphere against a box).

The walk's order is kept, so every sum is the same and the bits too. In a dense grid (the only one this
path takes; a hashed grid is walked) the walk hands on the pairs of sphere a and e, a before e in the
bucket order (cell row-major, then sphere index), sorted by a, then by e: a sphere's half shell lies
after its cell, run after run (search.walk_pairs). So each contact here gets the key (bucket, index) of
its earlier sphere (the walker) and of its later one, and the contacts are sorted by both (a radix sort
by the walker's key, then each walker's few partners by theirs) before any is handed to the sink, with
d = p_walker - p_partner exactly as the walk computes it. Nothing is handed on until every pair is
found, so the walk can still be taken (`pair_candidates` returns -1) when the buffers would overflow
or the body pairs' tests would cost more than the walk's.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.contact.body_phase import whole_grid_hashed
from rbcli.physics.contact.broad_phase import _cell
from rbcli.physics.contact.tables import SWEEP_PAIRS
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL

# The pair path gives way to the walk when its tests would cost more than the walk's estimated ones: the
# walk checks the ~13.5 cells of each sphere's half shell, at least gridded / cells spheres each on
# average (more where spheres cluster: ~50 checks per sphere of a cloud pile against this estimate's
# 20); a sphere-against-box test counts as half a check (narrow._pairs_of)
HALF_SHELL_CELLS = 13.5
_RADIX_BITS = 11
_INSERTION_SORT = 64  # contacts up to this many are sorted by insertion (n^2 / 4 moves against the radix passes)
_TAME = 2.0**62  # |p / cell size| below this: a cell index that fits, monotonic in p (broad_phase._cell)
_CULL = 1.0 + 1e-6  # a sphere's radius in the box test, widened far beyond any rounding of p +- r


@separately_compiled
@numba.njit(**STEP_KERNEL)
def pair_candidates(contact, work, gridded) -> int:  # noqa: ANN001
    """The overlapping sphere pairs of the body pairs in work.body_pair, sorted in the walk's order into
    work.pair_found[:n] (walker, partner), and the tests made (the candidates) in work.pair_tests[0];
    returns n, or -1 when the walk must be taken instead (the grid would be hashed, a buffer is too
    small, or the pairs' tests would cost more than the walk's estimated checks)."""
    pairs = work.body_sweep[SWEEP_PAIRS]
    ready, grid, budget = _prepare(contact, work, gridded, pairs)
    if ready <= 0:
        return ready
    side, near = work.pair_side, work.pair_near
    n, tests, spent = _pairs_of(contact, work, grid, 0, pairs, side[0, 0], side[0, 1], near[0], 0,
                                work.pair_found.shape[0], budget)  # fmt: skip
    if n < 0:
        return -1
    work.pair_tests[0] = tests
    _sort(work, n)
    return n


@numba.njit(**STEP_KERNEL, parallel=True)
def pair_candidates_threaded(contact, work, gridded) -> int:  # noqa: ANN001
    """`pair_candidates` with the body pairs split into one run per row of work.pair_side, searched on
    numba's threads, each into its own share of pair_found; the contacts are then gathered in run order
    and sorted as there, so the result is the same (every contact has its own pair of keys)."""
    pairs = work.body_sweep[SWEEP_PAIRS]
    ready, grid, budget = _prepare(contact, work, gridded, pairs)
    if ready <= 0:
        return ready
    side, near, tally, found, keys = work.pair_side, work.pair_near, work.pair_tally, work.pair_found, work.pair_key
    runs = side.shape[0]
    share = found.shape[0] // runs
    for run in numba.prange(runs):
        n, tests, spent = _pairs_of(contact, work, grid, run * pairs // runs, (run + 1) * pairs // runs,
                                    side[run, 0], side[run, 1], near[run], run * share, share, budget)  # fmt: skip
        tally[run, 0], tally[run, 1], tally[run, 2] = n, tests, spent
    n, tests, spent = 0, 0, 0
    for run in range(runs):
        if tally[run, 0] < 0:
            return -1
        spent += tally[run, 2]
        for r in range(run * share, run * share + tally[run, 0]):  # gathered in run order
            found[n, 0], found[n, 1], keys[n, 0], keys[n, 1] = found[r, 0], found[r, 1], keys[r, 0], keys[r, 1]
            n += 1
        tests += tally[run, 1]
    if spent > budget:
        return -1
    work.pair_tests[0] = tests
    _sort(work, n)
    return n


@numba.njit(cache=True, inline="always")
def _prepare(contact, work, gridded, pairs):  # noqa: ANN001, ANN202
    """What both searches check first: (1, the dense grid's tuple, the budget) to search; -1 when the
    walk must run (a buffer too small, the grid hashed); 0 when no sphere is gridded (only plane
    contacts: no pair to find, and no grid box to size a budget by). The budget is the walk's estimated
    checks in the units of `_pairs_of`'s cost (half a check)."""
    if pairs > work.body_pair.shape[0] or work.pair_found.shape[0] == 0:
        return -1, (False, 0, 0, 0, 0, 0, 0, np.int64(0)), np.int64(0)  # no grid built
    if gridded == 0:
        work.pair_tests[0] = 0
        return 0, (False, 0, 0, 0, 0, 0, 0, np.int64(0)), np.int64(0)
    grid = _cell_box(contact, work, gridded, whole_grid_hashed(contact, work))
    _, _, _, _, nx, ny, nz, _ = grid
    budget = np.int64(2.0 * HALF_SHELL_CELLS * gridded * (gridded / (nx * ny * nz)))
    return (1 if grid[0] else -1), grid, budget


@numba.njit(cache=True, inline="always")
def _cell_box(contact, work, count, hashed):  # noqa: ANN001, ANN202
    """broad_phase.grid_box's grid tuple for the spheres work.active_sphere[:count] (count > 0), from the
    extremes of their positions, without the cell of every sphere: `_pairs_of` needs only the cells of
    the spheres it finds (the cells of all, 5 us of container_mix's ~170 us evaluation). The cell is
    monotonic in a coordinate whose cell index fits (|p / size| < 2^62), so the least such coordinate has
    the least cell; a coordinate beyond it, or NaN, is taken with its own cell (broad_phase._cell)."""
    pos, spheres = work.sphere_position, work.active_sphere
    inv = 1.0 / contact.cell_size
    # per axis: the least and most tame coordinate, the least and most cell of the wild ones
    x0, x1, xc0, xc1 = math.inf, -math.inf, np.int64(2**62), np.int64(-(2**62))
    y0, y1, yc0, yc1 = x0, x1, xc0, xc1
    z0, z1, zc0, zc1 = x0, x1, xc0, xc1
    for a in range(count):
        i = spheres[a]
        x0, x1, xc0, xc1 = _fold(pos[i, 0], inv, x0, x1, xc0, xc1)
        y0, y1, yc0, yc1 = _fold(pos[i, 1], inv, y0, y1, yc0, yc1)
        z0, z1, zc0, zc1 = _fold(pos[i, 2], inv, z0, z1, zc0, zc1)
    lo0, hi0 = _extreme_cells(x0, x1, xc0, xc1, inv)
    lo1, hi1 = _extreme_cells(y0, y1, yc0, yc1, inv)
    lo2, hi2 = _extreme_cells(z0, z1, zc0, zc1, inv)
    buckets = contact.bucket_count
    nx, ny, nz = hi0 - lo0 + 1, hi1 - lo1 + 1, hi2 - lo2 + 1  # each <= 2^41 + 1: no overflow
    dense = nx <= buckets and ny <= buckets and nz <= buckets and nx * ny <= buckets and nx * ny * nz <= buckets
    return (dense and not hashed, lo0, lo1, lo2, nx, ny, nz, np.int64(buckets - 1))


@numba.njit(cache=True, inline="always")
def _fold(p, inv, least, most, least_cell, most_cell):  # noqa: ANN001, ANN202
    """A coordinate p folded into an axis's extremes (`_cell_box`)."""
    if abs(p * inv) < _TAME:
        return min(least, p), max(most, p), least_cell, most_cell
    c = _cell(p, inv)
    return least, most, min(least_cell, c), max(most_cell, c)


@numba.njit(cache=True, inline="always")
def _extreme_cells(least, most, least_cell, most_cell, inv):  # noqa: ANN001, ANN202
    """The least and most cell of an axis from `_fold`'s extremes (no tame coordinate: least > most)."""
    if least <= most:
        least_cell, most_cell = min(least_cell, _cell(least, inv)), max(most_cell, _cell(most, inv))
    return least_cell, most_cell


@numba.njit(cache=True, inline="always")
def _pairs_of(contact, work, grid, first, last, side_a, side_b, near, row0, capacity, budget):  # noqa: ANN001, ANN202
    """The overlapping sphere pairs of body pairs first .. last - 1, each as (walker, partner) with its
    keys into work.pair_found and pair_key rows row0 .. row0 + capacity - 1: (found, tests, cost), found
    -1 when they do not fit or the cost (in half checks: a sphere-box test 1, a sphere pair 2) passes
    the budget."""
    _, i0, j0, k0, nx, ny, _, _ = grid
    pos, radius, inv = work.sphere_position, contact.sphere_radius, 1.0 / contact.cell_size
    start, lo, hi, body_pair = contact.body_sphere_start, work.body_lo, work.body_hi, work.body_pair
    found, keys = work.pair_found, work.pair_key
    spheres = radius.shape[0]
    tests, cost, n = 0, 0, 0
    for k in range(first, last):
        a, b = body_pair[k, 0], body_pair[k, 1]
        if contact.primitive_kind[a] >= 0 or contact.primitive_kind[b] >= 0:  # primitive_search.py's pairs
            continue
        if not (
            (lo[a, 0] <= hi[b, 0]) & (lo[b, 0] <= hi[a, 0]) & (lo[a, 1] <= hi[b, 1])
            & (lo[b, 1] <= hi[a, 1]) & (lo[a, 2] <= hi[b, 2]) & (lo[b, 2] <= hi[a, 2])
        ):  # fmt: skip
            continue  # the boxes of their spheres (body_phase.place_spheres) do not meet
        na = _cull(pos, radius, start[a], start[a + 1], lo, hi, b, side_a)
        if na == 0:
            continue
        nb = _cull(pos, radius, start[b], start[b + 1], lo, hi, a, side_b)
        culls = start[a + 1] - start[a] + start[b + 1] - start[b]
        tests += culls + na * nb
        cost += culls + 2 * na * nb
        if cost > budget:
            return -1, tests, cost
        for v in range(nb):  # B's spheres near A side by side: the inner loop reads them in a row
            j = side_b[v]
            near[v, 0], near[v, 1], near[v, 2], near[v, 3] = pos[j, 0], pos[j, 1], pos[j, 2], radius[j]
        for u in range(na):
            i = side_a[u]
            p0, p1, p2, ri = pos[i, 0], pos[i, 1], pos[i, 2], radius[i]
            for v in range(nb):
                # the walk's test of the pair (its d is +-this one, its reach r_j + r_i: the same bits)
                d0, d1, d2 = p0 - near[v, 0], p1 - near[v, 1], p2 - near[v, 2]
                reach = ri + near[v, 3]
                dist2 = d0 * d0 + d1 * d1 + d2 * d2
                if dist2 < reach * reach and dist2 > 0.0:
                    if n == capacity:
                        return -1, tests, cost
                    j = side_b[v]
                    ki = _walk_key(pos, i, inv, i0, j0, k0, nx, ny, spheres)
                    kj = _walk_key(pos, j, inv, i0, j0, k0, nx, ny, spheres)
                    row = row0 + n
                    if ki < kj:  # the walker (earlier in bucket order) first
                        found[row, 0], found[row, 1], keys[row, 0], keys[row, 1] = i, j, ki, kj
                    else:
                        found[row, 0], found[row, 1], keys[row, 0], keys[row, 1] = j, i, kj, ki
                    n += 1
    return n, tests, cost


@numba.njit(cache=True, inline="always")
def _walk_key(pos, i, inv, i0, j0, k0, nx, ny, spheres):  # noqa: ANN001, ANN202
    """Sphere i's place in the dense walk's order: its bucket (cell row-major in the grid's box), then i."""
    c0, c1, c2 = _cell(pos[i, 0], inv), _cell(pos[i, 1], inv), _cell(pos[i, 2], inv)
    return (((c2 - k0) * ny + (c1 - j0)) * nx + (c0 - i0)) * spheres + i


@numba.njit(cache=True, inline="always")
def _cull(pos, radius, first, last, lo, hi, other, out) -> int:  # noqa: ANN001
    """The spheres first .. last - 1 whose box meets body `other`'s box (lo, hi) into out; their count."""
    n = 0
    l0, l1, l2, h0, h1, h2 = lo[other, 0], lo[other, 1], lo[other, 2], hi[other, 0], hi[other, 1], hi[other, 2]
    for i in range(first, last):
        r = radius[i] * _CULL
        out[n] = i
        n += (
            (pos[i, 0] + r >= l0) & (pos[i, 0] - r <= h0)
            & (pos[i, 1] + r >= l1) & (pos[i, 1] - r <= h1)
            & (pos[i, 2] + r >= l2) & (pos[i, 2] - r <= h2)
        )  # fmt: skip
    return n


@numba.njit(cache=True, inline="always")
def _sort(work, n) -> None:  # noqa: ANN001
    """work.pair_found[:n] in the order of the keys pair_key[:n] (column 0, then 1; every contact's pair
    of keys is its own, so the order is unique): up to _INSERTION_SORT contacts an insertion sort by
    both, else a stable LSD radix sort of column 0 (digits of _RADIX_BITS), then an insertion sort of each
    run of one walker by column 1 (a walker has a few partners). pair_key is scratch afterwards."""
    found, keys, order, histogram = work.pair_found, work.pair_key, work.pair_order, work.pair_radix
    if n < 2:
        return
    top = 0
    for r in range(n):
        top = max(top, keys[r, 0])
    src, dst = order[0], order[1]
    for r in range(n):
        src[r] = r
    if n <= _INSERTION_SORT:  # a few contacts: sorted by both keys at once (the radix passes cost ~2 us)
        for r in range(1, n):
            moving = src[r]
            m0, m1 = keys[moving, 0], keys[moving, 1]
            s = r
            while s > 0 and (keys[src[s - 1], 0] > m0 or (keys[src[s - 1], 0] == m0 and keys[src[s - 1], 1] > m1)):
                src[s] = src[s - 1]
                s -= 1
            src[s] = moving
        _permute(found, keys, src, dst, n)
        return
    radix = 1 << _RADIX_BITS
    shift = 0
    while (top >> shift) > 0:
        histogram[: radix + 1] = 0
        for r in range(n):
            histogram[((keys[src[r], 0] >> shift) & (radix - 1)) + 1] += 1
        for digit in range(radix):
            histogram[digit + 1] += histogram[digit]
        for r in range(n):
            digit = (keys[src[r], 0] >> shift) & (radix - 1)
            dst[histogram[digit]] = src[r]
            histogram[digit] += 1
        src, dst = dst, src
        shift += _RADIX_BITS
    # each walker's partners by their key (runs of a few)
    run = 0
    while run < n:
        end = run + 1
        while end < n and keys[src[end], 0] == keys[src[run], 0]:
            end += 1
        for r in range(run + 1, end):
            moving = src[r]
            s = r
            while s > run and keys[src[s - 1], 1] > keys[moving, 1]:
                src[s] = src[s - 1]
                s -= 1
            src[s] = moving
        run = end
    _permute(found, keys, src, dst, n)


@numba.njit(cache=True, inline="always")
def _permute(found, keys, src, dst, n) -> None:  # noqa: ANN001
    """found[:n] reordered to found[src[:n]] (through dst and keys' first column as scratch)."""
    for r in range(n):
        dst[r] = found[src[r], 0]
    for r in range(n):
        keys[r, 0] = found[src[r], 1]
    for r in range(n):
        found[r, 0], found[r, 1] = dst[r], keys[r, 0]
