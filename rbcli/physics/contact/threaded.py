"""The contact force stage's pair search on threads (issue 28 item 1): the same contacts, forces, history
and statistics as the serial search (search.find_contacts with force.py's sink), bit for bit, at any
thread count.

What makes a parallel search differ from a serial one is the order of its sums: each contact adds its
force to two bodies (F, tau), its spring to its owner's trial slots, its energy to the evaluation's
total, and floating-point sums depend on their order. So the work is split where nothing is summed:

    1. the plane contacts, serially, as find_contacts does them (a pile's ~300 of ~2,300 contacts;
       as blocks of their own on the threads they measured slower: ~290 against ~265 us per step);
    2. the grid (broad_phase.build_grid_of), serially: a counting sort, ~5 % of the search;
    3. the records pass, on threads: the walkers (bucket order) in blocks of RECORD_BLOCK, each block
       walking its walkers exactly as find_contacts does (search.walk_pairs) and writing, for each
       contact it finds, what `law.contact_values` computes from the state and the history alone
       (the force, the spring's elongation and limit, the energy) with the contact's geometry into the
       block's own rows of ContactWork.record_*; nothing else is written, so the blocks are independent;
    4. the apply pass, serially: block by block, record by record, `law.apply_contact` does what the
       serial sink would have done with each contact, in the serial search's order: the same sums in
       the same order, so the same bits. A block that found more contacts than its rows is walked again
       here with the serial sink itself, in its place in the order.

Scenes of bodies of many spheres take narrow.py's pair path instead of the walk: its body pairs are
searched on threads (pair_candidates_threaded), the contacts it finds handed to the force sink serially
in the walk's order (measured: the force law on threads over them gained nothing at 3,500 contacts).

The force law's inputs (body velocities, the history) do not change during the records pass: the
history changes only at the commit, after the step. What stays serial is large: the apply pass's
scattered writes (trial slots by owner, F and tau by body) cost about as much as finding and computing
the contacts (measured in docs/performance.md, "Threads", with what would move them onto threads).
The blocks are a fixed size, not one per thread, so the records and the order do not depend on the
thread count either.

`find_contacts_threaded` is compiled with numba's parallel=True (its own function: the serial search
keeps its plain compiled form) and is what force.accumulate_contact's `contact_search` compiles to when
the run's ContactWork has record blocks (`record_*`: the Simulation allocates them when
runner/threads.py gives the contact stage more than one thread); with them None it compiles to
the serial search, and a serial run compiles nothing of this module's kernels (~15 s of a cold first
run of the pile). The recorded state's statistics (state.py) keep the serial search: they run once
per recorded frame, not per evaluation.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numba
import numpy as np
from numba.core import types
from numba.extending import overload

from rbcli.physics.contact.law import ContactGeometry, ContactOutcome, apply_contact, contact_values
from rbcli.physics.contact.search import (
    contact_found,
    find_contacts,
    grid_of_gridded,
    pairs_of_bodies,
    plane_contacts,
    walk_pairs,
    walk_range,
)
from rbcli.physics.contact.tables import (
    RECORD_BLOCK,
    RECORD_ELONGATION,
    RECORD_ENERGY,
    RECORD_FORCE,
    RECORD_FRICTION,
    RECORD_INT_BODY_A,
    RECORD_INT_BODY_B,
    RECORD_INT_OWNER,
    RECORD_INT_PARTNER,
    RECORD_LIMIT,
    RECORD_NORMAL,
    RECORD_OVERLAP,
    RECORD_POINT,
    SWEEP_SPHERES,
)
from rbcli.physics.step import STEP_KERNEL

_OPTIONS: Any = STEP_KERNEL  # typed Any: numba's stubs type jit_options as a TypedDict without `_nrt`


class ContactRecordSink(NamedTuple):
    """The records pass's sink of the contact search: block `block`'s contacts, at offset s into the step
    of the state whose centres of mass are x, into its `rows` rows (from block * rows) of ints and floats
    (the ContactWork.record_* arrays); counts[block] counts them, past the rows when they do not fit."""

    x: np.ndarray
    s: float
    ints: np.ndarray
    floats: np.ndarray
    counts: np.ndarray
    block: int
    rows: int


def contact_search(contact, work, sink) -> int:  # noqa: ANN001
    """The force stage's contact search (kernels only): find_contacts_threaded when the run's work has
    record blocks (ContactWork.record_*), else search.find_contacts; returns the candidate pairs."""
    raise TypeError("contact_search runs in compiled kernels only")


@overload(contact_search, jit_options=_OPTIONS)
def _contact_search(contact, work, sink):  # noqa: ANN001, ANN202
    records = dict(zip(work.fields, work.types, strict=True))["record_int"]
    if isinstance(records, types.NoneType):  # a serial run: no threaded code is compiled
        return lambda contact, work, sink: find_contacts(contact, work, sink)
    return lambda contact, work, sink: find_contacts_threaded(contact, work, sink)


@numba.njit(**STEP_KERNEL, parallel=True)
def find_contacts_threaded(contact, work, sink) -> int:  # noqa: ANN001
    """search.find_contacts for the force stage's sink (sink.force_sink) on numba's threads, with
    the same results bit for bit (module docstring); returns the candidate pairs tested."""
    plane_contacts(contact, work, sink)
    gridded = work.body_sweep[SWEEP_SPHERES]
    tested = pairs_of_bodies(contact, work, sink, gridded, True)  # (narrow.py; -1: the walk runs)
    if tested >= 0:
        return tested
    ints, floats = work.record_int, work.record_float
    counts, block_candidates = work.record_count, work.record_candidates
    rows = ints.shape[0] // counts.shape[0]  # a block's rows (make_contact_work; tests give fewer)
    x, s = sink.x, sink.s
    grid = grid_of_gridded(contact, work, gridded)
    blocks = (gridded + RECORD_BLOCK - 1) // RECORD_BLOCK
    # numba gives each thread an equal run of iterations in one piece, and the blocks' costs differ (a
    # pile's top walkers find few contacts): iteration k takes block k * stride mod blocks, stride
    # ~0.38 blocks and coprime with it, so each run holds blocks from all over (which thread takes a
    # block changes nothing in its rows). numba.set_parallel_chunksize would hand them out one by one,
    # but it makes the kernel uncacheable (a ctypes pointer)
    stride = _coprime_stride(blocks)
    for k in numba.prange(blocks):
        block = (k * stride) % blocks
        counts[block] = 0
        first = block * RECORD_BLOCK
        last = min(gridded, first + RECORD_BLOCK)
        sink_of_block = ContactRecordSink(x, s, ints, floats, counts, block, rows)
        block_candidates[block] = walk_pairs(contact, work, sink_of_block, grid, first, last)
    candidates = 0
    for block in range(blocks):
        if counts[block] > rows:  # more contacts than rows: searched again, serially, in its place
            first = block * RECORD_BLOCK
            candidates += walk_range(contact, work, sink, grid, first, min(gridded, first + RECORD_BLOCK))
            continue
        candidates += block_candidates[block]
        for row in range(block * rows, block * rows + counts[block]):
            _apply_record(work, sink, ints, floats, row)
    return candidates


@numba.njit(cache=True, inline="always")
def _coprime_stride(count) -> int:  # noqa: ANN001
    """The integer nearest 0.382 count (the golden ratio's section: consecutive multiples spread evenly)
    that has no common factor with count (1 for count <= 2)."""
    stride = max(1, int(0.382 * count + 0.5))
    while True:
        a, b = stride, count
        while b:
            a, b = b, a % b
        if a == 1:
            return stride
        stride += 1


@numba.njit(cache=True, inline="always")
def _apply_record(work, sink, ints, floats, row) -> None:  # noqa: ANN001
    """law.apply_contact of record `row`."""
    i, r = ints[row], floats[row]
    geometry = ContactGeometry(
        i[RECORD_INT_OWNER], i[RECORD_INT_PARTNER], i[RECORD_INT_BODY_A], i[RECORD_INT_BODY_B],
        (r[RECORD_NORMAL], r[RECORD_NORMAL + 1], r[RECORD_NORMAL + 2]), r[RECORD_OVERLAP],
        (r[RECORD_POINT], r[RECORD_POINT + 1], r[RECORD_POINT + 2]),
    )  # fmt: skip
    outcome = ContactOutcome(
        (r[RECORD_FORCE], r[RECORD_FORCE + 1], r[RECORD_FORCE + 2]),
        (r[RECORD_ELONGATION], r[RECORD_ELONGATION + 1], r[RECORD_ELONGATION + 2]),
        r[RECORD_LIMIT], r[RECORD_ENERGY],
    )  # fmt: skip
    apply_contact(work, sink.x, sink.F, sink.tau, geometry, r[RECORD_FRICTION] != 0.0, outcome)


@overload(contact_found, jit_options=_OPTIONS)
def _contact_record(sink, contact, work, owner, partner, ba, bb, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu):  # noqa: ANN001, ANN202
    """One contact of the records pass: force.contact_values and its geometry into the block's next row."""
    if not (isinstance(sink, types.BaseNamedTuple) and sink.instance_class is ContactRecordSink):
        return None

    def record(sink, contact, work, owner, partner, ba, bb, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu):  # noqa: ANN001, ANN202
        found = sink.counts[sink.block]
        sink.counts[sink.block] = found + 1
        if found >= sink.rows:  # the block is searched again serially (find_contacts_threaded)
            return
        geometry = ContactGeometry(owner, partner, ba, bb, (n0, n1, n2), overlap, (c0, c1, c2))
        outcome = contact_values(contact, work, sink.x, sink.s, geometry, k, zeta, mu)
        (f0, f1, f2), (u0, u1, u2) = outcome.force, outcome.elongation
        limit, energy = outcome.limit, outcome.energy
        row = sink.block * sink.rows + found
        i, r = sink.ints[row], sink.floats[row]
        i[RECORD_INT_OWNER], i[RECORD_INT_PARTNER], i[RECORD_INT_BODY_A], i[RECORD_INT_BODY_B] = owner, partner, ba, bb
        r[RECORD_NORMAL], r[RECORD_NORMAL + 1], r[RECORD_NORMAL + 2], r[RECORD_OVERLAP] = n0, n1, n2, overlap
        r[RECORD_POINT], r[RECORD_POINT + 1], r[RECORD_POINT + 2] = c0, c1, c2
        r[RECORD_FRICTION] = 1.0 if mu > 0.0 else 0.0
        r[RECORD_FORCE], r[RECORD_FORCE + 1], r[RECORD_FORCE + 2] = f0, f1, f2
        r[RECORD_ELONGATION], r[RECORD_ELONGATION + 1], r[RECORD_ELONGATION + 2] = u0, u1, u2
        r[RECORD_LIMIT], r[RECORD_ENERGY] = limit, energy

    return record
