"""The total wrench of all force terms on every body: `accumulate_wrench`, the one function integrators
call, and its numpy reference and the potential energy.

`accumulate_wrench` (forces/wrench_pass.py) calls the one list of force stages,
forces/stage_list.py FORCE_STAGES: gravity, per-particle fields, point forces, torques,
springs-dampers, drag, contact (physics/contact: broad phase and contact forces), then static bodies
held (their wrench zeroed), each a loop over its own table's rows only (rows list only touched bodies).
Impulses are not forces: they are applied between steps by `impulse.apply_impulses` (the pipeline's
impulse stage).

Only the stages a scene has are compiled. The kernels take `ForceTables.kernel()` (KernelForceTables,
forces/tables.py), whose table of a force type the scene does not use is None, and the model's contact
table (`Model.kernel().contact`, None without contact); every stage but gravity is called through a
dispatcher (forces/stages.py `force_stage`, a `numba.extending.overload`) that compiles to a no-op for
a NoneType table and to the stage otherwise. A run-time `if table.rows:` test
alone skips the work but not the compilation: numba compiles both sides of a branch, so a gravity-only
scene's first run compiled every force type. Why this design: the Python side keeps reading
ForceTables as before (every table present, 0 rows when unused: `forces.spring.body_a`,
`force_terms_present`, the scene checks), only the places that hand tables to kernels call `.kernel()`
(runner/simulation.py), and kernels still accept a plain ForceTables (each stage then compiled and
skipped at run time when empty), so tests and benchmarks that call kernels with `compiled.forces`
work unchanged. A scene always gets the same combination of None and tables, so numba's on-disk cache
serves its kernels from run to run.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.forces.drag import drag_numpy
from rbcli.physics.forces.field import field_numpy, field_potential
from rbcli.physics.forces.gravity import gravity_potential
from rbcli.physics.forces.point_force import point_force_numpy, point_force_potential
from rbcli.physics.forces.spring import spring_numpy, spring_potential
from rbcli.physics.forces.tables import ForceTables
from rbcli.physics.forces.torque import torque_numpy
from rbcli.physics.forces.wrench_pass import accumulate_wrench

__all__ = ["accumulate_wrench", "potential_energy", "wrench_numpy"]


def wrench_numpy(  # noqa: ANN001
    model, forces: ForceTables, t: float, x, q, P, L, dissipative: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Plain numpy reference of `accumulate_wrench` (tests); model: Model, KernelModel or KernelBodies.
    Contact forces carry history, so they have their own reference (physics/contact/reference.py), not
    this one: ValueError for a model with contact spheres."""
    spring, drag = forces.spring, forces.drag
    if not dissipative:
        spring = spring._replace(damping=np.zeros_like(spring.damping))
        drag = drag._replace(**{name: getattr(drag, name)[:0] for name in drag._fields})
    contact = getattr(model, "contact", None)  # KernelBodies has no tables
    if contact is not None and contact.sphere_body.shape[0]:
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
