"""The contact force law: spring-dashpot normal force and Coulomb-capped tangential spring of one contact
(the formulas are force.py's module docstring), in pieces its users share: the force stage (force.py)
uses all of them, the recorded contact points (points.py) the relative velocity and the normal force,
the recorded state's statistics (state.py) the history. Body velocities are in ContactWork
(`body_velocities` fills them once per evaluation).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba

from rbcli.physics.contact.tables import (
    COUNT_CONTACTS,
    COUNT_OVERFLOW,
    ROWS_TRIAL,
    STAT_CONTACTS,
    STAT_ENERGY,
    STAT_MAX_PENETRATION,
)
from rbcli.physics.rotation_kernels import rotate, rotate_inverse


class ContactGeometry(NamedTuple):
    """One contact as the search found it (search.py `contact_found`): contact sphere `owner` of body
    `body_a` touching `partner` (a sphere of body `body_b`, or a plane: body_b = -1), the unit normal
    n pointing from b to a, the overlap d [m] and the contact point c [m, world]. Built inside kernels
    and inlined away (LLVM keeps the scalars in registers: the same machine code as passing them one by
    one)."""

    owner: int
    partner: int
    body_a: int
    body_b: int
    normal: tuple[float, float, float]
    overlap: float
    point: tuple[float, float, float]


class ContactOutcome(NamedTuple):
    """What one contact does (`contact_values`): the force f [N, world] on body_a at the contact point
    (body_b gets -f), the tangential spring's elongation u [m, world] at the evaluation's offset into the
    step, its Coulomb limit mu f_n / k_t [m] (0 without friction) and the energy in its springs [J]."""

    force: tuple[float, float, float]
    elongation: tuple[float, float, float]
    limit: float
    energy: float


@numba.njit(cache=True, inline="always")
def body_velocities(model, work, x, q, P, L) -> None:  # noqa: ANN001
    """v = P / M and w = R I^-1 R^T L of every body (static bodies: 0) into work.body_velocity/omega."""
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
def velocity_at(work, x, b, c0, c1, c2):  # noqa: ANN001, ANN201
    """v_b + w_b x (c - x_b) [m/s, world]: the velocity of body b's material point at c."""
    v, w = work.body_velocity, work.body_omega
    r0, r1, r2 = c0 - x[b, 0], c1 - x[b, 1], c2 - x[b, 2]
    return (
        v[b, 0] + w[b, 1] * r2 - w[b, 2] * r1,
        v[b, 1] + w[b, 2] * r0 - w[b, 0] * r2,
        v[b, 2] + w[b, 0] * r1 - w[b, 1] * r0,
    )


@numba.njit(cache=True, inline="always")
def relative_velocity(contact, work, x, ba, bb, n0, n1, n2, c0, c1, c2):  # noqa: ANN001, ANN201
    """(m_eff, v_n, v_t) of a contact at c: m_eff = 1 / (1/m_a + 1/m_b) [kg] (tables.py's per-sphere
    contact masses; bb = -1, a plane: m_b infinite), and the velocity of a's point at c relative to b's,
    v = v_a(c) - v_b(c), split into v_n = v . n [m/s] and v_t = v - v_n n [m/s, world]."""
    # a plane contact: the plane's inverse contact mass of the body (tables.py: a primitive's manifold
    # points share its mass; for spheres the same number as body_inv_contact_mass)
    inv_a = contact.body_inv_contact_mass[ba] if bb >= 0 else contact.body_plane_inv_contact_mass[ba]
    inv_b = contact.body_inv_contact_mass[bb] if bb >= 0 else 0.0
    m_eff = 1.0 / (inv_a + inv_b)
    va0, va1, va2 = velocity_at(work, x, ba, c0, c1, c2)
    if bb >= 0:
        vb0, vb1, vb2 = velocity_at(work, x, bb, c0, c1, c2)
        va0, va1, va2 = va0 - vb0, va1 - vb1, va2 - vb2
    vn = va0 * n0 + va1 * n1 + va2 * n2
    return m_eff, vn, va0 - vn * n0, va1 - vn * n1, va2 - vn * n2


@numba.njit(cache=True, inline="always")
def normal_force(k, zeta, m_eff, overlap, vn):  # noqa: ANN001, ANN201
    """(f_n, c_n): f_n = max(0, k d - c_n v_n) [N] with c_n = 2 zeta sqrt(k m_eff) [N s/m]."""
    cn = 2.0 * zeta * math.sqrt(k * m_eff)
    fn = k * overlap - cn * vn
    if fn < 0.0:  # a dashpot pulling the surfaces together is not a contact force
        fn = 0.0
    return fn, cn


@numba.njit(cache=True, inline="always")
def history_elongation(work, owner, partner, n0, n1, n2):  # noqa: ANN001, ANN201
    """The contact's tangential spring xi_0 [m, world] at the start of the step (0 for a new contact),
    turned into the current tangent plane (its component along n removed) with its length kept."""
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
    return x0, x1, x2


@numba.njit(cache=True, inline="always")
def tangential_force(tangential_ratio, work, s, owner, partner, n0, n1, n2, t0, t1, t2, k, cn, fn, mu):  # noqa: ANN001, ANN201
    """(f_t, u, k_t) at offset s into the step: the spring's elongation u = xi_0 + s v_t [m] and
    f_t = -k_t u - c_t v_t [N], k_t = tangential_ratio k, c_t = c_n sqrt(tangential_ratio) (= 2 zeta
    sqrt(k_t m_eff)); beyond |f_t| = mu f_n (sliding) f_t is scaled back to the limit and u set to match."""
    x0, x1, x2 = history_elongation(work, owner, partner, n0, n1, n2)
    kt = tangential_ratio * k
    ct = cn * math.sqrt(tangential_ratio)  # 2 zeta sqrt(k_t m_eff)
    u0, u1, u2 = x0 + s * t0, x1 + s * t1, x2 + s * t2  # elongation now
    g0, g1, g2 = -kt * u0 - ct * t0, -kt * u1 - ct * t1, -kt * u2 - ct * t2
    ft2 = g0 * g0 + g1 * g1 + g2 * g2
    cap = mu * fn
    if ft2 > cap * cap:  # sliding: the force at the Coulomb limit, the spring stretched to match it
        scale = cap / math.sqrt(ft2)
        g0, g1, g2 = g0 * scale, g1 * scale, g2 * scale
        inv_kt = 1.0 / kt
        u0, u1, u2 = -(g0 + ct * t0) * inv_kt, -(g1 + ct * t1) * inv_kt, -(g2 + ct * t2) * inv_kt
    return g0, g1, g2, u0, u1, u2, kt


@numba.njit(cache=True, inline="always")
def push(x, b, c0, c1, c2, f0, f1, f2, F, tau) -> None:  # noqa: ANN001
    """Force f [N] at world point c on body b: F += f, tau += (c - x_b) x f (about its centre of mass)."""
    r0, r1, r2 = c0 - x[b, 0], c1 - x[b, 1], c2 - x[b, 2]
    F[b, 0] += f0
    F[b, 1] += f1
    F[b, 2] += f2
    tau[b, 0] += r1 * f2 - r2 * f1
    tau[b, 1] += r2 * f0 - r0 * f2
    tau[b, 2] += r0 * f1 - r1 * f0


@numba.njit(cache=True, inline="always")
def contact_values(contact, work, x, s, geometry, k, zeta, mu):  # noqa: ANN001, ANN201
    """What one contact (a ContactGeometry) does, a ContactOutcome (module docstring), computed from the
    state and the history alone, at offset s [s] into the step, with stiffness k [N/m], damping ratio
    zeta and friction coefficient mu. Reads, writes nothing: the threaded search (threaded.py) computes it
    on any thread and `apply_contact` does what it says in the search's order."""
    owner, partner, ba, bb = geometry.owner, geometry.partner, geometry.body_a, geometry.body_b
    n0, n1, n2 = geometry.normal
    c0, c1, c2 = geometry.point
    overlap = geometry.overlap
    m_eff, vn, t0, t1, t2 = relative_velocity(contact, work, x, ba, bb, n0, n1, n2, c0, c1, c2)
    fn, cn = normal_force(k, zeta, m_eff, overlap, vn)
    energy = 0.5 * k * overlap * overlap
    f0, f1, f2 = fn * n0, fn * n1, fn * n2
    u0, u1, u2, limit = 0.0, 0.0, 0.0, 0.0
    if mu > 0.0:
        g0, g1, g2, u0, u1, u2, kt = tangential_force(contact.tangential_ratio, work, s, owner, partner,
                                                      n0, n1, n2, t0, t1, t2, k, cn, fn, mu)  # fmt: skip
        energy += 0.5 * kt * (u0 * u0 + u1 * u1 + u2 * u2)
        f0, f1, f2 = f0 + g0, f1 + g1, f2 + g2
        limit = mu * fn / kt
    return ContactOutcome((f0, f1, f2), (u0, u1, u2), limit, energy)


@numba.njit(cache=True, inline="always")
def apply_contact(work, x, F, tau, geometry, friction, outcome) -> None:  # noqa: ANN001
    """Do what `contact_values` computed (`outcome`) for the contact `geometry`: the force and torque on
    both bodies (F, tau), the spring proposed to the history (trial arrays, when the contact has
    `friction`; commit_contacts advances it to the end of the step), the evaluation's statistics and
    counters."""
    owner, ba, bb = geometry.owner, geometry.body_a, geometry.body_b
    n0, n1, n2 = geometry.normal
    c0, c1, c2 = geometry.point
    f0, f1, f2 = outcome.force
    if friction:
        slot = work.trial_count[owner]
        if slot < work.trial_partner.shape[1]:
            u0, u1, u2 = outcome.elongation
            work.trial_partner[owner, slot] = geometry.partner
            work.trial_xi[owner, slot, 0], work.trial_xi[owner, slot, 1] = u0, u1
            work.trial_xi[owner, slot, 2] = u2
            work.trial_normal[owner, slot, 0], work.trial_normal[owner, slot, 1] = n0, n1
            work.trial_normal[owner, slot, 2] = n2
            work.trial_point[owner, slot, 0], work.trial_point[owner, slot, 1] = c0, c1
            work.trial_point[owner, slot, 2] = c2
            work.trial_limit[owner, slot] = outcome.limit
            work.trial_count[owner] = slot + 1
            if slot == 0:  # the row's first trial: listed for the commit and the next clearing
                listed = work.row_counts[ROWS_TRIAL]
                work.trial_rows[listed] = owner
                work.row_counts[ROWS_TRIAL] = listed + 1
        else:
            work.counters[COUNT_OVERFLOW] += 1
            if work.overflow_sphere[0] < 0:
                work.overflow_sphere[0] = owner
    push(x, ba, c0, c1, c2, f0, f1, f2, F, tau)
    if bb >= 0:
        push(x, bb, c0, c1, c2, -f0, -f1, -f2, F, tau)
    work.stats[STAT_CONTACTS] += 1.0
    work.stats[STAT_MAX_PENETRATION] = max(work.stats[STAT_MAX_PENETRATION], geometry.overlap)
    work.stats[STAT_ENERGY] += outcome.energy
    work.counters[COUNT_CONTACTS] += 1
