"""Impulses: instantaneous changes P += J, L += r x J (r = R r0, the point's world offset), exact.

Applied BETWEEN steps, not through the wrench, so the change is exactly J and r x J whatever the
integrator (a force spike of J / dt inside one step would be smeared differently by each method).
The step pipeline's impulse stage calls `apply_impulses(model, forces, force_data, t_prev, t_next,
x, q, P, L)` on the state at t_prev just before stepping from t_prev to t_next (the adaptive loop lands
on each grid step that holds one, found by `next_impulse_step`, and applies them there): an impulse at time T is
applied in the first step with t_prev <= T < t_next, to the state at t_prev (so the recorded frame at
t_prev shows the momentum just before it, the next frame the momentum after it). T within 1e-9 dt
below a step's start time counts as that start time, because t = n dt carries round-off
(3 * 0.1 = 0.30000000000000004 > 0.3).
A body-frame J turns with the body: J_world = R(t_prev) J0.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.forces.body_point import rotate
from rbcli.physics.forces.tables import TERM_IMPULSE, ImpulseTable
from rbcli.physics.rotation import quat_to_matrix

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources

# Fraction of the step within which an impulse time below t_prev still counts as t_prev (round-off).
IMPULSE_TIME_SLACK = 1e-9
# `next_impulse_step` when no later step holds an impulse: beyond any grid index a run reaches
NO_IMPULSE_STEP = 2**62


@numba.njit(cache=True)
def apply_impulses(model, forces, force_data, t_prev, t_next, x, q, P, L) -> int:  # noqa: ANN001 - numba types
    """Apply every impulse of the step [t_prev, t_next) to P and L in place; returns how many."""
    impulse = forces.impulse
    slack = IMPULSE_TIME_SLACK * (t_next - t_prev)
    applied = 0
    for row in range(impulse.body.shape[0]):  # rows are sorted by time
        T = impulse.time[row]
        if T < t_prev - slack:
            continue
        if T >= t_next - slack:
            break
        b = impulse.body[row]
        jx, jy, jz = impulse.vector[row, 0], impulse.vector[row, 1], impulse.vector[row, 2]
        if impulse.body_frame[row]:
            jx, jy, jz = rotate(q, b, jx, jy, jz)
        p = impulse.point[row]
        rx, ry, rz = rotate(q, b, p[0], p[1], p[2])
        P[b, 0] += jx
        P[b, 1] += jy
        P[b, 2] += jz
        L[b, 0] += ry * jz - rz * jy
        L[b, 1] += rz * jx - rx * jz
        L[b, 2] += rx * jy - ry * jx
        applied += 1
    force_data.term_evaluations[TERM_IMPULSE] += applied
    return applied


@numba.njit(cache=True)
def next_impulse_step(forces, dt, index) -> int:  # noqa: ANN001 - numba types
    """The first grid step n > index whose step [n dt, (n + 1) dt) holds an impulse, by exactly the rule
    of `apply_impulses` (same products n * dt, same slack); NO_IMPULSE_STEP when none does."""
    impulse = forces.impulse
    for row in range(impulse.body.shape[0]):  # rows are sorted by time, and n grows with T
        T = impulse.time[row]
        guess = math.floor(T / dt)
        for n in range(guess - 1, guess + 2):  # T / dt's rounding can be off by one either way
            t_prev, t_next = n * dt, (n + 1) * dt
            slack = IMPULSE_TIME_SLACK * (t_next - t_prev)
            if n > index and t_prev - slack <= T < t_next - slack:
                return n
    return NO_IMPULSE_STEP


def impulses_numpy(impulse: ImpulseTable, t_prev: float, t_next: float, q, P, L) -> int:  # noqa: ANN001
    """Plain numpy reference of `apply_impulses` (in place on P, L); returns how many were applied."""
    slack = IMPULSE_TIME_SLACK * (t_next - t_prev)
    rows = np.flatnonzero((impulse.time >= t_prev - slack) & (impulse.time < t_next - slack))
    body = impulse.body[rows]
    R = quat_to_matrix(q[body])
    J = np.where(impulse.body_frame[rows, None], np.einsum("rij,rj->ri", R, impulse.vector[rows]), impulse.vector[rows])
    r = np.einsum("rij,rj->ri", R, impulse.point[rows])
    np.add.at(P, body, J)
    np.add.at(L, body, np.cross(r, J))
    return int(rows.shape[0])


def impulse_step_indices(forces, dt: float) -> np.ndarray:  # noqa: ANN001
    """Sorted distinct step indices n >= 0 whose step [n dt, (n + 1) dt) holds an impulse, by exactly the
    rule of `apply_impulses` (same products n * dt, same slack): the plain-Python reference of
    `next_impulse_step` (tests), each index the next one's answer for the one before it. Impulses before
    t = 0 never apply."""
    steps = set()
    for T in forces.impulse.time.tolist():
        guess = int(np.floor(T / dt))
        for n in (guess - 1, guess, guess + 1):  # T / dt's rounding can be off by one either way
            t_prev, t_next = n * dt, (n + 1) * dt
            slack = IMPULSE_TIME_SLACK * (t_next - t_prev)
            if n >= 0 and t_prev - slack <= T < t_next - slack:
                steps.add(n)
    return np.array(sorted(steps), dtype=np.int64)
