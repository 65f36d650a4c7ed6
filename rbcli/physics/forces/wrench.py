"""The total wrench of all force terms on every body: the one function integrators call.

Stages, each a loop over its own table's rows only (0 rows: no work; rows list only touched bodies):
gravity, per-particle fields, point forces, torques, springs-dampers, drag, contact (physics/contact:
broad phase and contact forces), then static bodies held (their wrench zeroed). Impulses are not
forces: they are applied between steps by `impulse.apply_impulses`.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics.contact.force import accumulate_contact, hold_static_bodies
from rbcli.physics.forces.drag import accumulate_drag, drag_numpy
from rbcli.physics.forces.field import accumulate_field, field_numpy, field_potential
from rbcli.physics.forces.gravity import accumulate_gravity, gravity_potential
from rbcli.physics.forces.point_force import accumulate_point_force, point_force_numpy, point_force_potential
from rbcli.physics.forces.spring import accumulate_spring, spring_numpy, spring_potential
from rbcli.physics.forces.tables import (
    TERM_CONTACT,
    TERM_DRAG,
    TERM_FIELD,
    TERM_GRAVITY,
    TERM_POINT_FORCE,
    TERM_SPRING,
    TERM_TORQUE,
    ForceTables,
)
from rbcli.physics.forces.torque import accumulate_torque, torque_numpy
from rbcli.physics.step import STEP_KERNEL


@numba.njit(**STEP_KERNEL)
def accumulate_wrench(model, forces, force_data, t, x, q, P, L, F, tau) -> None:  # noqa: ANN001 - numba types
    """Set F [N] and tau [N m] (body_count, 3), world frame, about each centre of mass, to the sum of the
    scene's force terms at time t [s]. tau is left untouched (zero) when forces.has_torque is False;
    otherwise it is exactly zero for every body that forces.torque_body does not flag. force_data
    (ForceData) holds what the pass writes besides F and tau: the stage counters."""
    F[:, :] = 0.0
    if forces.has_torque:
        tau[:, :] = 0.0
    counts = force_data.term_evaluations
    if forces.has_gravity:
        accumulate_gravity(model.body_mass, forces.gravity, F)
        counts[TERM_GRAVITY] += F.shape[0]
    if forces.field.body.shape[0]:
        counts[TERM_FIELD] += accumulate_field(model, forces.field, forces.schedule, t, x, q, F, tau)
    if forces.point_force.body.shape[0]:
        counts[TERM_POINT_FORCE] += accumulate_point_force(forces.point_force, forces.schedule, t, q, F, tau)
    if forces.torque.body.shape[0]:
        counts[TERM_TORQUE] += accumulate_torque(forces.torque, forces.schedule, t, q, tau)
    if forces.spring.body_a.shape[0]:
        counts[TERM_SPRING] += accumulate_spring(model, forces.spring, x, q, P, L, F, tau)
    if forces.drag.body.shape[0]:
        counts[TERM_DRAG] += accumulate_drag(model, forces.drag, q, P, L, F, tau)
    if forces.contact.sphere_body.shape[0]:
        accumulate_contact(model, forces.contact, force_data.contact, t, x, q, P, L, F, tau)
        counts[TERM_CONTACT] += np.int64(force_data.contact.stats[0])
    if forces.contact.static_body.shape[0]:
        hold_static_bodies(forces.contact, F, tau)


def wrench_numpy(model, forces: ForceTables, t: float, x, q, P, L) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """Plain numpy reference of `accumulate_wrench` (tests); model: Model or KernelModel. Contact forces
    carry history, so they have their own reference (physics/contact/reference.py), not this one."""
    if forces.contact.sphere_body.shape[0]:
        raise ValueError("wrench_numpy has no contact forces: compare contact with physics/contact/reference.py")
    F = np.zeros_like(x)
    tau = np.zeros_like(x)
    if forces.has_gravity:
        F += model.body_mass[:, None] * forces.gravity
    for dF, dtau in (
        field_numpy(model, forces.field, forces.schedule, t, x, q),
        point_force_numpy(forces.point_force, forces.schedule, t, x, q),
        torque_numpy(forces.torque, forces.schedule, t, x, q),
        spring_numpy(model, forces.spring, x, q, P, L),
        drag_numpy(model, forces.drag, x, q, P, L),
    ):
        F += dF
        tau += dtau
    return F, tau


def potential_energy(model, forces: ForceTables, x: np.ndarray, q: np.ndarray) -> np.ndarray:  # noqa: ANN001
    """Total potential energy [J] of the conservative terms; x: (..., body_count, 3) -> (...).

    Conservative: gravity, springs (k (l - l0)^2 / 2), unscheduled fields with a symmetric gradient,
    unscheduled world-frame point forces. Scheduled terms, body-frame forces, torques, dampers and
    drag have no potential (their work shows up as a change of the total energy).
    """
    V = np.zeros(x.shape[:-2])
    if forces.has_gravity:
        V = V + gravity_potential(model.body_mass, forces.gravity, x).sum(axis=-1)
    if forces.spring.body_a.shape[0]:
        V = V + spring_potential(forces.spring, x, q)
    if forces.field.body.shape[0]:
        V = V + field_potential(model, forces.field, x, q)
    if forces.point_force.body.shape[0]:
        V = V + point_force_potential(forces.point_force, x, q)
    return V
