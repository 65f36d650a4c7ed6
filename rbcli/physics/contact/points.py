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

from typing import Any, NamedTuple

import numba
import numpy as np
from numba.core import types
from numba.extending import overload

from rbcli.physics.contact.law import body_velocities, normal_force, relative_velocity
from rbcli.physics.contact.search import contact_found, find_contacts, sphere_positions

# typed Any: numba's stubs type jit_options as a TypedDict without `cache`
_OPTIONS: Any = {"cache": True, "error_model": "numpy"}


class ContactPointSink(NamedTuple):
    """The contact-points sink of the contact search: point (capacity, 3) [m, world] and force
    (capacity,) [N] take the first `capacity` contacts, found (1,) counts them all."""

    x: np.ndarray
    point: np.ndarray
    force: np.ndarray
    found: np.ndarray


@numba.njit(cache=True, nogil=True, error_model="numpy")
def contact_points(model, contact, work, x, q, P, L, point, force) -> int:  # noqa: ANN001
    """Write the contacts of the state (x, q, P, L; internal principal frame) to point (capacity, 3)
    [m, world] and force (capacity,) [N], in search order; returns how many there are (call again with
    larger arrays when that exceeds the capacity: only the first `capacity` are written)."""
    body_velocities(model, work, x, q, P, L)
    found = np.zeros(1, dtype=np.int64)
    if sphere_positions(contact, work, x, q):  # else nothing can touch (search.py)
        find_contacts(contact, work, ContactPointSink(x, point, force, found))
    return found[0]


@overload(contact_found, jit_options=_OPTIONS)
def _contact_point(sink, contact, work, owner, partner, ba, bb, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu):  # noqa: ANN001, ANN202
    if not (isinstance(sink, types.BaseNamedTuple) and sink.instance_class is ContactPointSink):
        return None

    def put(sink, contact, work, owner, partner, ba, bb, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu):  # noqa: ANN001, ANN202
        m_eff, vn, _, _, _ = relative_velocity(contact, work, sink.x, ba, bb, n0, n1, n2, c0, c1, c2)
        fn, _ = normal_force(k, zeta, m_eff, overlap, vn)
        index = sink.found[0]
        if index < sink.point.shape[0]:
            sink.point[index, 0], sink.point[index, 1], sink.point[index, 2] = c0, c1, c2
            sink.force[index] = fn
        sink.found[0] = index + 1

    return put
