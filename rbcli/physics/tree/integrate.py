"""Integrators in joint coordinates: the state of a tree is its coordinates and rates (TreeData.coord,
.rate); the bodies' x, q, P, L are what forward kinematics makes of them (aba.py), so the force pass,
contact, recording and every output read the state arrays as in maximal coordinates.

    reduced-euler   semi-implicit (symplectic) Euler, MuJoCo's default: one force pass and one ABA a step.
                    rate += h qdd(coord, rate);  coord advanced along the NEW rate: angles and travels
                    + h rate, a ball's u <- u exp(h omega / 2) (omega in the link frame: right
                    multiplication, du/dt = u (0, omega) / 2), a free root's x += h R v, q <- q exp(h omega / 2)
    reduced-implicit  reduced-euler's step, its contact forces then taken to the end of the step by
                    backward Euler (implicit_contact.py, between the rates' update and the coordinates')
    reduced-rk4     the classical Runge-Kutta method on y = (coord, rate), dy/dt = (coord_rate(coord, rate),
                    qdd): four force passes and four ABAs a step; quaternion coordinates are summed in
                    R^4 and normalised at each stage and at the end (a projection onto |u| = 1, which
                    keeps the order: the exact flow stays on the sphere)

The joints' dampers (-c rate on each rate) are implicit in reduced-euler, as MuJoCo's joint damping:
(M + h C) qdd = f - C rate, so rate_new = rate + h qdd solves M (rate_new - rate) / h = f - C rate_new
(backward Euler in the damper: stable at any c h), by adding h c to D = S^T I^A S in ABA (the armature
term, work.armature); explicit in reduced-rk4 (stable while c h is below ~2.8 of the joint's inertia).

Limits, cones and motors act after either step's smooth part as impulses on the rates, with the step's
last ABA factors (limits.py `limit_stage`: nothing where the tree has none); an impulse on a link is
projected onto the rates before the step (`tree_kick`, the chunk loop's stage after the impulses); the
joints' reactions are summed only in a run that records them (reactions.py).

First order / fourth order (tests/physics/test_tree_integrate.py measures both on the compound pendulum's
exact period). Neither is symplectic: in joint coordinates the Hamiltonian H = p^T M(q)^-1 p / 2 + V(q) is
not separable, so no explicit splitting keeps it (Leimkuhler-Reich ch. 4); semi-implicit Euler is
symplectic only where M is constant (one hinge), and a free root's rotation under it is the explicit
gyroscopic update that `semi-implicit-gyro` shows to gain |L| at fast spin (docs/trees.md says where each
is the better choice). Maximal coordinates with split2 + RATTLE stay the structure-preserving option.

`TreeData.fk_state[0]` is 1 when the state arrays and the tree work hold forward kinematics of (coord,
rate) exactly: every step ends so, and a step starts without recomputing it; anything that changes the
coordinates from outside (Data.clear_work, set_state) sets it to 0.
"""

from __future__ import annotations

import math

import numba
from numba.extending import overload

from rbcli.physics import kernel_cache
from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only, member
from rbcli.physics.forces.wrench import accumulate_wrench
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_ENTRY, STEP_KERNEL
from rbcli.physics.tree.aba import forward_kinematics, tree_accelerations
from rbcli.physics.tree.flow import advance_coords, coord_rate, normalise_quaternions
from rbcli.physics.tree.implicit_contact import implicit_contact_stage
from rbcli.physics.tree.limits import generalized_momentum, limit_stage, tree_response
from rbcli.physics.tree.reactions import joint_wrench_stage

kernel_cache.install()


@numba.njit(cache=True, inline="always")
def damper_forces(damping, rate, joint_force, armature, implicit_h) -> None:  # noqa: ANN001
    """The joints' dampers: joint_force = -c rate, and armature = implicit_h c (the module docstring: an
    implicit damper when implicit_h is the step, explicit with 0). Its arrays alone, inlined: passing the
    tree's tables to a call cost ~10 % of a 10-link chain's step."""
    for k in range(rate.shape[0]):
        c = damping[k]
        joint_force[k] = -c * rate[k]
        armature[k] = implicit_h * c


@separately_compiled
@numba.njit(**STEP_KERNEL)
def tree_record(tree, tree_data, frames, filled, due) -> None:  # noqa: ANN001
    """On a recording step, each joint's reaction over the step just taken into the frame the record stage
    is about to fill (frames.joint (K, J, 12): on body_a [0:6] and body_b [6:12], (force [N], torque [N m]
    about each body's centre of mass), world: Simulation.joint_reactions' layout); NaN while reactions are
    off. Only into buffers made for them."""
    out = frames.joint
    if not due or filled >= out.shape[0] or out.shape[1] == 0:
        return
    known = tree_data.reactions_on[0] == 1.0
    for i in range(tree.parent.shape[0]):
        j, side = tree.joint[i], tree.joint_side[i]
        if j < 0 or j >= out.shape[1]:
            continue
        shift = 0 if side > 0 else 6  # the link's part [0:6] is body_a's when the link is body_a
        for k in range(12):
            out[filled, j, (k + shift) % 12] = tree_data.reaction[i, k] if known else math.nan


@numba.njit(**STEP_ENTRY)
def _accelerations(model, forces, contact, force_data, tree, tree_data, t, coord, rate, x, q, P, L, F, tau):  # noqa: ANN001, ANN202
    """qdd at (coord, rate) and time t into tree_data.qdd: forward kinematics (the state arrays), the force
    pass, ABA. One call site per integrator, so the force pass is inlined once."""
    forward_kinematics(tree, coord, rate, tree_data.work, x, q, P, L)
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    damper_forces(tree.damping, rate, tree_data.joint_force, tree_data.work.armature, 0.0)
    tree_accelerations(tree, tree_data.work, F, tau, tree_data.joint_force, tree_data.qdd)


@numba.njit(**STEP_ENTRY)
def step_euler(model, forces, contact, force_data, tree, tree_data, t, h, x, q, P, L, F, tau) -> None:  # noqa: ANN001
    """One semi-implicit Euler step of every tree (module docstring), in place: the coordinates, rates and
    the links' x, q, P, L."""
    coord, rate, qdd = tree_data.coord, tree_data.rate, tree_data.qdd
    work = tree_data.work
    if tree_data.fk_state[0] != 1.0:
        forward_kinematics(tree, coord, rate, work, x, q, P, L)
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    damper_forces(tree.damping, rate, tree_data.joint_force, work.armature, h)  # implicit: (M + h C) qdd = f - C rate
    tree_accelerations(tree, work, F, tau, tree_data.joint_force, qdd)
    # the reactions (while recorded): the step's accelerations are constant over it, so its mean
    joint_wrench_stage(tree_data.wrench, tree, tree_data, F, tau, 1.0, True)
    for k in range(rate.shape[0]):
        rate[k] += h * qdd[k]
    # reduced-implicit: the contact forces taken to the end of the step (implicit_contact.py; compiled to
    # nothing where the contact work keeps no contacts: reduced-euler, scenes without contact)
    implicit_contact_stage(force_data, tree, tree_data, x, q, P, L, h)
    advance_coords(tree, coord, rate, h)
    # the limits' and motors' impulses, with this step's ABA (limits.py; nothing where the tree has none)
    limit_stage(tree.limits, tree, tree_data, h)
    forward_kinematics(tree, coord, rate, work, x, q, P, L)
    tree_data.fk_state[0] = 1.0


@numba.njit(**STEP_ENTRY)
def step_rk4(model, forces, contact, force_data, tree, tree_data, t, h, x, q, P, L, F, tau) -> None:  # noqa: ANN001
    """One classical RK4 step of every tree (module docstring), in place. Stage s evaluates qdd and the
    coordinates' rate at y_s = y0 + a_s h k_{s-1} (a = 0, 1/2, 1/2, 1), its forces at t + a_s h; the
    step is y0 + h (k1 + 2 k2 + 2 k3 + k4) / 6, quaternions normalised at each stage and at the end."""
    coord, rate, qdd, dcoord = tree_data.coord, tree_data.rate, tree_data.qdd, tree_data.dcoord
    coord0, rate0, coord_sum, rate_sum = tree_data.coord0, tree_data.rate0, tree_data.coord_sum, tree_data.rate_sum
    nc, nd = coord.shape[0], rate.shape[0]
    for k in range(nc):
        coord0[k] = coord[k]
        coord_sum[k] = 0.0
    for k in range(nd):
        rate0[k] = rate[k]
        rate_sum[k] = 0.0
    for stage in range(4):
        a = 0.0 if stage == 0 else (1.0 if stage == 3 else 0.5)
        weight = 2.0 if stage == 1 or stage == 2 else 1.0
        if stage > 0:  # y_s = y0 + a h k_{s-1} (dcoord, qdd hold k_{s-1})
            for k in range(nc):
                coord[k] = coord0[k] + a * h * dcoord[k]
            for k in range(nd):
                rate[k] = rate0[k] + a * h * qdd[k]
            normalise_quaternions(tree, coord)
        # the first stage's forward kinematics is the state's own, kept from the last step
        if stage == 0 and tree_data.fk_state[0] == 1.0:
            accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
            damper_forces(tree.damping, rate, tree_data.joint_force, tree_data.work.armature, 0.0)
            tree_accelerations(tree, tree_data.work, F, tau, tree_data.joint_force, qdd)
        else:
            _accelerations(model, forces, contact, force_data, tree, tree_data, t + a * h, coord, rate, x, q, P, L,
                           F, tau)  # fmt: skip
        # the reactions (while recorded): the mean over the step, with the stages' weights
        joint_wrench_stage(tree_data.wrench, tree, tree_data, F, tau, weight / 6.0, stage == 0)
        coord_rate(tree, coord, rate, dcoord)
        for k in range(nc):
            coord_sum[k] += weight * dcoord[k]
        for k in range(nd):
            rate_sum[k] += weight * qdd[k]
    sixth = h / 6.0
    for k in range(nc):
        coord[k] = coord0[k] + sixth * coord_sum[k]
    for k in range(nd):
        rate[k] = rate0[k] + sixth * rate_sum[k]
    normalise_quaternions(tree, coord)
    limit_stage(tree.limits, tree, tree_data, h)  # after the smooth step, with its last ABA (limits.py)
    forward_kinematics(tree, coord, rate, tree_data.work, x, q, P, L)
    tree_data.fk_state[0] = 1.0


@separately_compiled
@numba.njit(**STEP_KERNEL)
def tree_kick(tree, tree_data, x, q, P, L, F, tau) -> None:  # noqa: ANN001
    """After impulses changed some links' P, L (the impulses stage): the rates the joints allow closest in
    kinetic energy, M rate = J^T h with h the links' momenta now, the joints' exact impulsive reaction (as
    coordinates.py sets the start, and as the maximal joints' joint_begin projects a kick); then the state
    arrays rewritten by forward kinematics. M at the coordinates now: one ABA refreshes its factors (no
    armature: a kick takes no time, so no damper acts in it; F, tau only feed ABA's bias, unused here)."""
    work, rw = tree_data.work, tree_data.response
    coord, rate = tree_data.coord, tree_data.rate
    if tree_data.fk_state[0] != 1.0:  # the kinematics ABA reads, keeping the kicked momenta (rw.acc: scratch)
        for i in range(tree.parent.shape[0]):
            b = tree.body[i]
            for k in range(3):
                rw.acc[i, k], rw.acc[i, 3 + k] = P[b, k], L[b, k]
        forward_kinematics(tree, coord, rate, work, x, q, P, L)
        for i in range(tree.parent.shape[0]):
            b = tree.body[i]
            for k in range(3):
                P[b, k], L[b, k] = rw.acc[i, k], rw.acc[i, 3 + k]
    for k in range(rate.shape[0]):
        work.armature[k] = 0.0
    tree_accelerations(tree, work, F, tau, tree_data.joint_force, tree_data.qdd)
    generalized_momentum(tree, work, P, L, rw.tau)
    tree_response(tree, work, rw.tau, rate, rw.force, rw.acc)
    forward_kinematics(tree, coord, rate, work, x, q, P, L)
    tree_data.fk_state[0] = 1.0


def tree_kick_stage(forces, tree, tree_data, x, q, P, L, F, tau) -> None:  # noqa: ANN001
    """tree_kick where the scene has impulses; compiled to nothing where it has none (physics/dispatch.py)."""
    kernel_only()


@overload(tree_kick_stage, jit_options=DISPATCH_OPTIONS)
def _tree_kick_stage(forces, tree, tree_data, x, q, P, L, F, tau):  # noqa: ANN001, ANN202
    if absent(member(forces, "impulse")):
        return lambda forces, tree, tree_data, x, q, P, L, F, tau: None

    def run(forces, tree, tree_data, x, q, P, L, F, tau):  # noqa: ANN001, ANN202
        tree_kick(tree, tree_data, x, q, P, L, F, tau)

    return run


def tree_record_stage(tree, tree_data, frames, filled, due) -> None:  # noqa: ANN001
    """tree_record in a run that records the reactions (TreeData.wrench not None); else nothing to write."""
    kernel_only()


@overload(tree_record_stage, jit_options=DISPATCH_OPTIONS)
def _tree_record_stage(tree, tree_data, frames, filled, due):  # noqa: ANN001, ANN202
    if absent(member(tree_data, "wrench")):
        return lambda tree, tree_data, frames, filled, due: None

    def run(tree, tree_data, frames, filled, due):  # noqa: ANN001, ANN202
        tree_record(tree, tree_data, frames, filled, due)

    return run
