"""The contact points of one state, for the optional `contacts` record stream (docs/contact.md "Outputs").

For each overlapping pair of contact spheres of different bodies and each sphere overlapping a plane,
the contact point (halfway through the overlap, as the force stage places it) and the magnitude of the
normal force there, f_n = max(0, k d - c_n v_n) (force.py's law, with the same stiffness, damping ratio
and effective mass). The tangential force needs the contact's history, which a recorded frame does not
carry, so it is left out.

Run by the recorder on recorded frames only and only when the scene asks for the stream: the force
stage itself is untouched, so a scene that does not record contacts pays nothing. The search is the
force stage's (broad_phase.build_grid and the same half-shell walk), in a scratch ContactWork without
history slots (`make_contact_work(..., history=False)`).
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.contact.broad_phase import HALF_SHELL, bucket_of, build_grid
from rbcli.physics.contact.force import _body_velocities, _sphere_positions, _velocity_at


@numba.njit(cache=True, nogil=True, error_model="numpy")
def contact_points(model, contact, work, x, q, P, L, point, force) -> int:  # noqa: ANN001
    """Write the contacts of the state (x, q, P, L; internal principal frame) to point (capacity, 3)
    [m, world] and force (capacity,) [N], in search order; returns how many there are (call again with
    larger arrays when that exceeds the capacity: only the first `capacity` are written)."""
    _body_velocities(model, work, x, q, P, L)
    _sphere_positions(contact, work, x, q)
    grid = build_grid(contact, work)
    pos = work.sphere_position
    count = 0
    for i in range(pos.shape[0]):  # plane contacts
        b = contact.sphere_body[i]
        if contact.body_inv_contact_mass[b] == 0.0:
            continue
        r = contact.sphere_radius[i]
        for p in range(contact.plane_point.shape[0]):
            n0, n1, n2 = contact.plane_normal[p, 0], contact.plane_normal[p, 1], contact.plane_normal[p, 2]
            dist = (
                (pos[i, 0] - contact.plane_point[p, 0]) * n0
                + (pos[i, 1] - contact.plane_point[p, 1]) * n1
                + (pos[i, 2] - contact.plane_point[p, 2]) * n2
            )
            overlap = r - dist
            if overlap <= 0.0:
                continue
            back = r - 0.5 * overlap
            c0, c1, c2 = pos[i, 0] - back * n0, pos[i, 1] - back * n1, pos[i, 2] - back * n2
            zeta = min(contact.body_damping_ratio[b], contact.plane_damping_ratio[p])
            f = _normal_force(contact, work, x, b, -1, n0, n1, n2, overlap, c0, c1, c2,
                              contact.body_plane_stiffness[b], zeta)  # fmt: skip
            count = _put(point, force, count, c0, c1, c2, f)
    cell, sp, order, start = work.sorted_cell, work.sorted_position, work.sorted_sphere, work.bucket_start
    dense = grid[0]
    for a in range(order.shape[0]):  # sphere pairs: force.accumulate_contact's walk
        ci, cj, ck = cell[a, 0], cell[a, 1], cell[a, 2]
        own = work.sphere_bucket[order[a]]
        for n in range(-1, HALF_SHELL.shape[0]):
            if n < 0:  # the later spheres of its own bucket
                lo, hi, ni, nj, nk = a + 1, start[own + 1], ci, cj, ck
            else:
                ni, nj, nk = ci + HALF_SHELL[n, 0], cj + HALF_SHELL[n, 1], ck + HALF_SHELL[n, 2]
                bucket = bucket_of(ni, nj, nk, grid)
                if bucket < 0:
                    continue
                lo, hi = start[bucket], start[bucket + 1]
            for e in range(lo, hi):
                if not dense and (cell[e, 0] != ni or cell[e, 1] != nj or cell[e, 2] != nk):
                    continue
                d0, d1, d2 = sp[a, 0] - sp[e, 0], sp[a, 1] - sp[e, 1], sp[a, 2] - sp[e, 2]
                reach = sp[a, 3] + sp[e, 3]
                dist2 = d0 * d0 + d1 * d1 + d2 * d2
                if not (dist2 < reach * reach and dist2 > 0.0):
                    continue
                i, j = order[a], order[e]
                bi, bj = contact.sphere_body[i], contact.sphere_body[j]
                if bi == bj or (contact.body_inv_contact_mass[bi] == 0.0 and contact.body_inv_contact_mass[bj] == 0.0):
                    continue
                dist = math.sqrt(dist2)
                overlap = reach - dist
                n0, n1, n2 = d0 / dist, d1 / dist, d2 / dist  # towards sphere i
                forward = contact.sphere_radius[j] - 0.5 * overlap
                c0, c1, c2 = pos[j, 0] + forward * n0, pos[j, 1] + forward * n1, pos[j, 2] + forward * n2
                ka, kb = contact.body_stiffness[bi], contact.body_stiffness[bj]
                k = ka if ka == kb else 2.0 * ka * kb / (ka + kb)
                zeta = min(contact.body_damping_ratio[bi], contact.body_damping_ratio[bj])
                f = _normal_force(contact, work, x, bi, bj, n0, n1, n2, overlap, c0, c1, c2, k, zeta)
                count = _put(point, force, count, c0, c1, c2, f)
    return count


@numba.njit(cache=True, inline="always")
def _normal_force(contact, work, x, ba, bb, n0, n1, n2, overlap, c0, c1, c2, k, zeta):  # noqa: ANN001, ANN202
    """max(0, k d - c_n v_n) of force._resolve, n pointing towards body ba (bb = -1: a plane)."""
    inv_b = contact.body_inv_contact_mass[bb] if bb >= 0 else 0.0
    m_eff = 1.0 / (contact.body_inv_contact_mass[ba] + inv_b)
    v0, v1, v2 = _velocity_at(work, x, ba, c0, c1, c2)
    if bb >= 0:
        w0, w1, w2 = _velocity_at(work, x, bb, c0, c1, c2)
        v0, v1, v2 = v0 - w0, v1 - w1, v2 - w2
    fn = k * overlap - 2.0 * zeta * math.sqrt(k * m_eff) * (v0 * n0 + v1 * n1 + v2 * n2)
    return fn if fn > 0.0 else 0.0


@numba.njit(cache=True, inline="always")
def _put(point, force, count, c0, c1, c2, f):  # noqa: ANN001, ANN202
    if count < point.shape[0]:
        point[count, 0], point[count, 1], point[count, 2] = c0, c1, c2
        force[count] = f
    return count + 1
