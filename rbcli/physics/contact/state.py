"""Contact statistics of a state, for the recorded invariants (docs/contact.md "Outputs").

For the state being recorded (x, q and the contact history committed at the end of its step), by the
force stage's own search (search.py), with the same stiffnesses:

    contact_count        the contacts of the state
    contact_max_overlap  max d [m]
    contact_energy       V_c = sum 1/2 k d^2 + 1/2 k_t |xi|^2 [J]: the normal springs at the state's
                         overlaps and the tangential springs the history holds (contacts with friction;
                         |xi| as the next evaluation turns it, length kept)

Why not the force stage's statistics: those are of the step's last force evaluation, not of the
recorded state (split2's is mid-step, semi-implicit's at the start of the step), and adding them to the
kinetic and potential energy of the recorded state gave a bounce's total energy a 1.6 % (split2) /
3.2 % (semi-implicit) dip in the impact (issue 30). The search costs one more grid walk per recorded
frame (no velocities, no forces), in the pipeline's contact_record stage.
"""

from __future__ import annotations

import numba

from rbcli.physics.contact.quiet import quiet_at_step_end
from rbcli.physics.contact.search import find_contacts, sphere_positions
from rbcli.physics.contact.sink import state_sink
from rbcli.physics.contact.tables import COUNT_OVERFLOW, STAT_OVERFLOW
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL


@separately_compiled
@numba.njit(**STEP_KERNEL)
def record_contact_state(contact, work, x, q, out, row) -> None:  # noqa: ANN001
    """out[row] = the contact statistics of the state (x, q; internal principal frame) with the history
    in work (module docstring), and out[row, STAT_OVERFLOW] the run's history overflows so far.
    Overwrites work's search arrays (positions, grid): every force evaluation rebuilds them."""
    for k in range(out.shape[1]):
        out[row, k] = 0.0
    if quiet_at_step_end(work, x):  # nothing can touch (quiet.py)
        pass
    elif sphere_positions(contact, work, x, q):  # else nothing can touch (search.py)
        find_contacts(contact, work, state_sink(x, out, row, work))
    out[row, STAT_OVERFLOW] = work.counters[COUNT_OVERFLOW]
