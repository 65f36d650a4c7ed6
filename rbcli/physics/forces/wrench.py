"""The total wrench of all force terms on every body: the one function integrators call.

Stages, each a loop over its own table's rows only (rows list only touched bodies): gravity,
per-particle fields, point forces, torques, springs-dampers, drag, contact (physics/contact: broad
phase and contact forces), then static bodies held (their wrench zeroed). Impulses are not forces:
they are applied between steps by `impulse.apply_impulses` (the pipeline's impulse stage).

Only the stages a scene has are compiled. The kernels take `ForceTables.kernel()` (KernelForceTables,
forces/tables.py), whose table of a force type the scene does not use is None; every stage but gravity
is called through a dispatcher of forces/stages.py, a `numba.extending.overload` that compiles to a
no-op for a NoneType table and to the stage's kernel otherwise. A run-time `if table.rows:` test, as
this function had, skips the work but not the compilation: numba compiles both sides of a branch, so
a gravity-only scene's first run compiled every force type. Why this design: the Python side keeps
reading ForceTables as before (every table present, 0 rows when unused: `forces.spring.body_a`,
`force_terms_present`, the scene checks), only the places that hand tables to kernels call `.kernel()`
(runner/simulation.py), and kernels still accept a plain ForceTables (each stage then compiled and
skipped at run time when empty), so tests and benchmarks that call kernels with `compiled.forces`
work unchanged. A scene always gets the same combination of None and tables, so numba's on-disk cache
serves its kernels from run to run.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics.forces.drag import drag_numpy
from rbcli.physics.forces.field import field_numpy, field_potential
from rbcli.physics.forces.gravity import accumulate_gravity, gravity_potential
from rbcli.physics.forces.point_force import point_force_numpy, point_force_potential
from rbcli.physics.forces.spring import spring_numpy, spring_potential
from rbcli.physics.forces.stages import (
    contact_stage,
    drag_stage,
    field_stage,
    point_force_stage,
    spring_stage,
    torque_stage,
)
from rbcli.physics.forces.tables import TERM_GRAVITY, ForceTables
from rbcli.physics.forces.torque import torque_numpy
from rbcli.physics.step import STEP_KERNEL


@numba.njit(**STEP_KERNEL)
def accumulate_wrench(model, forces, force_data, t, x, q, P, L, F, tau, dissipative=True) -> None:  # noqa: ANN001 - numba types
    """Set F [N] and tau [N m] (body_count, 3), world frame, about each centre of mass, to the sum of the
    scene's force terms at time t [s]. tau is left untouched (zero) when forces.has_torque is False;
    otherwise it is exactly zero for every body that forces.torque_body does not flag. forces:
    KernelForceTables (or ForceTables); force_data (ForceData) holds what the pass writes besides F and
    tau: the stage counters and the contact work. dissipative=False leaves out the spring dampers and
    drag, which the splitting integrators integrate as their own flow (forces/damping.py); contact's
    dashpots stay in (contact is not smooth, so no integrator keeps its order through it anyway)."""
    F[:, :] = 0.0
    if forces.has_torque:
        tau[:, :] = 0.0
    counts = force_data.term_evaluations
    if forces.has_gravity:
        accumulate_gravity(model.body_mass, forces.gravity, F)
        counts[TERM_GRAVITY] += F.shape[0]
    # each stage compiles to nothing when its table is None (forces/stages.py)
    field_stage(model, forces.field, forces.schedule, t, x, q, F, tau, counts)
    point_force_stage(forces.point_force, forces.schedule, t, q, F, tau, counts)
    torque_stage(forces.torque, forces.schedule, t, q, tau, counts)
    spring_stage(model, forces.spring, x, q, P, L, F, tau, counts, dissipative)
    if dissipative:
        drag_stage(model, forces.drag, q, P, L, F, tau, counts)
    contact_stage(model, forces.contact, force_data.contact, t, x, q, P, L, F, tau, counts)


def wrench_numpy(  # noqa: ANN001
    model, forces: ForceTables, t: float, x, q, P, L, dissipative: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Plain numpy reference of `accumulate_wrench` (tests); model: Model or KernelModel. Contact forces
    carry history, so they have their own reference (physics/contact/reference.py), not this one."""
    spring, drag = forces.spring, forces.drag
    if not dissipative:
        spring = spring._replace(damping=np.zeros_like(spring.damping))
        drag = drag._replace(**{name: getattr(drag, name)[:0] for name in drag._fields})
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
        spring_numpy(model, spring, x, q, P, L),
        drag_numpy(model, drag, x, q, P, L),
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
