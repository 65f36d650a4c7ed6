"""`exact`: force kicks around the EXACT torque-free motion (Celledoni, Fasso, Safstrom & Zanna 2008).

The splitting of split2 with the three principal-axis turns replaced by the exact flow of the whole
free-body kinetic energy T = sum m_k^2/(2 I_k) (Jacobi elliptic functions and an elliptic integral
of the third kind; `rbcli.physics.free_rotation_exact`, CFSZ 2008, "The exact computation of the
free rigid body motion and its use in splitting methods", SIAM J. Sci. Comput. 30):

  D(h/2) K(h) D(h/2),  D(s): x += s P/M and q <- exact free flow over s (L fixed in the world),
                       K(s): P += s F, L += s tau, one wrench evaluation at t + h/2.

With dampers or drag the kick is K_c(h/2) Dis(h) K_c(h/2), as in split2: F_c without the
velocity-dependent terms, Dis their own exact (symmetric) flow at the midpoint's x and q
(forces/damping.py). A kick with them inside is not symmetric, and the step fell to first order on
every damped scene (spring chain from t = 0.1 s: exact 1.15, exact4 1.00; now 2.00 and 4.00,
tests/physics/test_damped_orders.py). A body whose momentum the flow changes (a damper's end,
translational drag) has no constant-force flight, so its centre takes the leapfrog's second half from
the midpoint instead of the translation anchor below; its rotation keeps its anchor when it has no
torque (a damper at the centre of mass, linear drag alone: the flow leaves its L alone).

Exact at any horizon: from its ANCHOR. A body without torque keeps L, so its orientation at time t is
one call of the free flow from the orientation q_a it had at the anchor time t_a, q(t) = flow(q_a, L,
t - t_a), not a chain of per-step calls each restarting from its own rounded result (that chain grew
like the number of steps: 1e-8 rad on the flip at dt = 3e-4 over 20 s). Likewise a body whose force F
has not changed (bitwise) since its translation anchor is in free flight there: x = x_a + (t - t_a)
(P_a + (t - t_a) F / 2) / M, P = P_a + (t - t_a) F, which is what leapfrog computes for a constant
force, without its per-step rounding. The anchors (scratch columns below, in the run's Data) are
taken at the start of a run, after `Simulation.set_state` / `reset` (which clear the scratch), and
whenever the state differs from what this integrator last wrote (an impulse, any outside write); a
translation anchor also when F changes (a spring: then each step is the leapfrog step), and none for a
damped body. Bodies with
a torque chain the flow through the kicks as before (second order through the forces).

Evaluated only when needed: when the scene's only force is uniform gravity (no other force type, no
impulses, no contact: `forces_are_constant`) nothing between recorded frames depends on the states in
between, so inside a chunk loop the step only keeps the anchors and the pipeline's `materialise`
stage evaluates the closed form on recording steps and at the chunk's end: the cost is per recorded
frame. The stage's first call sets a flag in the scratch that lets `step` defer; `step` called on its
own (tests, benchmarks) never sees it and writes the state every step. The results are bitwise the
same either way (the same closed form at the same elapsed time (t - t_a) + h).
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np
from numba.core import types
from numba.extending import overload

from rbcli.physics.elliptic import JACOBI_WORK_SIZE
from rbcli.physics.forces.damping import dissipation_flow, dissipation_flow_numpy, dissipation_present
from rbcli.physics.forces.wrench import accumulate_wrench, wrench_numpy
from rbcli.physics.free_rotation_anchored import ANCHOR_CONSTANTS, anchor_evaluate, anchor_prepare
from rbcli.physics.free_rotation_exact import _free_rotation_exact_work, free_rotation_exact_batch
from rbcli.physics.step import STEP_ENTRY, STEP_KERNEL

# Scratch columns per body (the run's Data.scratch, zeroed by Data.clear_work: no anchor):
Q_MID = 0  # (4) orientation at the force evaluation (the wrench reads it as its q: first columns)
X_START = 4  # (3) centre of mass at the step's start (x holds the midpoint during the force pass)
ROT_ANCHORED = 7  # 1.0 when the rotation anchor below is the body's (torque-free) motion
ROT_T = 8  # anchor time t_a [s]
ROT_Q = 9  # (4) orientation at t_a, wxyz world-from-principal
ROT_L = 13  # (3) world angular momentum at t_a [kg m^2/s]
TR_ANCHORED = 16  # 1.0 when the translation anchor below is the body's (constant-force) motion
TR_T = 17  # anchor time [s]
TR_X = 18  # (3) centre of mass at the anchor [m]
TR_P = 21  # (3) momentum at the anchor [kg m/s]
TR_F = 24  # (3) the constant force [N] (nan: not known yet)
LAST_X = 27  # (3) the state this integrator last wrote: a difference means someone else changed it
LAST_Q = 30  # (4)
LAST_P = 34  # (3)
LAST_L = 37  # (3)
EVALUATIONS = 40  # closed-form evaluations of this body's motion since the scratch was cleared
DEFERRED = 41  # row 0: 1.0 once a chunk loop's materialise stage has run (the step may then defer)
DAMPED = 42  # 1.0 when a damper or translational drag acts on the body's momentum (set every damped step)
ROT_CONSTANTS = 43  # (ANCHOR_CONSTANTS) the flow's constants at the rotation anchor (free_rotation_anchored)
SCRATCH_WIDTH = ROT_CONSTANTS + ANCHOR_CONSTANTS
# The anchored flow needs no work array (its Jacobi AGM is kept in the constants). A body with a torque
# chains the one-shot flow, whose Jacobi functions need JACOBI_WORK_SIZE floats of work: its own row's
# ROT_CONSTANTS columns, unused while it has no rotation anchor. (A shared work area in row 0 made every
# row 48 columns wider, and the evaluation, which streams through the rows, a third slower: measured.)
assert ANCHOR_CONSTANTS >= JACOBI_WORK_SIZE

WEIGHTS = np.array([1.0])

# typed Any: numba's stubs type jit_options as a TypedDict without STEP_KERNEL's private `_nrt`
_OPTIONS: Any = STEP_KERNEL


def forces_are_constant(forces, contact) -> bool:  # noqa: ANN001
    """True when uniform gravity is the scene's only force (no other type, no impulses, no contact: the
    model's contact table `contact` None or empty): every body's F = M g is constant and its tau zero,
    so no state between recorded frames matters."""
    raise TypeError("forces_are_constant runs in compiled kernels only")


def _table_rows(table) -> int:  # noqa: ANN001
    raise TypeError("_table_rows runs in compiled kernels only")


@overload(_table_rows, jit_options=_OPTIONS)
def _table_rows_overload(table):  # noqa: ANN001, ANN202
    if isinstance(table, types.NoneType):  # absent from ForceTables.kernel() or Model.kernel(): known when compiling
        return lambda table: 0
    if "sphere_body" in table.fields:  # the contact table: spheres or static bodies
        return lambda table: table.sphere_body.shape[0] + table.static_body.shape[0]
    return lambda table: table[0].shape[0]  # every force table's first column has one entry per row


@overload(forces_are_constant, jit_options=_OPTIONS)
def _forces_are_constant_overload(forces, contact):  # noqa: ANN001, ANN202
    def run(forces, contact):  # noqa: ANN001, ANN202
        rows = _table_rows(forces.field) + _table_rows(forces.point_force) + _table_rows(forces.torque)
        rows += _table_rows(forces.spring) + _table_rows(forces.drag) + _table_rows(forces.impulse)
        return rows + _table_rows(contact) == 0

    return run


@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One `exact` step of every body, in place (one force evaluation, at t + dt/2, unless the forces are
    constant); defers writing the state only once a chunk loop's `materialise` stage has said it runs."""
    _step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch)


@numba.njit(cache=True, inline="always")
def _same(scratch, b, column, values, count) -> bool:  # noqa: ANN001
    """values[b, :count] == scratch[b, column : column + count], bitwise (nan never equal)."""
    for k in range(count):
        if values[b, k] != scratch[b, column + k]:
            return False
    return True


@numba.njit(cache=True, inline="always")
def _keep_anchors(model, forces, b, t, x, q, P, L, scratch, torque_free, constant) -> None:  # noqa: ANN001
    """Take body b's anchors from its state at time t where the state is not what was last written."""
    row = scratch[b]
    written = _same(scratch, b, LAST_X, x, 3) and _same(scratch, b, LAST_P, P, 3)
    turned = _same(scratch, b, LAST_Q, q, 4) and _same(scratch, b, LAST_L, L, 3)
    if not (written and row[TR_ANCHORED] == 1.0):
        row[TR_ANCHORED], row[TR_T] = 1.0, t
        for k in range(3):
            row[TR_X + k], row[TR_P + k] = x[b, k], P[b, k]
            row[TR_F + k] = np.nan  # unknown until the force pass says (a constant scene: M g, below)
            if constant:  # F = M g exactly as accumulate_gravity forms it (0 + M g)
                row[TR_F + k] = 0.0 + model.body_mass[b] * forces.gravity[k] if forces.has_gravity else 0.0
    if torque_free and not (turned and row[ROT_ANCHORED] == 1.0):
        row[ROT_ANCHORED], row[ROT_T] = 1.0, t
        for k in range(4):
            row[ROT_Q + k] = q[b, k]
        for k in range(3):
            row[ROT_L + k] = L[b, k]
        anchor_prepare(model.body_inertia[b], q[b], L[b], row[ROT_CONSTANTS:SCRATCH_WIDTH])
    elif not torque_free:
        row[ROT_ANCHORED] = 0.0


@numba.njit(cache=True, inline="always")
def _anchored_flow(model, row, b, elapsed, q_out) -> None:  # noqa: ANN001
    """q_out = the free flow from body b's rotation anchor (row: its scratch row) over elapsed [s]."""
    anchor_evaluate(row[ROT_CONSTANTS:SCRATCH_WIDTH], elapsed, q_out)
    row[EVALUATIONS] += 1.0


@numba.njit(cache=True, inline="always")
def _rotation_from_anchor(model, row, b, elapsed, q, L) -> None:  # noqa: ANN001
    """A torque-free body's orientation at its rotation anchor's time plus elapsed [s], and its L."""
    if row[ROT_ANCHORED] == 1.0:
        _anchored_flow(model, row, b, elapsed, q[b])
        for k in range(3):
            L[b, k] = row[ROT_L + k]


@numba.njit(cache=True, inline="always")
def _write_from_anchor(model, b, elapsed_rot, elapsed_tr, x, q, P, L, scratch) -> None:  # noqa: ANN001
    """Body b's state at its anchors' times plus the elapsed times [s]: the closed forms, then recorded
    as last written."""
    row = scratch[b]
    _rotation_from_anchor(model, row, b, elapsed_rot, q, L)
    s = elapsed_tr
    inverse_mass = 1.0 / model.body_mass[b]
    for k in range(3):
        P[b, k] = row[TR_P + k] + s * row[TR_F + k]
        x[b, k] = row[TR_X + k] + s * inverse_mass * (row[TR_P + k] + 0.5 * s * row[TR_F + k])
    _remember(b, x, q, P, L, scratch)


@numba.njit(cache=True, inline="always")
def _remember(b, x, q, P, L, scratch) -> None:  # noqa: ANN001
    row = scratch[b]
    for k in range(3):
        row[LAST_X + k], row[LAST_P + k], row[LAST_L + k] = x[b, k], P[b, k], L[b, k]
    for k in range(4):
        row[LAST_Q + k] = q[b, k]


@numba.njit(**STEP_KERNEL)
def _step(model, forces, contact, force_data, t, h, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001
    """The step of the module docstring."""
    n = x.shape[0]
    if n == 0:
        return
    constant = forces_are_constant(forces, contact)
    torque = forces.has_torque
    for b in range(n):
        _keep_anchors(model, forces, b, t, x, q, P, L, scratch, not (torque and forces.torque_body[b]), constant)
    if constant:
        if scratch[0, DEFERRED] == 1.0:
            return  # materialise writes the state when it is due
        for b in range(n):
            row = scratch[b]
            _write_from_anchor(model, b, (t - row[ROT_T]) + h, (t - row[TR_T]) + h, x, q, P, L, scratch)
        return
    # the force evaluation at the midpoint: x + (h/2) P/M, the flow at t + h/2
    for b in range(n):
        row = scratch[b]
        drift = 0.5 * h / model.body_mass[b]
        for k in range(3):
            row[X_START + k] = x[b, k]
            x[b, k] += drift * P[b, k]
        if row[ROT_ANCHORED] == 1.0:
            _anchored_flow(model, row, b, (t - row[ROT_T]) + 0.5 * h, row[Q_MID : Q_MID + 4])
        else:
            work = row[ROT_CONSTANTS : ROT_CONSTANTS + JACOBI_WORK_SIZE]  # free: no rotation anchor
            _free_rotation_exact_work(model.body_inertia[b], q[b], L[b], 0.5 * h, row[Q_MID : Q_MID + 4], work)
    # with dampers or drag the kick K(h) is K_c(h/2) D(h) K_c(h/2), as in split2 (forces/damping.py)
    dissipative = dissipation_present(forces.spring, forces.drag)
    accumulate_wrench(model, forces, contact, force_data, t + 0.5 * h, x, scratch, P, L, F, tau, not dissipative)
    kick = h
    if dissipative:
        kick = 0.5 * h
        _mark_damped(forces.spring, forces.drag, scratch)
        _half_kick(kick, P, L, F, tau, scratch)
        # at x and q of the midpoint
        dissipation_flow(model, forces.spring, forces.drag, force_data.damper, h, x, scratch, P, L)
    for b in range(n):
        row = scratch[b]
        if row[ROT_ANCHORED] != 1.0:  # a torque: kick L, then the second half-flow from the midpoint
            for k in range(3):
                L[b, k] += kick * tau[b, k]
            work = row[ROT_CONSTANTS : ROT_CONSTANTS + JACOBI_WORK_SIZE]
            _free_rotation_exact_work(model.body_inertia[b], row[Q_MID : Q_MID + 4], L[b], 0.5 * h, q[b], work)
        if dissipative and row[DAMPED] == 1.0:
            # the dissipation changed P: no constant-force flight to anchor, the leapfrog's second half
            drift = 0.5 * h / model.body_mass[b]
            for k in range(3):
                P[b, k] += kick * F[b, k]
                x[b, k] += drift * P[b, k]
            row[TR_ANCHORED] = 0.0
            _rotation_from_anchor(model, row, b, (t - row[ROT_T]) + h, q, L)
            _remember(b, x, q, P, L, scratch)
            continue
        if not _same(scratch, b, TR_F, F, 3):
            # a new force: the translation restarts from the step's start, F constant over the step
            row[TR_T] = t
            for k in range(3):
                row[TR_X + k], row[TR_P + k], row[TR_F + k] = row[X_START + k], P[b, k], F[b, k]
        _write_from_anchor(model, b, (t - row[ROT_T]) + h, (t - row[TR_T]) + h, x, q, P, L, scratch)


@numba.njit(cache=True)
def _mark_damped(spring, drag, scratch) -> None:  # noqa: ANN001
    """scratch[:, DAMPED] = 1.0 for the bodies a damper or translational drag acts on (their P changes
    in the dissipation flow), 0.0 for the others. Tables may be None (kernel form)."""
    for b in range(scratch.shape[0]):
        scratch[b, DAMPED] = 0.0
    if spring is not None:
        for row in range(spring.damping.shape[0]):
            if spring.damping[row] != 0.0:
                scratch[spring.body_a[row], DAMPED] = 1.0
                if spring.body_b[row] >= 0:
                    scratch[spring.body_b[row], DAMPED] = 1.0
    if drag is not None:
        for row in range(drag.body.shape[0]):
            if drag.linear[row] != 0.0 or drag.quadratic[row] != 0.0:
                scratch[drag.body[row], DAMPED] = 1.0


@numba.njit(cache=True)
def _half_kick(kick, P, L, F, tau, scratch) -> None:  # noqa: ANN001
    """K_c(kick) before the dissipation flow: P of the damped bodies (the others' P is left to the
    translation anchor, which the flow does not touch), L of the bodies with a torque."""
    for b in range(P.shape[0]):
        row = scratch[b]
        if row[DAMPED] == 1.0:
            for k in range(3):
                P[b, k] += kick * F[b, k]
        if row[ROT_ANCHORED] != 1.0:
            for k in range(3):
                L[b, k] += kick * tau[b, k]


@numba.njit(**STEP_KERNEL)
def materialise(model, forces, contact, t, h, x, q, P, L, scratch, due) -> None:  # noqa: ANN001
    """The chunk loop's stage after each step [t, t + h): when the forces are constant (the step then
    defers) and the state is due (a recording step or the chunk's last), write every body's state from
    its anchors. Its first call (after the scratch was cleared) tells `step` it may defer from now on."""
    if x.shape[0] == 0 or not forces_are_constant(forces, contact):
        return
    if scratch[0, DEFERRED] != 1.0:
        scratch[0, DEFERRED] = 1.0  # this step was written already; the next ones need not be
        return
    if due:
        for b in range(x.shape[0]):
            row = scratch[b]
            _write_from_anchor(model, b, (t - row[ROT_T]) + h, (t - row[TR_T]) + h, x, q, P, L, scratch)


@numba.njit(cache=True)
def compose(model, forces, contact, force_data, t, h, weights, x, q, P, L, F, tau, q_mid) -> None:  # noqa: ANN001
    """The composition exact(w_{s-1} h) ... exact(w_0 h), adjacent half drifts merged, in place.

    With torques the kicks change L, so the flow is chained through the stages. Torque-free L stays
    put and the orientation at every force evaluation is exact(q0, elapsed) written to q_mid (N, 4),
    and the step ends with q = exact(q0, h): every orientation is ONE call away from the step's
    start, so round-off does not pile up through s + 1 chained calls (it halves the flip-case error).
    Which of the two is a scene-wide choice (has_torque; both cost s + 1 flows); the kick adds tau only
    for the bodies torque_body flags (tau = 0 for the others). With dampers or drag each kick is
    K_c(h/2) Dis(h) K_c(h/2) (module docstring); Dis changes L only for torque bodies, so the
    torque-free path's fixed L still holds.
    """
    count = weights.shape[0]
    torque = forces.has_torque
    dissipative = dissipation_present(forces.spring, forces.drag)
    work = q_mid[0, 4:]  # a view: the step allocates nothing
    elapsed = 0.5 * weights[0] * h
    _drift_centre(model, elapsed, x, P)
    if torque:
        free_rotation_exact_batch(model.body_inertia, q, L, elapsed, q, work)
    for i in range(count):
        if not torque:
            free_rotation_exact_batch(model.body_inertia, q, L, elapsed, q_mid, work)
        q_now = q if torque else q_mid  # (one wrench call site: the compiled wrench is inlined once)
        accumulate_wrench(model, forces, contact, force_data, t + elapsed, x, q_now, P, L, F, tau, not dissipative)
        h_prev = weights[i] * h
        h_next = weights[i + 1] * h if i + 1 < count else 0.0
        if dissipative:  # K_c(h/2) D(h) K_c(h/2) (forces/damping.py)
            _kick(model, torque, forces.torque_body, 0.5 * h_prev, P, L, F, tau)
            dissipation_flow(model, forces.spring, forces.drag, force_data.damper, h_prev, x, q_now, P, L)
            _kick(model, torque, forces.torque_body, 0.5 * h_prev, P, L, F, tau)
        else:
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
    """Numpy reference of `compose`, stages unmerged: D(s/2) K(s) D(s/2) each (K(s) = K_c(s/2) D(s) K_c(s/2)
    with dampers or drag)."""
    elapsed = 0.0
    for weight in weights:
        s = weight * h
        x += 0.5 * s * P / model.body_mass[:, None]
        free_rotation_exact_batch(model.body_inertia, q, L, 0.5 * s, q, np.empty(JACOBI_WORK_SIZE))
        dissipative = bool(np.any(forces.spring.damping != 0.0) or _drag_present(forces.drag))
        F, tau = wrench_numpy(model, forces, t + elapsed + 0.5 * s, x, q, P, L, dissipative=not dissipative)
        kick = 0.5 * s if dissipative else s  # K_c(s/2) D(s) K_c(s/2) with dampers or drag
        P += kick * F
        if forces.has_torque:
            L += kick * tau
        if dissipative:
            dissipation_flow_numpy(model, forces.spring, forces.drag, s, x, q, P, L)
            P += kick * F
            if forces.has_torque:
                L += kick * tau
        x += 0.5 * s * P / model.body_mass[:, None]
        free_rotation_exact_batch(model.body_inertia, q, L, 0.5 * s, q, np.empty(JACOBI_WORK_SIZE))
        elapsed += s


def _drag_present(drag) -> bool:  # noqa: ANN001
    """Whether some drag row has a nonzero coefficient (numpy twin of part of `dissipation_present`)."""
    coefficients = np.concatenate([drag.linear, drag.quadratic, drag.angular_linear, drag.angular_quadratic])
    return bool(np.any(coefficients != 0.0))
