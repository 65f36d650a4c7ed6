"""The contact force stage: spring-dashpot normal force and Coulomb-capped tangential spring per
overlapping pair of contact spheres of different bodies, and per sphere overlapping a plane.

Per contact (Cundall & Strack 1979, "A discrete numerical model for granular assemblies"; the linear
spring-dashpot of Harada, GPU Gems 3 ch. 29), with n the unit normal towards the owner sphere, the
overlap d = r_a + r_b - |p_a - p_b| > 0 (plane: r - (p - p0) . n), the contact point c halfway through
the overlap, and the relative velocity at c, v = v_a + w_a x (c - x_a) - (v_b + w_b x (c - x_b)),
split into v_n = v . n and v_t = v - v_n n:

    normal      f_n = max(0, k d - c_n v_n),        c_n = 2 zeta sqrt(k m_eff),  m_eff = 1 / (1/m_a + 1/m_b)
                (m: the mass one contact sphere of the body carries, M / support: tables.py)
    tangential  f_t = -k_t xi - c_t v_t,             k_t = tangential_ratio k,    c_t = 2 zeta sqrt(k_t m_eff)
                |f_t| <= mu f_n  (Coulomb: beyond it f_t is scaled back and xi set to match, i.e. sliding)

The owner (the lower sphere index of a pair, or the sphere of a plane contact) gets f = f_n n + f_t at
c, the partner -f. xi is the tangential spring's elongation, the contact's history: it starts at 0
when the contact forms, is turned into the current tangent plane at each evaluation (its component
along n removed, its length kept), and grows by v_t times the time into the step. A force evaluation
at offset s into a step of length h uses xi_0 + s v_t (xi_0: the history at the start of the step) and
proposes xi_0 + h v_t for the end of the step, so the spring is integrated by the same quadrature as
the step (split2's single midpoint evaluation: the midpoint rule); the pipeline's contact_commit
stage keeps the last evaluation's proposal once the step is complete. A tangential spring with a
Coulomb cap lets a body rest on a slope without creeping (a viscous tangential law creeps), which is
why it is used; see docs/contact.md.
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.contact.body_phase import body_phase, place_spheres, whole_grid_hashed
from rbcli.physics.contact.broad_phase import HALF_SHELL, bucket_of, build_grid_of
from rbcli.physics.contact.tables import (
    ACTIVE_PLANE,
    COUNT_CANDIDATES,
    COUNT_CONTACTS,
    COUNT_EVALUATIONS,
    COUNT_OVERFLOW,
    PLANE_PARTNER_BASE,
    STAT_CONTACTS,
    STAT_ENERGY,
    STAT_MAX_PENETRATION,
)
from rbcli.physics.integrators.kinematics import rotate, rotate_inverse
from rbcli.physics.step import STEP_KERNEL


@numba.njit(**STEP_KERNEL)
def begin_contact_step(work, t, h) -> None:  # noqa: ANN001
    """Note the step [t, t + h) being taken: force evaluations measure their offset into it."""
    work.clock[0] = t
    work.clock[1] = h


@numba.njit(**STEP_KERNEL)
def commit_contacts(model, contact, work, x, q, P, L) -> None:  # noqa: ANN001
    """The step is complete: the contacts of its last force evaluation become the history (contacts
    not found again are forgotten), each spring advanced from that evaluation to the end of the step,
    xi += (h - s) v_t(end), with the end-of-step velocities, and kept within its Coulomb limit.

    Why the end velocity: integrating xi with the velocity of the evaluation alone (explicit Euler
    inside a leapfrog step) makes the stuck contact's oscillation grow (the update matrix has
    determinant 1 + h^2 k / (2 m)): the pile of the collisions issue kept ~10 J spinning after 2 s.
    Drift half a step with the old velocity, force, drift the rest with the new one is the leapfrog's
    own treatment of a position, so the tangential spring is as stable as the normal one.
    """
    s_last = work.clock[2]
    rest = work.clock[1] - s_last
    if rest != 0.0:  # the end-of-step velocities (the evaluation's are no longer needed)
        _body_velocities(model, work, x, q, P, L)
    # only bodies flagged in the last evaluation hold trial contacts, only bodies that held some keep a
    # history to forget: the others' spheres are not visited (body_phase.py), in sphere order as before
    start, trial, history = contact.body_sphere_start, work.body_trial, work.body_history
    for body in range(trial.shape[0]):
        if trial[body] == 0 and history[body] == 0:
            continue
        history[body] = 0
        for i in range(start[body], start[body + 1]):
            count = work.trial_count[i]
            work.hist_count[i] = count
            if count == 0:
                continue
            history[body] = 1
            ba = contact.sphere_body[i]
            for k in range(count):
                partner = work.trial_partner[i, k]
                if rest == 0.0:  # evaluated at the end of the step (rk4's last stage): nothing to advance
                    work.hist_partner[i, k] = partner
                    for j in range(3):
                        work.hist_xi[i, k, j] = work.trial_xi[i, k, j]
                    continue
                c0, c1, c2 = work.trial_point[i, k, 0], work.trial_point[i, k, 1], work.trial_point[i, k, 2]
                n0, n1, n2 = work.trial_normal[i, k, 0], work.trial_normal[i, k, 1], work.trial_normal[i, k, 2]
                v0, v1, v2 = _velocity_at(work, x, ba, c0, c1, c2)
                if partner >= 0:
                    w0, w1, w2 = _velocity_at(work, x, contact.sphere_body[partner], c0, c1, c2)
                    v0, v1, v2 = v0 - w0, v1 - w1, v2 - w2
                vn = v0 * n0 + v1 * n1 + v2 * n2
                e0 = work.trial_xi[i, k, 0] + rest * (v0 - vn * n0)
                e1 = work.trial_xi[i, k, 1] + rest * (v1 - vn * n1)
                e2 = work.trial_xi[i, k, 2] + rest * (v2 - vn * n2)
                limit = work.trial_limit[i, k]
                length2 = e0 * e0 + e1 * e1 + e2 * e2
                if length2 > limit * limit:
                    scale = limit / math.sqrt(length2)
                    e0, e1, e2 = e0 * scale, e1 * scale, e2 * scale
                work.hist_partner[i, k] = partner
                work.hist_xi[i, k, 0], work.hist_xi[i, k, 1], work.hist_xi[i, k, 2] = e0, e1, e2


@numba.njit(**STEP_KERNEL)
def hold_static_bodies(contact, F, tau) -> None:  # noqa: ANN001
    """Static bodies feel nothing: their wrench is set to zero after every other force stage."""
    for r in range(contact.static_body.shape[0]):
        b = contact.static_body[r]
        F[b, 0] = F[b, 1] = F[b, 2] = 0.0
        tau[b, 0] = tau[b, 1] = tau[b, 2] = 0.0


@numba.njit(**STEP_KERNEL)
def accumulate_contact(model, contact, work, t, x, q, P, L, F, tau) -> None:  # noqa: ANN001
    """Add every contact's force and torque to F and tau (world frame, about each centre of mass)."""
    _body_velocities(model, work, x, q, P, L)
    # the two-level broad phase: bodies whose boxes meet (body_phase.py), then only their spheres placed
    # and gridded; trial contacts cleared only where the last evaluation could have left some
    body_phase(contact, work, x, q, work.body_pair_none)
    start = contact.body_sphere_start
    for body in range(work.body_trial.shape[0]):
        if work.body_trial[body]:
            work.trial_count[start[body] : start[body + 1]] = 0
        work.body_trial[body] = 1 if work.body_active[body] else 0
    gridded = place_spheres(contact, work, x, q)
    hashed = whole_grid_hashed(contact, work) if gridded and not contact.body_level_off else False
    grid = build_grid_of(contact, work, gridded, hashed)
    work.stats[:] = 0.0
    work.counters[COUNT_EVALUATIONS] += 1
    s = t - work.clock[0]
    h = work.clock[1]
    work.clock[2] = s
    _plane_contacts(contact, work, x, s, h, F, tau)
    # the walk reads the bucket-ordered copies (sorted_*: build_grid), so the distance checks of the
    # candidates touch neighbouring memory; sphere and body arrays are read only for real overlaps
    cell, sp, order, start = work.sorted_cell, work.sorted_position, work.sorted_sphere, work.bucket_start
    dense = grid[0]
    candidates = 0
    for a in range(gridded):
        ci, cj, ck = cell[a, 0], cell[a, 1], cell[a, 2]
        p0, p1, p2, ra = sp[a, 0], sp[a, 1], sp[a, 2], sp[a, 3]
        own = work.sphere_bucket[order[a]]
        for e in range(a + 1, start[own + 1]):  # later spheres of the same bucket, same cell
            if dense or (cell[e, 0] == ci and cell[e, 1] == cj and cell[e, 2] == ck):
                candidates += 1
                d0, d1, d2 = p0 - sp[e, 0], p1 - sp[e, 1], p2 - sp[e, 2]
                reach = ra + sp[e, 3]
                dist2 = d0 * d0 + d1 * d1 + d2 * d2
                if dist2 < reach * reach and dist2 > 0.0:  # coincident centres: no normal, skipped
                    _pair(contact, work, x, s, h, order[a], order[e], d0, d1, d2, dist2, reach, F, tau)
        for n in range(HALF_SHELL.shape[0]):
            ni, nj, nk = ci + HALF_SHELL[n, 0], cj + HALF_SHELL[n, 1], ck + HALF_SHELL[n, 2]
            b = bucket_of(ni, nj, nk, grid)
            if b < 0:
                continue
            for e in range(start[b], start[b + 1]):
                # dense: a bucket is one cell; hashed: other cells may share it
                if dense or (cell[e, 0] == ni and cell[e, 1] == nj and cell[e, 2] == nk):
                    candidates += 1
                    d0, d1, d2 = p0 - sp[e, 0], p1 - sp[e, 1], p2 - sp[e, 2]
                    reach = ra + sp[e, 3]
                    dist2 = d0 * d0 + d1 * d1 + d2 * d2
                    if dist2 < reach * reach and dist2 > 0.0:
                        _pair(contact, work, x, s, h, order[a], order[e], d0, d1, d2, dist2, reach, F, tau)
    work.counters[COUNT_CANDIDATES] += candidates


@numba.njit(cache=True, inline="always")
def _body_velocities(model, work, x, q, P, L) -> None:  # noqa: ANN001
    """v = P / M and w = R I^-1 R^T L of every body (static bodies: 0)."""
    v, w = work.body_velocity, work.body_omega
    inv = model.body_inertia_inv
    for b in range(v.shape[0]):
        inv_m = 1.0 / model.body_mass[b]
        v[b, 0], v[b, 1], v[b, 2] = P[b, 0] * inv_m, P[b, 1] * inv_m, P[b, 2] * inv_m
        i0, i1, i2 = inv[b, 0], inv[b, 1], inv[b, 2]
        if i0 == i1 and i1 == i2:  # a ball: w = L / I in any frame, no rotation needed
            w[b, 0], w[b, 1], w[b, 2] = L[b, 0] * i0, L[b, 1] * i0, L[b, 2] * i0
            continue
        qw, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        m0, m1, m2 = rotate_inverse(qw, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2])
        w[b, 0], w[b, 1], w[b, 2] = rotate(qw, qx, qy, qz, m0 * i0, m1 * i1, m2 * i2)


@numba.njit(cache=True, inline="always")
def _sphere_positions(contact, work, x, q) -> None:  # noqa: ANN001
    """p = x_b + R r0 of every contact sphere (no rotation for a sphere at its body's centre)."""
    pos = work.sphere_position
    off = contact.sphere_offset
    for i in range(pos.shape[0]):
        b = contact.sphere_body[i]
        o0, o1, o2 = off[i, 0], off[i, 1], off[i, 2]
        if o0 == 0.0 and o1 == 0.0 and o2 == 0.0:
            pos[i, 0], pos[i, 1], pos[i, 2] = x[b, 0], x[b, 1], x[b, 2]
        else:
            r0, r1, r2 = rotate(q[b, 0], q[b, 1], q[b, 2], q[b, 3], o0, o1, o2)
            pos[i, 0], pos[i, 1], pos[i, 2] = x[b, 0] + r0, x[b, 1] + r1, x[b, 2] + r2


@numba.njit(cache=True, inline="always")
def _plane_contacts(contact, work, x, s, h, F, tau) -> None:  # noqa: ANN001
    """Every sphere against every plane its body's box meets (body_phase.py), spheres in index order and
    planes in theirs for each, as a test of every sphere against every plane would find them."""
    pos = work.sphere_position
    planes = contact.plane_point.shape[0]
    start, active, near = contact.body_sphere_start, work.body_active, work.body_plane
    for b in range(active.shape[0]):
        if not active[b] & ACTIVE_PLANE:
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
                _resolve(contact, work, x, s, h, i, PLANE_PARTNER_BASE - p, b, -1, n0, n1, n2, overlap,
                         c0, c1, c2, k, zeta, mu, F, tau)  # fmt: skip


@numba.njit(cache=True, inline="always")
def _pair(contact, work, x, s, h, i, j, d0, d1, d2, dist2, reach, F, tau) -> None:  # noqa: ANN001
    """The contact of spheres i and j, overlapping (d = p_i - p_j, |d|^2 = dist2 < reach^2)."""
    pos = work.sphere_position
    bi, bj = contact.sphere_body[i], contact.sphere_body[j]
    if bi == bj:
        return
    if contact.body_inv_contact_mass[bi] == 0.0 and contact.body_inv_contact_mass[bj] == 0.0:
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
    _resolve(contact, work, x, s, h, i, j, bi, bj, n0, n1, n2, overlap, c0, c1, c2, k, zeta, mu, F, tau)


@numba.njit(cache=True, inline="always")
def _velocity_at(work, x, b, c0, c1, c2):  # noqa: ANN001, ANN202
    v, w = work.body_velocity, work.body_omega
    r0, r1, r2 = c0 - x[b, 0], c1 - x[b, 1], c2 - x[b, 2]
    return (
        v[b, 0] + w[b, 1] * r2 - w[b, 2] * r1,
        v[b, 1] + w[b, 2] * r0 - w[b, 0] * r2,
        v[b, 2] + w[b, 0] * r1 - w[b, 1] * r0,
    )


@numba.njit(cache=True, inline="always")
def _push(x, b, c0, c1, c2, f0, f1, f2, F, tau) -> None:  # noqa: ANN001
    """Force f at world point c on body b."""
    r0, r1, r2 = c0 - x[b, 0], c1 - x[b, 1], c2 - x[b, 2]
    F[b, 0] += f0
    F[b, 1] += f1
    F[b, 2] += f2
    tau[b, 0] += r1 * f2 - r2 * f1
    tau[b, 1] += r2 * f0 - r0 * f2
    tau[b, 2] += r0 * f1 - r1 * f0


@numba.njit(cache=True, inline="always")
def _resolve(  # noqa: ANN202
    contact,
    work,
    x,
    s,
    h,
    owner,
    partner,
    ba,
    bb,
    n0,
    n1,
    n2,
    overlap,
    c0,
    c1,
    c2,
    k,
    zeta,
    mu,
    F,
    tau,  # noqa: ANN001
):
    """Force of one contact (module docstring) on body ba (owner) and bb (partner; -1: a plane)."""
    inv_a = contact.body_inv_contact_mass[ba]
    inv_b = contact.body_inv_contact_mass[bb] if bb >= 0 else 0.0
    m_eff = 1.0 / (inv_a + inv_b)
    va0, va1, va2 = _velocity_at(work, x, ba, c0, c1, c2)
    if bb >= 0:
        vb0, vb1, vb2 = _velocity_at(work, x, bb, c0, c1, c2)
        va0, va1, va2 = va0 - vb0, va1 - vb1, va2 - vb2
    vn = va0 * n0 + va1 * n1 + va2 * n2
    t0, t1, t2 = va0 - vn * n0, va1 - vn * n1, va2 - vn * n2
    cn = 2.0 * zeta * math.sqrt(k * m_eff)
    fn = k * overlap - cn * vn
    if fn < 0.0:  # a dashpot pulling the surfaces together is not a contact force
        fn = 0.0
    energy = 0.5 * k * overlap * overlap
    f0, f1, f2 = fn * n0, fn * n1, fn * n2
    if mu > 0.0:
        # the history of this contact, turned into the current tangent plane with its length kept
        x0, x1, x2 = 0.0, 0.0, 0.0
        for slot in range(work.hist_count[owner]):
            if work.hist_partner[owner, slot] == partner:
                x0, x1, x2 = work.hist_xi[owner, slot, 0], work.hist_xi[owner, slot, 1], work.hist_xi[owner, slot, 2]
                length2 = x0 * x0 + x1 * x1 + x2 * x2
                along = x0 * n0 + x1 * n1 + x2 * n2
                if along * along > 1e-12 * length2:  # else: a normal part < 1e-6 |xi| stays, harmless
                    x0, x1, x2 = x0 - along * n0, x1 - along * n1, x2 - along * n2
                    kept2 = x0 * x0 + x1 * x1 + x2 * x2
                    scale = math.sqrt(length2 / kept2) if kept2 > 0.0 else 0.0
                    x0, x1, x2 = x0 * scale, x1 * scale, x2 * scale
                break
        kt = contact.tangential_ratio * k
        ct = cn * math.sqrt(contact.tangential_ratio)  # 2 zeta sqrt(k_t m_eff)
        u0, u1, u2 = x0 + s * t0, x1 + s * t1, x2 + s * t2  # elongation now
        g0, g1, g2 = -kt * u0 - ct * t0, -kt * u1 - ct * t1, -kt * u2 - ct * t2
        ft2 = g0 * g0 + g1 * g1 + g2 * g2
        cap = mu * fn
        if ft2 > cap * cap:  # sliding: the force at the Coulomb limit, the spring stretched to match it
            scale = cap / math.sqrt(ft2)
            g0, g1, g2 = g0 * scale, g1 * scale, g2 * scale
            inv_kt = 1.0 / kt
            u0, u1, u2 = -(g0 + ct * t0) * inv_kt, -(g1 + ct * t1) * inv_kt, -(g2 + ct * t2) * inv_kt
        energy += 0.5 * kt * (u0 * u0 + u1 * u1 + u2 * u2)
        f0, f1, f2 = f0 + g0, f1 + g1, f2 + g2
        slot = work.trial_count[owner]
        if slot < work.trial_partner.shape[1]:  # commit_contacts advances it to the end of the step
            work.trial_partner[owner, slot] = partner
            work.trial_xi[owner, slot, 0], work.trial_xi[owner, slot, 1], work.trial_xi[owner, slot, 2] = u0, u1, u2
            work.trial_normal[owner, slot, 0], work.trial_normal[owner, slot, 1] = n0, n1
            work.trial_normal[owner, slot, 2] = n2
            work.trial_point[owner, slot, 0], work.trial_point[owner, slot, 1] = c0, c1
            work.trial_point[owner, slot, 2] = c2
            work.trial_limit[owner, slot] = cap / kt
            work.trial_count[owner] = slot + 1
        else:
            work.counters[COUNT_OVERFLOW] += 1
    _push(x, ba, c0, c1, c2, f0, f1, f2, F, tau)
    if bb >= 0:
        _push(x, bb, c0, c1, c2, -f0, -f1, -f2, F, tau)
    work.stats[STAT_CONTACTS] += 1.0
    work.stats[STAT_MAX_PENETRATION] = max(work.stats[STAT_MAX_PENETRATION], overlap)
    work.stats[STAT_ENERGY] += energy
    work.counters[COUNT_CONTACTS] += 1
