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
at offset s into a step of length h uses u = xi_0 + s v_t (xi_0: the history at the start of the step)
and writes u to the trial arrays; once the step is complete, the pipeline's contact_commit stage
advances the last evaluation's u to the end of the step, xi = u + (h - s) v_t with the end-of-step
velocities (`commit_contacts`). A tangential spring with a Coulomb cap lets a body rest on a slope
without creeping (a viscous tangential law creeps), which is why it is used; see docs/contact.md.

Where the pieces are: the contacts come from the one contact search (search.py: planes, the grid walk,
the mixed materials), the formulas from law.py, the search's sink from sink.py; this module is the stage
that applies them, and the stages around the update (the clock, the commit, static bodies held).
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.contact.implicit_rows import implicit_begin
from rbcli.physics.contact.law import body_velocities, velocity_at
from rbcli.physics.contact.quiet import try_quiet
from rbcli.physics.contact.search import sphere_positions
from rbcli.physics.contact.sink import force_sink
from rbcli.physics.contact.tables import COUNT_CANDIDATES, COUNT_EVALUATIONS, QUIET_SURE, ROWS_HISTORY, ROWS_TRIAL
from rbcli.physics.contact.threaded import contact_search
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL


@numba.njit(**STEP_KERNEL)
def begin_contact_step(work, t, h) -> None:  # noqa: ANN001
    """Note the step [t, t + h) being taken: force evaluations measure their offset into it. A sure quiet
    window (quiet.py) holds only for steps of the h it was set at: another h (adaptive stepping, a call
    with another dt) ends its sureness, and the evaluations test the paths again."""
    work.clock[0] = t
    work.clock[1] = h
    if h != work.quiet_window[2]:
        work.quiet_state[QUIET_SURE] = 0


@separately_compiled
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
        body_velocities(model, work, x, q, P, L)
    # only the rows listed hold trial contacts (law.apply_contact) or history (the last commit): each row
    # is committed on its own, so visiting the listed rows gives what visiting every row gave; where the
    # history rows are not known (a restored run), every row is visited once, and listed
    trial_rows, history_rows, counts = work.trial_rows, work.history_rows, work.row_counts
    listed = counts[ROWS_HISTORY]
    if listed < 0:
        listed = 0
        for i in range(work.hist_count.shape[0]):
            if work.hist_count[i]:
                history_rows[listed] = i
                listed += 1
    for k in range(listed):  # contacts not found again are forgotten
        i = history_rows[k]
        if work.trial_count[i] == 0:
            work.hist_count[i] = 0
    for r in range(counts[ROWS_TRIAL]):
        i = trial_rows[r]
        history_rows[r] = i
        count = work.trial_count[i]
        work.hist_count[i] = count
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
            v0, v1, v2 = velocity_at(work, x, ba, c0, c1, c2)
            if partner >= 0:
                w0, w1, w2 = velocity_at(work, x, contact.sphere_body[partner], c0, c1, c2)
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
    counts[ROWS_HISTORY] = counts[ROWS_TRIAL]
    held = counts[ROWS_TRIAL] > 0
    if not held:  # nothing touches: the stages may rest while every body stays within its skin (quiet.py)
        try_quiet(contact, work, x)


@numba.njit(**STEP_KERNEL)
def hold_static_bodies(contact, F, tau) -> None:  # noqa: ANN001
    """Static bodies feel nothing: their wrench is set to zero after every other force stage."""
    for r in range(contact.static_body.shape[0]):
        b = contact.static_body[r]
        F[b, 0] = F[b, 1] = F[b, 2] = 0.0
        tau[b, 0] = tau[b, 1] = tau[b, 2] = 0.0


@separately_compiled
@numba.njit(**STEP_KERNEL)
def accumulate_contact(model, contact, work, t, x, q, P, L, F, tau) -> None:  # noqa: ANN001
    """Add every contact's force and torque to F and tau (world frame, about each centre of mass)."""
    body_velocities(model, work, x, q, P, L)
    flagged = sphere_positions(contact, work, x, q)  # the two-level broad phase: flags the bodies that may touch
    # trial contacts cleared only in the rows the last evaluation gave some (law.apply_contact lists them)
    rows = work.trial_rows
    for k in range(work.row_counts[ROWS_TRIAL]):
        work.trial_count[rows[k]] = 0
    work.row_counts[ROWS_TRIAL] = 0
    work.stats[:] = 0.0
    work.counters[COUNT_EVALUATIONS] += 1
    implicit_begin(work)  # the contacts kept for reduced-implicit (implicit_rows.py) are this evaluation's
    s = t - work.clock[0]
    work.clock[2] = s
    if not flagged:  # nothing can touch: no search (search.py)
        return
    # the serial search, or the same contacts and sums with the walk and force law on threads (threaded.py)
    work.counters[COUNT_CANDIDATES] += contact_search(contact, work, force_sink(x, s, F, tau, work))
