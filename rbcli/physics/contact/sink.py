"""What the contact search hands each contact to: one sink type for the force stage, the recorded
statistics and the recorded contact points.

search.find_contacts walks the planes, the body pairs and the grid and calls `contact_found(sink, ...)`
for each contact it finds. The three serial searches of a run differ only in what they do with a contact:

    SINK_FORCE   the force stage (force.py): the contact's force and torque added to F and tau at offset s
                 into the step, its tangential spring proposed to the history (law.py)
    SINK_STATE   the recorded statistics of a state (state.py): count, deepest overlap, spring energy
    SINK_POINTS  the recorded contact points (points.py): each contact point and its normal force

They were three sink types, so a contact scene compiled find_contacts (its walk, ~4-5 CPU-s) once for the
force stage and again for the statistics (and a third time for the points). `ContactSink` is one numba
type for all three, `purpose` choosing at run time, so each kind of contact work compiles the search
once (issue 44). The branch costs a comparison per contact against a force law of ~100 flops. The fields
a purpose does not use hold placeholders of the right types (another purpose's arrays, never touched).
All three take the body-pair path (narrow.py) where the work has it: it finds the same contacts as the
walk, in the walk's order (tests/physics/test_contact_pairs.py), so the sums are the same.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numba
import numpy as np
from numba.core import types
from numba.extending import overload

from rbcli.physics.contact.implicit_rows import implicit_record
from rbcli.physics.contact.law import (
    ContactGeometry,
    apply_contact,
    contact_values,
    history_elongation,
    normal_force,
    relative_velocity,
)
from rbcli.physics.contact.search import contact_found
from rbcli.physics.contact.tables import STAT_CONTACTS, STAT_ENERGY, STAT_MAX_PENETRATION
from rbcli.physics.step import STEP_KERNEL

_OPTIONS: Any = STEP_KERNEL  # typed Any: numba's stubs type jit_options as a TypedDict without `_nrt`

SINK_FORCE, SINK_STATE, SINK_POINTS = 0, 1, 2


class ContactSink(NamedTuple):
    """A contact search's sink (module docstring); x, the centres of mass [m] (body_count, 3) of the state
    searched, serves every purpose."""

    purpose: int  # SINK_FORCE, SINK_STATE or SINK_POINTS
    x: np.ndarray
    s: float  # FORCE: the evaluation's offset [s] into the step
    F: np.ndarray  # FORCE: [N] (body_count, 3), world, added to
    tau: np.ndarray  # FORCE: [N m] (body_count, 3), world, about each centre of mass
    out: np.ndarray  # STATE: the statistics' rows (rows, FRAME_STAT_COUNT); row `row` takes the sums
    row: int
    point: np.ndarray  # POINTS: [m] (capacity, 3), world: the first `capacity` contact points
    force: np.ndarray  # POINTS: [N] (capacity,): their normal forces
    found: np.ndarray  # POINTS: int64 (1,): the contacts found, all of them


# search.pairs_of_bodies: every purpose takes narrow.py's pair path (a class attribute, not a field)
setattr(ContactSink, "PAIRS_OF_BODIES", True)  # noqa: B010


@numba.njit(cache=True, inline="always")
def force_sink(x, s, F, tau, work) -> ContactSink:  # noqa: ANN001
    """The force stage's sink: forces at offset s into the step into F and tau (work: placeholders)."""
    return ContactSink(SINK_FORCE, x, s, F, tau, F, 0, F, work.stats, work.counters)


@numba.njit(cache=True, inline="always")
def state_sink(x, out, row, work) -> ContactSink:  # noqa: ANN001
    """The recorded statistics' sink: out[row] takes the sums (work: placeholders)."""
    return ContactSink(SINK_STATE, x, 0.0, out, out, out, row, out, work.stats, work.counters)


@numba.njit(cache=True, inline="always")
def points_sink(x, point, force, found) -> ContactSink:  # noqa: ANN001
    """The recorded contact points' sink: point and force take the first contacts, found counts them."""
    return ContactSink(SINK_POINTS, x, 0.0, point, point, point, 0, point, force, found)


# not inline="always": numba 0.68's IR inlining of this overload lost the writes to sink.F and sink.tau
# (the forces came out zero; measured); as a function LLVM still inlines it into the walk
@overload(contact_found, jit_options=_OPTIONS)
def _contact_sink(sink, contact, work, owner, partner, ba, bb, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu):  # noqa: ANN001, ANN202
    """One contact (search.contact_found) for the sink's purpose."""
    if not (isinstance(sink, types.BaseNamedTuple) and sink.instance_class is ContactSink):
        return None

    def take(sink, contact, work, owner, partner, ba, bb, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu):  # noqa: ANN001, ANN202
        if sink.purpose == SINK_FORCE:
            # the force of the contact (force.py) on body ba (owner) and bb (partner; -1: a plane), its
            # spring proposed to the history (trial arrays; force.commit_contacts advances it)
            geometry = ContactGeometry(owner, partner, ba, bb, (n0, n1, n2), overlap, (c0, c1, c2))
            outcome = contact_values(contact, work, sink.x, sink.s, geometry, k, zeta, mu)
            apply_contact(work, sink.x, sink.F, sink.tau, geometry, mu > 0.0, outcome)
            # kept for the implicit correction (reduced-implicit's runs only; else compiled to nothing)
            implicit_record(contact, work, sink.x, sink.s, geometry, k, zeta, mu, outcome.force)
        elif sink.purpose == SINK_STATE:
            # the normal spring's energy at the overlap and the tangential one's that the history holds
            energy = 0.5 * k * overlap * overlap
            if mu > 0.0:
                x0, x1, x2 = history_elongation(work, owner, partner, n0, n1, n2)
                energy += 0.5 * contact.tangential_ratio * k * (x0 * x0 + x1 * x1 + x2 * x2)
            out, row = sink.out, sink.row
            out[row, STAT_CONTACTS] += 1.0
            out[row, STAT_MAX_PENETRATION] = max(out[row, STAT_MAX_PENETRATION], overlap)
            out[row, STAT_ENERGY] += energy
        else:
            # the contact point and its normal force f_n = max(0, k d - c_n v_n) (no history: points.py)
            m_eff, vn, _, _, _ = relative_velocity(contact, work, sink.x, ba, bb, n0, n1, n2, c0, c1, c2)
            fn, _ = normal_force(k, zeta, m_eff, overlap, vn)
            index = sink.found[0]
            if index < sink.point.shape[0]:
                sink.point[index, 0], sink.point[index, 1], sink.point[index, 2] = c0, c1, c2
                sink.force[index] = fn
            sink.found[0] = index + 1

    return take
