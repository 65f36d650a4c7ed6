"""The force pass `accumulate_wrench`: the stages of forces/stage_list.py FORCE_STAGES, in its order.

Each stage with a table is a plain function `_<name>` wrapped by `force_stage` (forces/stages.py) into a
dispatcher `<name>_stage` that compiles to nothing where the table is None (a scene without that force
type) and to the function otherwise; gravity is a flag and a vector, tested at run time. Written out by
hand: numba can call a dispatcher only by a name in the calling code (a tuple of kernels iterated in a
loop would be first-class function values, which its cache does not serve), so the pass names each
stage. tests/physics/test_pipeline.py checks that the calls below follow FORCE_STAGES: its order, the
tables each stage is dispatched on, and the dissipative ones called only when `dissipative`.
"""

import numba
import numpy as np
from numba.extending import overload

from rbcli.physics.contact.force import accumulate_contact, hold_static_bodies
from rbcli.physics.contact.quiet import contact_quiet
from rbcli.physics.contact.tables import QUIET_ON
from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only, member
from rbcli.physics.forces.drag import accumulate_drag
from rbcli.physics.forces.field import accumulate_field
from rbcli.physics.forces.gravity import accumulate_gravity
from rbcli.physics.forces.point_force import accumulate_point_force
from rbcli.physics.forces.spring import accumulate_spring
from rbcli.physics.forces.stages import force_stage
from rbcli.physics.forces.tables import (
    TERM_CONTACT,
    TERM_DRAG,
    TERM_FIELD,
    TERM_GRAVITY,
    TERM_POINT_FORCE,
    TERM_SPRING,
    TERM_TORQUE,
)
from rbcli.physics.forces.torque import accumulate_torque
from rbcli.physics.step import STEP_ENTRY

__all__ = ["accumulate_wrench"]


def _field(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
    """The field stage (FORCE_STAGES); `field_stage` dispatches to it."""
    if forces.field.body.shape[0]:
        counts[TERM_FIELD] += accumulate_field(model, forces.field, forces.schedule, t, x, q, F, tau)


field_stage = force_stage(_field, "forces.field")  # nothing when a table is None


def _point_force(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
    """The point_force stage (FORCE_STAGES); `point_force_stage` dispatches to it."""
    if forces.point_force.body.shape[0]:
        counts[TERM_POINT_FORCE] += accumulate_point_force(forces.point_force, forces.schedule, t, q, F, tau)


point_force_stage = force_stage(_point_force, "forces.point_force")  # nothing when a table is None


def _torque(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
    """The torque stage (FORCE_STAGES); `torque_stage` dispatches to it."""
    if forces.torque.body.shape[0]:
        counts[TERM_TORQUE] += accumulate_torque(forces.torque, forces.schedule, t, q, tau)


torque_stage = force_stage(_torque, "forces.torque")  # nothing when a table is None


def _spring(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
    """The spring stage (FORCE_STAGES); `spring_stage` dispatches to it."""
    if forces.spring.body_a.shape[0]:
        counts[TERM_SPRING] += accumulate_spring(model, forces.spring, x, q, P, L, F, tau, dissipative)


spring_stage = force_stage(_spring, "forces.spring")  # nothing when a table is None


def _drag(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
    """The drag stage (FORCE_STAGES); `drag_stage` dispatches to it."""
    if forces.drag.body.shape[0]:
        counts[TERM_DRAG] += accumulate_drag(model, forces.drag, q, P, L, F, tau)


drag_stage = force_stage(_drag, "forces.drag")  # nothing when a table is None


def _contact(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
    """The contact stage (FORCE_STAGES); `contact_stage` dispatches to it, where `contact_needed` says so."""
    work = force_data.contact
    accumulate_contact(model, contact, work, t, x, q, P, L, F, tau)
    counts[TERM_CONTACT] += np.int64(work.stats[0])
    if contact.static_body.shape[0]:
        hold_static_bodies(contact, F, tau)


contact_stage = force_stage(_contact, "contact", "force_data.contact")  # nothing when a table is None


def contact_needed(contact, force_data, x, t, F, tau) -> bool:  # noqa: ANN001
    """Whether the contact stage must run for the state x at time t: False without a contact table, or
    where nothing can touch (no contact spheres, or the quiet skin: contact/quiet.py), the static bodies'
    wrench then held here. Tested apart from the stage: a call of the stage passes the contact table and
    work by value (~300 ns an evaluation at 2 bodies, 2.4x a small scene's step, paid on every quiet
    evaluation), where this body is small enough for LLVM to inline. (numba's own inlining of the stage
    changed trajectories' bits, even of scenes without contact: not used.)"""
    kernel_only()
    return False


@overload(contact_needed, jit_options=DISPATCH_OPTIONS)
def _contact_needed(contact, force_data, x, t, F, tau):  # noqa: ANN001, ANN202
    if absent(contact) or absent(member(force_data, "contact")):
        return lambda contact, force_data, x, t, F, tau: False

    def run(contact, force_data, x, t, F, tau):  # noqa: ANN001, ANN202
        if contact.sphere_body.shape[0] and not contact_quiet(force_data.contact, x, t):
            return True
        if contact.static_body.shape[0]:
            hold_static_bodies(contact, F, tau)
        return False

    return run


def tau_held_zero(forces, force_data) -> bool:  # noqa: ANN001
    """Whether tau is zero already, so the pass need not zero it: a scene whose only torque is contact's
    (no force term table: KernelForceTables' are None) while the quiet skin is on (contact/quiet.py). The
    quiet is set only after an evaluation in which nothing touched (tau zeroed, nothing added), no stage
    writes tau until the contact stage runs again, and the evaluation that runs it ends the quiet first;
    a state set from outside ends it too (data.py). Exactly the zeros the loop would write (3 stores a
    body every quiet evaluation, ~1-2 ns of a 40 ns euler-quat step at 2 bodies: issue 47 item 6)."""
    kernel_only()
    return False


@overload(tau_held_zero, jit_options=DISPATCH_OPTIONS)
def _tau_held_zero(forces, force_data):  # noqa: ANN001, ANN202
    if absent(member(force_data, "contact")) or not absent(member(forces, "torque")):
        return lambda forces, force_data: False
    return lambda forces, force_data: force_data.contact.quiet_state[QUIET_ON] != 0


@numba.njit(**STEP_ENTRY)
def accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau, dissipative=True) -> None:  # noqa: ANN001
    """Set F [N] and tau [N m] (body_count, 3), world frame, about each centre of mass, to the sum of the
    scene's force terms at time t [s]: the stages of FORCE_STAGES in order. tau is left untouched (zero)
    when forces.has_torque is False; otherwise it is exactly zero for every body that forces.torque_body
    does not flag. model: the body arrays (KernelBodies); forces: KernelForceTables (or ForceTables);
    contact: the model's contact table (None without contact); force_data (ForceData) holds what the
    pass writes besides F and tau: the stage counters and the contact work. dissipative=False leaves out
    the spring dampers and drag, which the splitting integrators integrate as their own flow
    (forces/damping.py); contact's dashpots stay in (contact is not smooth, so no integrator keeps its
    order through it anyway)."""
    # zeroed by loops: numba's F[:, :] = 0.0 (a slice assignment) cost ~20-30 ns per evaluation at 2
    # bodies, a fifth of a small scene's step (docs/performance.md, "Idle contact")
    for b in range(F.shape[0]):
        F[b, 0] = F[b, 1] = F[b, 2] = 0.0
    if forces.has_torque and not tau_held_zero(forces, force_data):
        for b in range(tau.shape[0]):
            tau[b, 0] = tau[b, 1] = tau[b, 2] = 0.0
    counts = force_data.term_evaluations
    # gravity: M g at every centre of mass (forces/gravity.py)
    if forces.has_gravity:
        accumulate_gravity(model.body_mass, forces.gravity, F)
        counts[TERM_GRAVITY] += F.shape[0]
    # field: per-particle force or acceleration fields (forces/field.py)
    field_stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative)
    # point_force: forces at body points (forces/point_force.py)
    point_force_stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative)
    # torque: pure couples (forces/torque.py)
    torque_stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative)
    # spring: springs-dampers, the dampers only when dissipative (forces/spring.py)
    spring_stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative)
    # drag: linear and quadratic, translational and rotational (forces/drag.py)
    if dissipative:
        drag_stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative)
    # contact: contact forces, then the static bodies held, their wrench zeroed (physics/contact)
    if contact_needed(contact, force_data, x, t, F, tau):
        contact_stage(model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative)
