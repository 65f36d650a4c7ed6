"""Broad phase: a uniform grid of cells as large as the largest sphere diameter, rebuilt at every force
evaluation by a counting sort (Harada, "Real-time rigid body simulation on GPUs", GPU Gems 3 ch. 29;
Green, "Particle simulation using CUDA", 2010). Work and memory are linear in the number of spheres:

    1. each sphere's cell c = floor(p / cell_size);
    2. a bucket per cell: when the spheres' bounding box has at most `bucket_count` cells the grid is
       dense (bucket = the cell's row-major index, so neighbouring cells are neighbouring buckets and
       the walk stays in cache); otherwise (one body far from the rest) cells are hashed into the
       table (Teschner et al. 2003's primes), and a bucket may hold several cells;
    3. a counting sort orders the spheres by bucket (stable: ascending index within a bucket);
    4. every pair closer than one cell is found once: each sphere looks at the later spheres of its own
       cell and at all spheres of the 13 cells of its half shell (the other 13 neighbours find it).
       A sphere of another cell that shares a hashed bucket is skipped by comparing cells.

No allocation: the arrays are ContactWork's. Cell coordinates are clamped to +-2^40 before the integer
conversion, so a non-finite or huge position (a diverging run) cannot produce an undefined conversion,
and dense indices are bounds-checked, so nothing is ever written or read outside the arrays.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics import kernel_cache

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources

# the 13 neighbour cells (dx, dy, dz) of the half shell: the lexicographically positive offsets
HALF_SHELL = np.array(
    [(dx, dy, dz) for dz in (-1, 0, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dz, dy, dx) > (0, 0, 0)],
    dtype=np.int64,
)
_CELL_LIMIT = float(2**40)
_PRIME_X, _PRIME_Y, _PRIME_Z = 73856093, 19349663, 83492791


@numba.njit(cache=True, inline="always")
def _cell(value, inv_size):  # noqa: ANN001, ANN202
    c = math.floor(value * inv_size)
    if not c > -_CELL_LIMIT:  # also NaN
        c = -_CELL_LIMIT
    elif c > _CELL_LIMIT:
        c = _CELL_LIMIT
    return np.int64(c)


@numba.njit(cache=True, inline="always")
def bucket_of(ci, cj, ck, grid):  # noqa: ANN001, ANN201
    """The bucket of cell (ci, cj, ck), or -1 for a cell outside a dense grid (it holds no sphere).

    grid = (dense, i0, j0, k0, nx, ny, nz, mask) as `build_grid` returns it."""
    dense, i0, j0, k0, nx, ny, nz, mask = grid
    if dense:
        i, j, k = ci - i0, cj - j0, ck - k0
        if i < 0 or j < 0 or k < 0 or i >= nx or j >= ny or k >= nz:
            return -1
        return (k * ny + j) * nx + i
    return ((ci * _PRIME_X) ^ (cj * _PRIME_Y) ^ (ck * _PRIME_Z)) & mask


@numba.njit(cache=True)
def build_grid(contact, work):  # noqa: ANN001, ANN201
    """`build_grid_of` over every contact sphere."""
    spheres = work.active_sphere
    for i in range(spheres.shape[0]):
        spheres[i] = i
    return build_grid_of(contact, work, spheres.shape[0])


@numba.njit(cache=True, inline="always")
def grid_box(contact, work, count, hashed=False):  # noqa: ANN001, ANN201
    """The cell of each sphere work.active_sphere[:count] into work.sphere_cell, and the grid tuple
    `bucket_of` takes: dense over the cells' box when it has at most bucket_count cells and `hashed` is
    False (build_grid_of)."""
    pos, cell, spheres = work.sphere_position, work.sphere_cell, work.active_sphere
    inv_size = 1.0 / contact.cell_size
    lo0, lo1, lo2 = np.int64(2**62), np.int64(2**62), np.int64(2**62)
    hi0, hi1, hi2 = -lo0, -lo1, -lo2
    for a in range(count):
        i = spheres[a]
        c0, c1, c2 = _cell(pos[i, 0], inv_size), _cell(pos[i, 1], inv_size), _cell(pos[i, 2], inv_size)
        cell[i, 0], cell[i, 1], cell[i, 2] = c0, c1, c2
        lo0, lo1, lo2 = min(lo0, c0), min(lo1, c1), min(lo2, c2)
        hi0, hi1, hi2 = max(hi0, c0), max(hi1, c1), max(hi2, c2)
    buckets = contact.bucket_count
    nx, ny, nz = hi0 - lo0 + 1, hi1 - lo1 + 1, hi2 - lo2 + 1  # each <= 2^41 + 1: no overflow
    dense = nx <= buckets and ny <= buckets and nz <= buckets and nx * ny <= buckets and nx * ny * nz <= buckets
    dense = dense and not hashed  # hashed: the grid over every sphere would be (its walk order kept)
    return (dense, lo0, lo1, lo2, nx, ny, nz, np.int64(buckets - 1))


@numba.njit(cache=True, inline="always")
def build_grid_of(contact, work, count, hashed=False):  # noqa: ANN001, ANN201
    """Cells, buckets and the bucket-sorted order of the spheres work.active_sphere[:count] (ascending
    indices) at their positions in work.sphere_position; returns the grid tuple `bucket_of` takes. Bucket
    b holds sorted_sphere[bucket_start[b] : bucket_start[b + 1]], sorted_* of length count.

    A dense grid numbers cells row-major from the low corner of the spheres' box, so the order (by cell,
    then by index) does not depend on where that corner is: a subset of spheres is walked in the order
    of the whole, and only the buckets of its box (nx ny nz of them) are cleared and summed. When the grid
    over every sphere would be hashed (`hashed`, body_phase.whole_grid_hashed), so is this one: a subset
    in a dense grid would be walked in another order than the whole. Inlined: a
    call passing the contact tuples increments and decrements the reference count of every array in them."""
    pos, cell, spheres = work.sphere_position, work.sphere_cell, work.active_sphere
    grid = grid_box(contact, work, count, hashed)
    dense, _, _, _, nx, ny, nz, _ = grid
    buckets = contact.bucket_count
    used = (nx * ny * nz if dense else buckets) if count > 0 else 0  # the buckets the grid can name
    start, bucket = work.bucket_start, work.sphere_bucket
    start[: used + 1] = 0
    for a in range(count):
        i = spheres[a]
        b = bucket_of(cell[i, 0], cell[i, 1], cell[i, 2], grid)
        bucket[i] = b
        start[b] += 1
    running = 0
    for b in range(used):  # inclusive prefix sum: start[b] = end of bucket b
        running += start[b]
        start[b] = running
    start[used] = count
    order = work.sorted_sphere
    for a in range(count - 1, -1, -1):  # stable: ascending sphere index within a bucket
        i = spheres[a]
        b = bucket[i]
        start[b] -= 1
        order[start[b]] = i
    sp, sc, radius = work.sorted_position, work.sorted_cell, contact.sphere_radius
    for a in range(count):  # bucket-ordered copies for the walk: neighbours are near in memory
        i = order[a]
        sp[a, 0], sp[a, 1], sp[a, 2], sp[a, 3] = pos[i, 0], pos[i, 1], pos[i, 2], radius[i]
        sc[a, 0], sc[a, 1], sc[a, 2] = cell[i, 0], cell[i, 1], cell[i, 2]
    return grid
