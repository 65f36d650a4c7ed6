"""`split2`: second-order symplectic splitting, exact rotations about the principal axes.

The Hamiltonian H = |P|^2/(2M) + T_1 + T_2 + T_3 + V, with T_k = m_k^2/(2 I_k) the kinetic energy of
the rotation about principal axis k (m = R^T L the body-frame angular momentum), is split into pieces
whose flows are exact and cheap (McLachlan 1993; Reich 1994; Dullweber, Leimkuhler & McLachlan 1997,
"Symplectic splitting methods for rigid body molecular dynamics", J. Chem. Phys. 107):
  D_x(s): x += s P/M                                        (free flight of the centre of mass)
  T_k(s): turn the body by theta = s m_k/I_k about its axis k (kinematics.turn; L fixed in the world)
  K(s):   P += s F, L += s tau                              (the force kick, one wrench evaluation)
composed symmetrically with the kick in the middle:

  D_x(h/2) T_a(h/2) T_b(h/2) T_c(h/2)  K(h)  T_c(h/2) T_b(h/2) T_a(h/2) D_x(h/2)

with I_a <= I_b <= I_c. Torque-free, T_c(h/2) K T_c(h/2) = T_c(h) (m_c is unchanged by the kick), so
the rotation is the classical R_a(h/2) R_b(h/2) R_c(h) R_b(h/2) R_a(h/2) and costs 5 sin/cos pairs;
this is decided per body (`ForceTables.torque_body`): in a scene with torques only the bodies that
some term can give a torque pay the kick of m and a sixth sin/cos pair (the others' tau is 0, and
their two T_c(h/2) turns reuse one (cos, sin): bitwise what the torque path gives with tau = 0). For
the centre of mass D_x(h/2) K(h) D_x(h/2) is the leapfrog (position Verlet, the same trajectory
family as velocity Verlet), exact for a uniform force such as gravity.

Why the kick sits in the middle: every step then needs exactly ONE force evaluation, at the symmetric
midpoint (t + h/2, x_1/2, q_1/2), always fresh. The kick-drift-kick order needs the force at both ends;
reusing the end-of-step force at the start of the next call would save one evaluation but is only
valid if nothing (impulses, a restarted run, a changed dt) touched the state in between — it is not
done. Velocity-dependent forces (dampers, drag) would make this, like velocity Verlet, first order in
that term (the kick would no longer be symmetric); they are taken out of the kick and integrated as their
own symmetric flow instead, K(h) = K_c(h/2) D(h) K_c(h/2) (forces/damping.py), which keeps the order.

Round-off: m is carried from one step to the next in the scratch (rebuilt as R^T L only when something
else wrote q or L), the turns rotate m in the form m + (cos - 1) m + sin m_perp, and in split4 m's sums
are compensated: near the separatrix each of the older choices leaked ~1e-11 rad per step
(docs/accuracy.md). split2 skips the compensation: its truncation error is far above that floor at any
step it is used at, and it would cost ~20 % per body-step. With dampers or drag a step costs the
dissipation flow besides (the 4-link spring chain: 0.9 -> 2.3 us per step for split2, 4.6 -> 8 us for
split4, measured on a loaded 2-core machine).

Axis order: which moment gets the outer half steps and which the full middle step changes the error
constant by up to 1000x. Measured over 20 s at dt = 0.01 against the exact solution (flip:
I = diag(1, 2, 3), omega0 = (0.01, 5, 0); generic: omega0 = (1, 1, 2); thin rod I = diag(1, 1, 1e-3),
omega0 = (0.3, 0, 100)), outer = smallest moment (the fastest turn), centre = largest is the best or
within 15 % of it everywhere: flip 6.3e-3 rad (worst order 6.3e-2), generic 6.2e-4 (best 5.4e-4),
rod 1.5e-6 to 4e-6 (worst 2.5 rad), and at fast spin it keeps the energy error at 6.7 % where other
orders reach 45 to 160 % (table in docs/integrators.md).

Isotropic bodies (I1 = I2 = I3: balls, kinematic bodies): T_a T_b T_c is replaced by the exact flow of
the whole rotational energy |L|^2 / (2 I), a turn about the world-fixed omega = L / I (one sin/cos pair
instead of five or six; the axis pieces do not commute, so for these bodies the composition only
approximated what is now exact). The 1,000-ball pile of the collisions issue ran 26x -> 31x MuJoCo.

Properties: symplectic and time-reversible; order 2; L exactly conserved torque-free (it is never
touched), |m| = |L| exactly, energy error bounded (no drift); one force evaluation per step.
`compose` also runs any symmetric composition of this step (split4) with the half drifts of adjacent
stages merged: D_x and T_a of one stage's end and the next stage's start commute with nothing in
between, so s stages cost s + 1 passes over the bodies and s force evaluations.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.forces.damping import dissipation_flow, dissipation_flow_numpy, dissipation_present
from rbcli.physics.forces.wrench import accumulate_wrench, wrench_numpy
from rbcli.physics.integrators.kinematics import (
    axis_order,
    axis_order_numpy,
    body_momentum_numpy,
    carried_momentum_valid,
    half_turn,
    rotate_inverse,
    sum_compensated,
    turn_numpy,
)
from rbcli.physics.integrators.kinematics import turn as turn_plain
from rbcli.physics.integrators.kinematics import (
    turn_compensated as turn,
)
from rbcli.physics.rotation import quat_multiply
from rbcli.physics.step import STEP_ENTRY, STEP_KERNEL

# per body: body-frame angular momentum m (3), cos and sin of the half angle of the last T_c (2), and
# the q (4) and L (3) the last step wrote, to which the m carried to the next step belongs
SCRATCH_WIDTH = 18
_Q_END = 5
_L_END = 9
_M_COMP = 12  # the compensation of m's sums (kinematics.turn_compensated)
_L_SAVED = 15  # L before the dissipation flow (damped scenes), to turn its change into m's

# a single stage: the plain Strang step
WEIGHTS = np.array([1.0])


@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One split2 step of every body, in place (one force evaluation, at t + dt/2)."""
    compose(model, forces, contact, force_data, t, dt, WEIGHTS, x, q, P, L, F, tau, scratch, False)


@numba.njit(**STEP_KERNEL, parallel=True)
def step_parallel(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001
    """`step` with its two passes over the bodies (`_drift_to_first_kick`, `_kick_and_drift`: prange
    loops, inlined here) spread over numba's threads; the force evaluation and the stages around the
    step stay serial. Each body's arithmetic is the serial step's, nothing is summed across bodies, so
    any thread count gives the same bits as `step` (tests/physics/test_threaded_loop.py). A function of its
    own, not `numba.njit(parallel=True)(step.py_func)`: numba's cache is keyed on the function's name
    and line, and the two would overwrite each other's cached code. docs/performance.md, "Threads"."""
    compose(model, forces, contact, force_data, t, dt, WEIGHTS, x, q, P, L, F, tau, scratch, False)


# compose and its two passes are inlined at numba level: a call boundary costs a reference-count
# update per array argument (the model and force tables hold dozens), measured 2.25 -> 1.65 us per
# step for one body, and 93 -> 88 ns per body-step at 100 bodies.
@numba.njit(cache=True, inline="always")
def compose(model, forces, contact, force_data, t, h, weights, x, q, P, L, F, tau, scratch, compensate) -> None:  # noqa: ANN001
    """The composition split2(w_{s-1} h) ... split2(w_0 h) of every body, in place.

    compensate: m's sums in the turns compensated (split4, which reaches the round-off floor; split2's
    error is its truncation long before, and the compensation would cost it ~20 % per body-step).
    weights (s,) must be symmetric for the composition to be; force evaluation i happens at the
    midpoint of stage i, t + (w_0 + ... + w_{i-1} + w_i/2) h.
    With dampers or drag (forces/damping.py) the kick K(h) is K_c(h/2) D(h) K_c(h/2): F_c without the
    dissipative terms, D their own symmetric flow, so the step stays symmetric and keeps its order.
    """
    count = weights.shape[0]
    dissipative = dissipation_present(forces.spring, forces.drag)
    _drift_to_first_kick(model, weights[0] * h, x, q, P, L, scratch, compensate)
    elapsed = 0.5 * weights[0] * h
    for i in range(count):
        accumulate_wrench(model, forces, contact, force_data, t + elapsed, x, q, P, L, F, tau, not dissipative)
        h_prev = weights[i] * h
        h_next = weights[i + 1] * h if i + 1 < count else 0.0
        kick = h_prev
        if dissipative:
            kick = 0.5 * h_prev
            _half_kick(model, forces.has_torque, forces.torque_body, kick, q, P, L, F, tau, scratch)
            dissipation_flow(model, forces.spring, forces.drag, force_data.damper, h_prev, x, q, P, L)
            _momentum_change_to_body(model, forces.has_torque, forces.torque_body, q, L, scratch)
        _kick_and_drift(
            model,
            forces.has_torque,
            forces.torque_body,
            dissipative,
            kick,
            h_prev,
            h_next,
            x,
            q,
            P,
            L,
            F,
            tau,
            scratch,
            compensate,
        )
        elapsed += 0.5 * (h_prev + h_next)


@numba.njit(cache=True)
def _half_kick(model, has_torque, torque_body, kick, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001
    """K_c(kick) before the dissipation flow: P += kick F, and for torque bodies L += kick tau with m
    following (m += kick R^T tau); L is then saved for `_momentum_change_to_body`."""
    for b in range(P.shape[0]):
        P[b, 0] += kick * F[b, 0]
        P[b, 1] += kick * F[b, 1]
        P[b, 2] += kick * F[b, 2]
        if has_torque and torque_body[b]:
            t0, t1, t2 = tau[b, 0], tau[b, 1], tau[b, 2]
            if t0 != 0.0 or t1 != 0.0 or t2 != 0.0:  # tau = 0: L and m as they are (up to the sign of a zero)
                L[b, 0] += kick * t0
                L[b, 1] += kick * t1
                L[b, 2] += kick * t2
                tb0, tb1, tb2 = rotate_inverse(q[b, 0], q[b, 1], q[b, 2], q[b, 3], t0, t1, t2)
                scratch[b, 0], scratch[b, _M_COMP] = sum_compensated(scratch[b, 0], kick * tb0, scratch[b, _M_COMP])
                scratch[b, 1], scratch[b, _M_COMP + 1] = sum_compensated(
                    scratch[b, 1], kick * tb1, scratch[b, _M_COMP + 1]
                )
                scratch[b, 2], scratch[b, _M_COMP + 2] = sum_compensated(
                    scratch[b, 2], kick * tb2, scratch[b, _M_COMP + 2]
                )
            scratch[b, _L_SAVED], scratch[b, _L_SAVED + 1], scratch[b, _L_SAVED + 2] = L[b, 0], L[b, 1], L[b, 2]


@numba.njit(cache=True)
def _momentum_change_to_body(model, has_torque, torque_body, q, L, scratch) -> None:  # noqa: ANN001
    """m += R^T (L - L_saved): the dissipation flow's change of L (q held) in the body frame. Only
    torque bodies can have one (a damper off the centre of mass or angular drag flags its body)."""
    if not has_torque:
        return
    for b in range(L.shape[0]):
        if torque_body[b]:
            d0 = L[b, 0] - scratch[b, _L_SAVED]
            d1 = L[b, 1] - scratch[b, _L_SAVED + 1]
            d2 = L[b, 2] - scratch[b, _L_SAVED + 2]
            if d0 == 0.0 and d1 == 0.0 and d2 == 0.0:  # the flow left L (no angular damping here): m as it is
                continue
            db0, db1, db2 = rotate_inverse(q[b, 0], q[b, 1], q[b, 2], q[b, 3], d0, d1, d2)
            scratch[b, 0], scratch[b, _M_COMP] = sum_compensated(scratch[b, 0], db0, scratch[b, _M_COMP])
            scratch[b, 1], scratch[b, _M_COMP + 1] = sum_compensated(scratch[b, 1], db1, scratch[b, _M_COMP + 1])
            scratch[b, 2], scratch[b, _M_COMP + 2] = sum_compensated(scratch[b, 2], db2, scratch[b, _M_COMP + 2])


@numba.njit(cache=True, inline="always")
def _flow_moved(L, scratch, b) -> bool:  # noqa: ANN001
    """Whether the dissipation flow changed body b's L (L differs from what `_half_kick` saved): its m moved."""
    return L[b, 0] != scratch[b, _L_SAVED] or L[b, 1] != scratch[b, _L_SAVED + 1] or L[b, 2] != scratch[b, _L_SAVED + 2]


@numba.njit(cache=True, inline="always")
def _drift_to_first_kick(model, h, x, q, P, L, scratch, compensate) -> None:  # noqa: ANN001
    """D_x(h/2) T_a(h/2) T_b(h/2) T_c(h/2); leaves m and T_c's (cos, sin) in scratch.
    An isotropic body (a ball) turns by its exact free rotation T(h/2) instead (`_turn_isotropic`).
    prange: a plain range in `step`, a loop over threads in `step_parallel` (each body on its own)."""
    for b in numba.prange(x.shape[0]):
        inv0, inv1, inv2 = model.body_inertia_inv[b, 0], model.body_inertia_inv[b, 1], model.body_inertia_inv[b, 2]
        drift = 0.5 * h / model.body_mass[b]
        x[b, 0] += drift * P[b, 0]
        x[b, 1] += drift * P[b, 1]
        x[b, 2] += drift * P[b, 2]
        if inv0 == inv1 and inv1 == inv2:
            _turn_isotropic(q, L, b, 0.5 * h * inv0)
            continue
        ka, kb, kc = axis_order(model.body_inertia[b, 0], model.body_inertia[b, 1], model.body_inertia[b, 2])
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        if carried_momentum_valid(scratch[b], _Q_END, _L_END, q, L, b):  # m of the last step, not R^T L
            m0, m1, m2 = scratch[b, 0], scratch[b, 1], scratch[b, 2]
            e0, e1, e2 = scratch[b, _M_COMP], scratch[b, _M_COMP + 1], scratch[b, _M_COMP + 2]
        else:
            m0, m1, m2 = rotate_inverse(w, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2])
            e0, e1, e2 = 0.0, 0.0, 0.0
        c, s = half_turn(ka, 0.5 * h, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, e0, e1, e2, w, qx, qy, qz = turn(ka, c, s, m0, m1, m2, e0, e1, e2, w, qx, qy, qz, compensate)
        c, s = half_turn(kb, 0.5 * h, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, e0, e1, e2, w, qx, qy, qz = turn(kb, c, s, m0, m1, m2, e0, e1, e2, w, qx, qy, qz, compensate)
        c, s = half_turn(kc, 0.5 * h, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, e0, e1, e2, w, qx, qy, qz = turn(kc, c, s, m0, m1, m2, e0, e1, e2, w, qx, qy, qz, compensate)
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = w, qx, qy, qz
        scratch[b, 0], scratch[b, 1], scratch[b, 2] = m0, m1, m2
        scratch[b, _M_COMP], scratch[b, _M_COMP + 1], scratch[b, _M_COMP + 2] = e0, e1, e2
        scratch[b, 3], scratch[b, 4] = c, s


@numba.njit(cache=True, inline="always")
def _kick_and_drift(
    model, has_torque, torque_body, m_moved, kick, h_prev, h_next, x, q, P, L, F, tau, scratch, compensate
) -> None:  # noqa: ANN001
    """K(kick) T_c(h_prev/2) T_b(h_prev/2) [T_a D_x]((h_prev + h_next)/2) T_b(h_next/2) T_c(h_next/2).

    kick is h_prev, or h_prev / 2 when the dissipation flow took the other half's place (compose).
    h_next = 0 ends the step (the last two turns are skipped). The torque kick runs only for the bodies
    torque_body flags whose tau this evaluation is not zero, or, when m_moved (a damped scene: the half
    kick and the dissipation flow ran), whose L the flow changed (`_flow_moved`; the half kick leaves m
    alone where tau is zero, and so does `_momentum_change_to_body` where the flow left L: a damped far
    contact scene turned every body's last turn again, ~45 ns per body-step); the others' m_c is
    unchanged, so T_c reuses the turn of the previous pass (the very same (cos, sin): the result of the
    torque path with tau = 0, up to the sign of a zero: L = -0.0 plus 0 is +0.0). Why tau is tested,
    not only torque_body: a contact body far from anything, a spring at rest, a torque outside its
    window has tau = 0 in most steps, and skipping its sixth sin/cos pair and the kick of m saves
    ~27 ns per body-step (benchmarks/bench_contact.py far, two tumbling bricks with contact: 208 -> 153
    ns per step).
    """
    for b in numba.prange(x.shape[0]):
        inv0, inv1, inv2 = model.body_inertia_inv[b, 0], model.body_inertia_inv[b, 1], model.body_inertia_inv[b, 2]
        if inv0 == inv1 and inv1 == inv2:  # K(h_prev), then T((h_prev + h_next)/2) D_x((h_prev + h_next)/2)
            h_mid = 0.5 * (h_prev + h_next)
            P[b, 0] += kick * F[b, 0]
            P[b, 1] += kick * F[b, 1]
            P[b, 2] += kick * F[b, 2]
            if has_torque and torque_body[b] and (tau[b, 0] != 0.0 or tau[b, 1] != 0.0 or tau[b, 2] != 0.0):
                L[b, 0] += kick * tau[b, 0]
                L[b, 1] += kick * tau[b, 1]
                L[b, 2] += kick * tau[b, 2]
            _turn_isotropic(q, L, b, h_mid * inv0)
            drift = h_mid / model.body_mass[b]
            x[b, 0] += drift * P[b, 0]
            x[b, 1] += drift * P[b, 1]
            x[b, 2] += drift * P[b, 2]
            if h_next == 0.0:
                w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
                norm = 1.0 / math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
                q[b, 0], q[b, 1], q[b, 2], q[b, 3] = w * norm, qx * norm, qy * norm, qz * norm
            continue
        ka, kb, kc = axis_order(model.body_inertia[b, 0], model.body_inertia[b, 1], model.body_inertia[b, 2])
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        m0, m1, m2 = scratch[b, 0], scratch[b, 1], scratch[b, 2]
        e0, e1, e2 = scratch[b, _M_COMP], scratch[b, _M_COMP + 1], scratch[b, _M_COMP + 2]
        P[b, 0] += kick * F[b, 0]
        P[b, 1] += kick * F[b, 1]
        P[b, 2] += kick * F[b, 2]
        if (
            has_torque
            and torque_body[b]
            and (tau[b, 0] != 0.0 or tau[b, 1] != 0.0 or tau[b, 2] != 0.0 or (m_moved and _flow_moved(L, scratch, b)))
        ):
            t0, t1, t2 = tau[b, 0], tau[b, 1], tau[b, 2]
            L[b, 0] += kick * t0
            L[b, 1] += kick * t1
            L[b, 2] += kick * t2
            tb0, tb1, tb2 = rotate_inverse(w, qx, qy, qz, t0, t1, t2)
            m0, e0 = sum_compensated(m0, kick * tb0, e0)
            m1, e1 = sum_compensated(m1, kick * tb1, e1)
            m2, e2 = sum_compensated(m2, kick * tb2, e2)
            c, s = half_turn(kc, 0.5 * h_prev, m0, m1, m2, inv0, inv1, inv2)
        else:  # m_c is what it was before the kick: the same turn as T_c of the previous pass
            c, s = scratch[b, 3], scratch[b, 4]
        m0, m1, m2, e0, e1, e2, w, qx, qy, qz = turn(kc, c, s, m0, m1, m2, e0, e1, e2, w, qx, qy, qz, compensate)
        c, s = half_turn(kb, 0.5 * h_prev, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, e0, e1, e2, w, qx, qy, qz = turn(kb, c, s, m0, m1, m2, e0, e1, e2, w, qx, qy, qz, compensate)
        h_mid = 0.5 * (h_prev + h_next)
        c, s = half_turn(ka, h_mid, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, e0, e1, e2, w, qx, qy, qz = turn(ka, c, s, m0, m1, m2, e0, e1, e2, w, qx, qy, qz, compensate)
        drift = h_mid / model.body_mass[b]
        x[b, 0] += drift * P[b, 0]
        x[b, 1] += drift * P[b, 1]
        x[b, 2] += drift * P[b, 2]
        if h_next != 0.0:
            c, s = half_turn(kb, 0.5 * h_next, m0, m1, m2, inv0, inv1, inv2)
            m0, m1, m2, e0, e1, e2, w, qx, qy, qz = turn(kb, c, s, m0, m1, m2, e0, e1, e2, w, qx, qy, qz, compensate)
            c, s = half_turn(kc, 0.5 * h_next, m0, m1, m2, inv0, inv1, inv2)
            m0, m1, m2, e0, e1, e2, w, qx, qy, qz = turn(kc, c, s, m0, m1, m2, e0, e1, e2, w, qx, qy, qz, compensate)
            scratch[b, 3], scratch[b, 4] = c, s
        else:  # end of the step: products of unit quaternions drift off |q| = 1 by round-off, a random walk
            norm = 1.0 / math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
            w, qx, qy, qz = w * norm, qx * norm, qy * norm, qz * norm
            scratch[b, _Q_END], scratch[b, _Q_END + 1], scratch[b, _Q_END + 2], scratch[b, _Q_END + 3] = w, qx, qy, qz
            scratch[b, _L_END], scratch[b, _L_END + 1], scratch[b, _L_END + 2] = L[b, 0], L[b, 1], L[b, 2]
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = w, qx, qy, qz
        scratch[b, 0], scratch[b, 1], scratch[b, 2] = m0, m1, m2
        scratch[b, _M_COMP], scratch[b, _M_COMP + 1], scratch[b, _M_COMP + 2] = e0, e1, e2


@numba.njit(cache=True, inline="always")
def _turn_isotropic(q, L, b, s_over_i) -> None:  # noqa: ANN001
    """The exact free rotation of an isotropic body (I1 = I2 = I3 = I) over a time s: omega = L / I is
    fixed in the world, so q <- (cos(theta/2), sin(theta/2) L/|L|) * q with theta = |L| s / I. It is
    the exact flow of the whole rotational kinetic energy |L|^2 / (2 I), which the axis pieces T_a T_b
    T_c only approximate (they do not commute), so a ball's turn costs one sin/cos pair, not five or six.
    """
    l0, l1, l2 = L[b, 0], L[b, 1], L[b, 2]
    length = math.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
    if length == 0.0:
        return
    half = 0.5 * length * s_over_i
    c, s = math.cos(half), math.sin(half) / length
    rx, ry, rz = s * l0, s * l1, s * l2
    w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    q[b, 0] = c * w - rx * qx - ry * qy - rz * qz
    q[b, 1] = c * qx + rx * w + ry * qz - rz * qy
    q[b, 2] = c * qy - rx * qz + ry * w + rz * qx
    q[b, 3] = c * qz + rx * qy - ry * qx + rz * w


@numba.njit(cache=True, inline="always")
def free_drift(model, b, h, x0, q0, P, L, x, q) -> None:  # noqa: ANN001
    """Body b's free drift over h from (x0[b], q0[b]) with momenta (P[b], L[b]), into (x[b], q[b]):
    D_x(h) and T_a(h/2) T_b(h/2) T_c(h) T_b(h/2) T_a(h/2) (the exact turn of an isotropic body), q
    normalised. It is the step's two half drifts with no kick between them (T_c(h/2) T_c(h/2) = T_c(h)),
    a palindrome of exact flows: symmetric, so free_drift(-h) undoes free_drift(h) to round-off. The
    joints' RATTLE step (joints/rattle.py) runs it once per Newton iteration."""
    inv0, inv1, inv2 = model.body_inertia_inv[b, 0], model.body_inertia_inv[b, 1], model.body_inertia_inv[b, 2]
    move = h / model.body_mass[b]
    x[b, 0] = x0[b, 0] + move * P[b, 0]
    x[b, 1] = x0[b, 1] + move * P[b, 1]
    x[b, 2] = x0[b, 2] + move * P[b, 2]
    q[b, 0], q[b, 1], q[b, 2], q[b, 3] = q0[b, 0], q0[b, 1], q0[b, 2], q0[b, 3]
    if inv0 == inv1 and inv1 == inv2:
        _turn_isotropic(q, L, b, h * inv0)
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    else:
        ka, kb, kc = axis_order(model.body_inertia[b, 0], model.body_inertia[b, 1], model.body_inertia[b, 2])
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        m0, m1, m2 = rotate_inverse(w, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2])
        c, s = half_turn(ka, 0.5 * h, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, w, qx, qy, qz = turn_plain(ka, c, s, m0, m1, m2, w, qx, qy, qz)
        c, s = half_turn(kb, 0.5 * h, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, w, qx, qy, qz = turn_plain(kb, c, s, m0, m1, m2, w, qx, qy, qz)
        c, s = half_turn(kc, h, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, w, qx, qy, qz = turn_plain(kc, c, s, m0, m1, m2, w, qx, qy, qz)
        c, s = half_turn(kb, 0.5 * h, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, w, qx, qy, qz = turn_plain(kb, c, s, m0, m1, m2, w, qx, qy, qz)
        c, s = half_turn(ka, 0.5 * h, m0, m1, m2, inv0, inv1, inv2)
        m0, m1, m2, w, qx, qy, qz = turn_plain(ka, c, s, m0, m1, m2, w, qx, qy, qz)
    norm = 1.0 / math.sqrt(w * w + qx * qx + qy * qy + qz * qz)
    q[b, 0], q[b, 1], q[b, 2], q[b, 3] = w * norm, qx * norm, qy * norm, qz * norm


def free_drift_numpy(model, h: float, x0: np.ndarray, q0: np.ndarray, P: np.ndarray, L: np.ndarray):  # noqa: ANN001, ANN201
    """Numpy twin of `free_drift`, every body: (x, q) after the free drift over h."""
    order = axis_order_numpy(model.body_inertia)
    inv = model.body_inertia_inv
    iso = (inv[:, 0] == inv[:, 1]) & (inv[:, 1] == inv[:, 2])
    x = x0 + h * P / model.body_mass[:, None]
    m, q = body_momentum_numpy(q0, L), q0.copy()
    for axis, s in ((order[:, 0], 0.5 * h), (order[:, 1], 0.5 * h), (order[:, 2], h), (order[:, 1], 0.5 * h),
                    (order[:, 0], 0.5 * h)):  # fmt: skip
        m, q = turn_numpy(axis, s, m, q, inv)
    q[iso] = _turn_isotropic_numpy(q0, L, h * inv[:, 0])[iso]
    return x, q / np.linalg.norm(q, axis=1, keepdims=True)


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Plain numpy reference of `step`, vectorised over bodies, in place."""
    compose_numpy(model, forces, t, dt, WEIGHTS, x, q, P, L)


def compose_numpy(model, forces, t, h, weights, x, q, P, L) -> None:  # noqa: ANN001
    """Numpy reference of `compose`: each stage unmerged, D_x T_a T_b T_c K T_c T_b T_a D_x."""
    order = axis_order_numpy(model.body_inertia)
    inv = model.body_inertia_inv
    iso = (inv[:, 0] == inv[:, 1]) & (inv[:, 1] == inv[:, 2])
    elapsed = 0.0
    for weight in weights:
        s = weight * h
        x += 0.5 * s * P / model.body_mass[:, None]
        m = body_momentum_numpy(q, L)
        q_iso = _turn_isotropic_numpy(q, L, 0.5 * s * inv[:, 0])
        for axis in (order[:, 0], order[:, 1], order[:, 2]):
            m, q[:] = turn_numpy(axis, 0.5 * s, m, q, inv)
        q[iso] = q_iso[iso]
        drag = forces.drag
        coefficients = np.concatenate([drag.linear, drag.quadratic, drag.angular_linear, drag.angular_quadratic])
        dissipative = bool(np.any(forces.spring.damping != 0.0) or np.any(coefficients != 0.0))
        F, tau = wrench_numpy(model, forces, t + elapsed + 0.5 * s, x, q, P, L, dissipative=not dissipative)
        if dissipative:  # K_c(s/2) D(s) K_c(s/2)
            P += 0.5 * s * F
            L += 0.5 * s * tau
            L_before = L.copy()
            dissipation_flow_numpy(model, forces.spring, forces.drag, s, x, q, P, L)
            m = m + 0.5 * s * body_momentum_numpy(q, tau) + body_momentum_numpy(q, L - L_before)
            P += 0.5 * s * F
            L += 0.5 * s * tau
            m = m + 0.5 * s * body_momentum_numpy(q, tau)
        else:
            P += s * F
            if forces.has_torque:
                L += s * tau
                m = m + s * body_momentum_numpy(q, tau)
        q_iso = _turn_isotropic_numpy(q, L, 0.5 * s * inv[:, 0])
        for axis in (order[:, 2], order[:, 1], order[:, 0]):
            m, q[:] = turn_numpy(axis, 0.5 * s, m, q, inv)
        q[iso] = q_iso[iso]
        x += 0.5 * s * P / model.body_mass[:, None]
        elapsed += s
    q /= np.linalg.norm(q, axis=1, keepdims=True)


def _turn_isotropic_numpy(q: np.ndarray, L: np.ndarray, s_over_i: np.ndarray) -> np.ndarray:
    """Numpy reference of `_turn_isotropic`, every body (the caller keeps the isotropic ones)."""
    length = np.linalg.norm(L, axis=1)
    half = 0.5 * length * s_over_i
    safe = np.where(length > 0.0, length, 1.0)
    r = np.concatenate([np.cos(half)[:, None], (np.sin(half) / safe)[:, None] * L], axis=1)
    return quat_multiply(r, q)
