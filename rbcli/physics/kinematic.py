"""Kinematic bodies: a prescribed motion, set exactly at every step (a paddle, a shaker, a conveyor).

A kinematic body's motion is given, not integrated: with S(t) = integral of s over [0, t] (the row's
schedule, forces/schedule.py; s = 1 without one), v0, w0 its velocity and angular velocity [world]
and p0 the pivot it turns about [world, at t = 0; default its centre of mass x0],

    theta(t) = |w0| S(t) about the fixed world axis w0 / |w0|,   R(t) = that rotation
    p(t) = p0 + v0 S(t)                                          the pivot moves with the translation
    x(t) = p(t) + R(t) (x0 - p0),    q(t) = R(t) q0
    v(t) = s(t) (v0 + w0 x (x(t) - p(t))),   w(t) = s(t) w0,   P = M v,   L = I w

(kinematic bodies get an isotropic inertia I at compile time, so L = I w in any frame). A constant
velocity is the schedule-free case, `kinematic: true`. The table (`KinematicTable`, one row per body:
kinematic_table.py) is the model's `kinematic` (physics/model.py); its schedules are rows of the force
terms' ScheduleTable (forces/tables.py). kinematic_reference.py holds the numpy reference of the
closed form (numpy only: the scene compiler uses it for the initial state). Kinematic bodies are not
contact code: contact sees them as bodies of infinite contact mass (inverse contact mass 0,
contact/tables.py) moving at the velocity the stages below set.

Two pipeline stages hold it (physics/pipeline.py), around each (sub-)step [t, t + h) of the integrator:
  kinematic_begin  x, q at t exactly, and P, L set to the step's mean motion: P = M (x(t+h) - x(t)) / h
                   and L = I w0 (S(t+h) - S(t)) / h, so the integrator's own drift (the body feels no
                   force: its wrench is held at zero like a static body's) passes through the exact
                   pose at both ends of the step and contact sees the body move at its mean velocity,
                   within O(h^2) of the true one mid-step (the exact v(t) would be O(h) off there);
  kinematic_end    x, q, P, L at t + h exactly, from the closed form: nothing accumulates over steps.
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.forces.schedule import schedule_integral, schedule_value
from rbcli.physics.rotation_kernels import rotate
from rbcli.physics.step import STEP_KERNEL


@numba.njit(cache=True, inline="always")
def _pose(table, r, S):  # noqa: ANN001, ANN202
    """(x, q, x - p) of row r after the schedule integral S: the closed form of the module docstring."""
    v, w = table.velocity[r], table.angular_velocity[r]
    x0, p0, q0 = table.position[r], table.pivot[r], table.orientation[r]
    speed = math.sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2])
    a0, a1, a2 = x0[0] - p0[0], x0[1] - p0[1], x0[2] - p0[2]
    if speed > 0.0:
        half = 0.5 * speed * S
        c, s = math.cos(half), math.sin(half) / speed
        dw, dx, dy, dz = c, s * w[0], s * w[1], s * w[2]
        a0, a1, a2 = rotate(dw, dx, dy, dz, a0, a1, a2)
        # q = dq q0 (the turn is about a world axis, so it multiplies from the left)
        qw = dw * q0[0] - dx * q0[1] - dy * q0[2] - dz * q0[3]
        qx = dw * q0[1] + dx * q0[0] + dy * q0[3] - dz * q0[2]
        qy = dw * q0[2] - dx * q0[3] + dy * q0[0] + dz * q0[1]
        qz = dw * q0[3] + dx * q0[2] - dy * q0[1] + dz * q0[0]
    else:
        qw, qx, qy, qz = q0[0], q0[1], q0[2], q0[3]
    x = (p0[0] + v[0] * S + a0, p0[1] + v[1] * S + a1, p0[2] + v[2] * S + a2)
    return x, (qw, qx, qy, qz), (a0, a1, a2)


@numba.njit(**STEP_KERNEL)
def kinematic_begin(model, table, schedule, t, h, x, q, P, L) -> None:  # noqa: ANN001
    """Each kinematic body at its exact pose at t, moving at its mean velocity over [t, t + h)."""
    for r in range(table.body.shape[0]):
        b = table.body[r]
        S0 = schedule_integral(schedule, table.schedule[r], t)
        S1 = schedule_integral(schedule, table.schedule[r], t + h)
        start, turn, _ = _pose(table, r, S0)
        end, _, _ = _pose(table, r, S1)
        mass = model.body_mass[b]
        inertia = 1.0 / model.body_inertia_inv[b, 0]  # isotropic (scene/compile.py)
        rate = (S1 - S0) / h
        for j in range(3):
            x[b, j] = start[j]
            P[b, j] = mass * (end[j] - start[j]) / h
            L[b, j] = inertia * table.angular_velocity[r, j] * rate
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = turn


@numba.njit(**STEP_KERNEL)
def kinematic_end(model, table, schedule, t, x, q, P, L) -> None:  # noqa: ANN001
    """Each kinematic body's exact x, q, P, L at time t."""
    for r in range(table.body.shape[0]):
        b = table.body[r]
        S = schedule_integral(schedule, table.schedule[r], t)
        s = schedule_value(schedule, table.schedule[r], t)
        pose, turn, arm = _pose(table, r, S)
        v, w = table.velocity[r], table.angular_velocity[r]
        mass = model.body_mass[b]
        inertia = 1.0 / model.body_inertia_inv[b, 0]
        spin = (w[1] * arm[2] - w[2] * arm[1], w[2] * arm[0] - w[0] * arm[2], w[0] * arm[1] - w[1] * arm[0])
        for j in range(3):
            x[b, j] = pose[j]
            P[b, j] = mass * s * (v[j] + spin[j])
            L[b, j] = inertia * s * w[j]
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = turn
