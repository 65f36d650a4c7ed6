"""The contact points of one state, for the optional `contacts` record stream (docs/contact.md "Outputs").

For each contact the force stage finds (the same search, search.py, and the same law, law.py: sphere
pairs of different bodies and spheres overlapping a plane), the contact point halfway through the
overlap and the magnitude of the normal force there, f_n = max(0, k d - c_n v_n). The tangential force
needs the contact's history, which a recorded frame does not carry, so it is left out.

Run by the recorder on recorded frames only and only when the scene asks for the stream: the force
stage itself is untouched, so a scene that does not record contacts pays nothing. The search runs in a
scratch ContactWork without history slots (`make_contact_work(..., history=False)`).
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics.contact.law import body_velocities
from rbcli.physics.contact.search import find_contacts, sphere_positions
from rbcli.physics.contact.sink import points_sink


@numba.njit(cache=True, nogil=True, error_model="numpy")
def contact_points(model, contact, work, x, q, P, L, point, force) -> int:  # noqa: ANN001
    """Write the contacts of the state (x, q, P, L; internal principal frame) to point (capacity, 3)
    [m, world] and force (capacity,) [N], in search order; returns how many there are (call again with
    larger arrays when that exceeds the capacity: only the first `capacity` are written)."""
    body_velocities(model, work, x, q, P, L)
    found = np.zeros(1, dtype=np.int64)
    if sphere_positions(contact, work, x, q):  # else nothing can touch (search.py)
        find_contacts(contact, work, points_sink(x, point, force, found))
    return found[0]
