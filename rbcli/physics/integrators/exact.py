"""`exact`: force kicks around the EXACT torque-free motion (Celledoni, Fasso, Safstrom & Zanna 2008).

The splitting of split2 with the three principal-axis turns replaced by the exact flow of the whole
free-body kinetic energy T = sum m_k^2/(2 I_k) (Jacobi elliptic functions and an elliptic integral
of the third kind; `rbcli.physics.free_rotation_exact`, CFSZ 2008, "The exact computation of the
free rigid body motion and its use in splitting methods", SIAM J. Sci. Comput. 30):

  D(h/2) K(h) D(h/2),  D(s): x += s P/M and q <- exact free flow over s (L fixed in the world),
                       K(s): P += s F, L += s tau, one wrench evaluation at t + h/2.

Torque-free the rotation is exact to round-off for any dt (D(h/2) D(h/2) = D(h) by the flow
property), so the only error is the splitting against the forces: second order, symplectic,
time-reversible, and for uniform gravity exact as well (leapfrog is exact for constant forces).
Like split2 the kick sits in the middle so that each step takes one fresh force evaluation; the
price is two exact flows per step even when torque-free (a force can depend on the orientation at
the midpoint, e.g. a body-frame thrust through the centre of mass). `compose` merges the half-flows
of adjacent stages of a composition (exact4): s stages cost s + 1 flows and s force evaluations.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics.elliptic import JACOBI_WORK_SIZE
from rbcli.physics.forces.wrench import accumulate_wrench, wrench_numpy
from rbcli.physics.free_rotation_exact import free_rotation_exact_batch

# per body: the orientation at the current force evaluation, when torque-free (see `compose`)
# per body: the orientation at the force evaluation (4); row 0 also holds the Jacobi functions' work
SCRATCH_WIDTH = 4 + JACOBI_WORK_SIZE

WEIGHTS = np.array([1.0])


@numba.njit(cache=True)
def step(model, forces, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One `exact` step of every body, in place (one force evaluation, at t + dt/2)."""
    compose(model, forces, force_data, t, dt, WEIGHTS, x, q, P, L, F, tau, scratch)


@numba.njit(cache=True)
def compose(model, forces, force_data, t, h, weights, x, q, P, L, F, tau, q_mid) -> None:  # noqa: ANN001
    """The composition exact(w_{s-1} h) ... exact(w_0 h), adjacent half drifts merged, in place.

    With torques the kicks change L, so the flow is chained through the stages. Torque-free L stays
    put and the orientation at every force evaluation is exact(q0, elapsed) written to q_mid (N, 4),
    and the step ends with q = exact(q0, h): every orientation is ONE call away from the step's
    start, so round-off does not pile up through s + 1 chained calls (it halves the flip-case error).
    Which of the two is a scene-wide choice (has_torque; both cost s + 1 flows); the kick adds tau only
    for the bodies torque_body flags (tau = 0 for the others).
    """
    count = weights.shape[0]
    torque = forces.has_torque
    work = q_mid[0, 4:]  # a view: the step allocates nothing
    elapsed = 0.5 * weights[0] * h
    _drift_centre(model, elapsed, x, P)
    if torque:
        free_rotation_exact_batch(model.body_inertia, q, L, elapsed, q, work)
    for i in range(count):
        if not torque:
            free_rotation_exact_batch(model.body_inertia, q, L, elapsed, q_mid, work)
        q_now = q if torque else q_mid  # (one wrench call site: the compiled wrench is inlined once)
        accumulate_wrench(model, forces, force_data, t + elapsed, x, q_now, P, L, F, tau)
        h_prev = weights[i] * h
        h_next = weights[i + 1] * h if i + 1 < count else 0.0
        _kick(model, torque, forces.torque_body, h_prev, P, L, F, tau)
        _drift_centre(model, 0.5 * (h_prev + h_next), x, P)
        if torque:
            free_rotation_exact_batch(model.body_inertia, q, L, 0.5 * (h_prev + h_next), q, work)
        elapsed += 0.5 * (h_prev + h_next)
    if not torque:
        free_rotation_exact_batch(model.body_inertia, q, L, h, q, work)


@numba.njit(cache=True)
def _drift_centre(model, s, x, P) -> None:  # noqa: ANN001
    """The centre of mass in free flight for a time s."""
    for b in range(x.shape[0]):
        drift = s / model.body_mass[b]
        for k in range(3):
            x[b, k] += drift * P[b, k]


@numba.njit(cache=True)
def _kick(model, has_torque, torque_body, s, P, L, F, tau) -> None:  # noqa: ANN001
    """K(s): P += s F, L += s tau (tau only for the bodies torque_body flags; it is 0 for the others)."""
    for b in range(P.shape[0]):
        for k in range(3):
            P[b, k] += s * F[b, k]
        if has_torque and torque_body[b]:
            for k in range(3):
                L[b, k] += s * tau[b, k]


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Numpy reference of `step` (the free flow itself is the compiled one: it has its own tests)."""
    compose_numpy(model, forces, t, dt, WEIGHTS, x, q, P, L)


def compose_numpy(model, forces, t, h, weights, x, q, P, L) -> None:  # noqa: ANN001
    """Numpy reference of `compose`, stages unmerged: D(s/2) K(s) D(s/2) each."""
    elapsed = 0.0
    for weight in weights:
        s = weight * h
        x += 0.5 * s * P / model.body_mass[:, None]
        free_rotation_exact_batch(model.body_inertia, q, L, 0.5 * s, q, np.empty(JACOBI_WORK_SIZE))
        F, tau = wrench_numpy(model, forces, t + elapsed + 0.5 * s, x, q, P, L)
        P += s * F
        if forces.has_torque:
            L += s * tau
        x += 0.5 * s * P / model.body_mass[:, None]
        free_rotation_exact_batch(model.body_inertia, q, L, 0.5 * s, q, np.empty(JACOBI_WORK_SIZE))
        elapsed += s
