"""Dampers and drag on jointed bodies: their flow on the joints' tangent space, for the RATTLE step.

split2 takes the dissipative terms out of its kick as their own flow D (forces/damping.py: each damper
and drag row's exact flow with x and q held, composed as a palindrome), which keeps it second order on
free bodies. On bodies held by joints that flow is not the system's: the velocity a damper slows is the
joints' (the rows' velocities V with G V = 0), and the mass it acts on is the constrained one. Composed
with RATTLE as the free flow, the step was first order (measured 2026-12-06 against the same motion in
joint coordinates: docs/integrators.md, "Limitations"): the step's end applied it to the drift's momenta,
which break the velocity rows by O(h), and both ends used the free bodies' effective mass.

Here every row is a linear damper along a fixed direction J (a 1 x 6N row of body velocities), and its
flow on the tangent space, positions held, is exact: with V tangent (G V = 0), W the bodies' inverse
masses and A = G W G^T,

    r = J V                                      the row's rate
    w_c = J W J^T - b . A^-1 b,  b = G W J^T      its constrained inverse effective mass
    r(s) = r exp(-c w_c s)
    V(s) = V - j W (J^T - G^T A^-1 b),  j = r (1 - exp(-c w_c s)) / w_c

the impulse -j J^T and the joints' reaction j G^T A^-1 b (added to the joints' reactions), so V stays
tangent. The rows: each spring damper (J from its two ends' points along the spring, as forces/damping.py),
and each drag row as six rows along the world axes, three on the body's velocity and three on its angular
velocity, with coefficients b + c |v| and b_r + c_r |omega| (the quadratic parts frozen at the row's
start: exact for linear drag, first order in the quadratic coefficients). D(h) is the palindrome of the
rows' flows over h/2, forward then backward: symmetric, so the RATTLE step with D(h/2) on tangent
momenta at both ends stays symmetric and second order (tests/physics/test_joints_damped.py).

Each row costs one solve with the factor of A at the configuration (joints/solver.py), skipped for a row
whose bodies no joint holds (b = 0: the free flow).
"""

from __future__ import annotations

import math

import numba

from rbcli.physics import kernel_cache
from rbcli.physics.forces.damping import damper_line
from rbcli.physics.joints.impulses import apply_body_impulses, gather_impulses
from rbcli.physics.joints.solver import solve_rows
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL

kernel_cache.install()


@numba.njit(cache=True)
def _row_flow(table, work, s, c, a, b, la0, la1, la2, aa0, aa1, aa2, lb0, lb1, lb2, ab0, ab1, ab2, P, L) -> None:  # noqa: ANN001, E501
    """The exact tangent-space flow over s of a linear damper c on the row J = (la, aa) on body a, (lb, ab)
    on body b (b < 0: none), module docstring. work holds W and G at the configuration and the factor."""
    inv_mass, inv_inertia = work.inv_mass, work.inv_inertia
    # dV = W J^T per end, and the row's rate r = J V and w = J W J^T
    ma = inv_mass[a]
    Ia = inv_inertia[a]
    da0, da1, da2 = ma * la0, ma * la1, ma * la2
    ea0 = Ia[0, 0] * aa0 + Ia[0, 1] * aa1 + Ia[0, 2] * aa2
    ea1 = Ia[1, 0] * aa0 + Ia[1, 1] * aa1 + Ia[1, 2] * aa2
    ea2 = Ia[2, 0] * aa0 + Ia[2, 1] * aa1 + Ia[2, 2] * aa2
    rate = ma * (la0 * P[a, 0] + la1 * P[a, 1] + la2 * P[a, 2]) + (ea0 * L[a, 0] + ea1 * L[a, 1] + ea2 * L[a, 2])
    weight = la0 * da0 + la1 * da1 + la2 * da2 + aa0 * ea0 + aa1 * ea1 + aa2 * ea2
    db0 = db1 = db2 = eb0 = eb1 = eb2 = 0.0
    if b >= 0:
        mb = inv_mass[b]
        Ib = inv_inertia[b]
        db0, db1, db2 = mb * lb0, mb * lb1, mb * lb2
        eb0 = Ib[0, 0] * ab0 + Ib[0, 1] * ab1 + Ib[0, 2] * ab2
        eb1 = Ib[1, 0] * ab0 + Ib[1, 1] * ab1 + Ib[1, 2] * ab2
        eb2 = Ib[2, 0] * ab0 + Ib[2, 1] * ab1 + Ib[2, 2] * ab2
        rate += mb * (lb0 * P[b, 0] + lb1 * P[b, 1] + lb2 * P[b, 2]) + (eb0 * L[b, 0] + eb1 * L[b, 1] + eb2 * L[b, 2])
        weight += lb0 * db0 + lb1 * db1 + lb2 * db2 + ab0 * eb0 + ab1 * eb1 + ab2 * eb2
    if weight <= 0.0:  # both ends ground bodies: nothing moves
        return
    # b_r = G W J^T: each row's rate for that velocity change (only the rows on a or b have one)
    rhs, y = work.rhs, work.delta
    held = False
    for j in range(table.kind.shape[0]):
        ja, jb = table.body_a[j], table.body_b[j]
        for r in range(table.row_start[j], table.row_start[j] + table.row_count[j]):
            value = 0.0
            for side in range(2):
                end = ja if side == 0 else jb
                jac = work.jac_a if side == 0 else work.jac_b
                if end < 0:
                    continue
                if end == a:
                    value += (jac[r, 0] * da0 + jac[r, 1] * da1 + jac[r, 2] * da2
                              + jac[r, 3] * ea0 + jac[r, 4] * ea1 + jac[r, 5] * ea2)  # fmt: skip
                if end == b:
                    value += (jac[r, 0] * db0 + jac[r, 1] * db1 + jac[r, 2] * db2
                              + jac[r, 3] * eb0 + jac[r, 4] * eb1 + jac[r, 5] * eb2)  # fmt: skip
            rhs[r] = value
            held = held or value != 0.0
    if held:
        solve_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b, rhs, y)
        for r in range(rhs.shape[0]):
            weight -= rhs[r] * y[r]
    if weight <= 0.0:  # the joints hold the row still: no rate to slow
        return
    j_imp = -rate * math.expm1(-c * weight * s) / weight
    P[a, 0] -= j_imp * la0
    P[a, 1] -= j_imp * la1
    P[a, 2] -= j_imp * la2
    L[a, 0] -= j_imp * aa0
    L[a, 1] -= j_imp * aa1
    L[a, 2] -= j_imp * aa2
    if b >= 0:
        P[b, 0] -= j_imp * lb0
        P[b, 1] -= j_imp * lb1
        P[b, 2] -= j_imp * lb2
        L[b, 0] -= j_imp * ab0
        L[b, 1] -= j_imp * ab1
        L[b, 2] -= j_imp * ab2
    if held:  # the joints' reaction j G^T A^-1 b keeps V on G V = 0
        for r in range(y.shape[0]):
            y[r] *= j_imp
        gather_impulses(table, work, y)
        apply_body_impulses(table, work, P, L)


@numba.njit(cache=True)
def _damper_row(model, spring, table, work, row, s, x, q, P, L) -> None:  # noqa: ANN001
    """Spring damper `row`: J = (e, r_a x e) at end a, -(e, r_b x e) at end b, e from b's point to a's."""
    c = spring.damping[row]
    if c == 0.0:
        return
    a, b = spring.body_a[row], spring.body_b[row]
    ex, ey, ez, rax, ray, raz, rbx, rby, rbz, length = damper_line(spring, row, x, q)
    if length == 0.0:  # the force is zero there (spring.py), so is the flow
        return
    nax, nay, naz = ray * ez - raz * ey, raz * ex - rax * ez, rax * ey - ray * ex
    nbx, nby, nbz = rby * ez - rbz * ey, rbz * ex - rbx * ez, rbx * ey - rby * ex
    _row_flow(table, work, s, c, a, b, ex, ey, ez, nax, nay, naz, -ex, -ey, -ez, -nbx, -nby, -nbz, P, L)


@numba.njit(cache=True)
def _drag_rows(model, drag, table, work, row, s, q, P, L, forward) -> None:  # noqa: ANN001
    """Drag `row` as six rows along the world axes (linear, then angular; reversed when not forward), each
    a linear damper with the coefficient at its start (module docstring)."""
    b = drag.body[row]
    linear, quadratic = drag.linear[row], drag.quadratic[row]
    angular_linear, angular_quadratic = drag.angular_linear[row], drag.angular_quadratic[row]
    for k in range(6):
        axis = k if forward else 5 - k
        lx, ly, lz, ax, ay, az = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        if axis < 3:
            if linear == 0.0 and quadratic == 0.0:
                continue
            c = linear
            if quadratic != 0.0:
                c += quadratic * math.sqrt(P[b, 0] ** 2 + P[b, 1] ** 2 + P[b, 2] ** 2) / model.body_mass[b]
            if axis == 0:
                lx = 1.0
            elif axis == 1:
                ly = 1.0
            else:
                lz = 1.0
        else:
            if angular_linear == 0.0 and angular_quadratic == 0.0:
                continue
            c = angular_linear
            if angular_quadratic != 0.0:
                I = work.inv_inertia[b]  # noqa: E741 - the inverse inertia
                w0 = I[0, 0] * L[b, 0] + I[0, 1] * L[b, 1] + I[0, 2] * L[b, 2]
                w1 = I[1, 0] * L[b, 0] + I[1, 1] * L[b, 1] + I[1, 2] * L[b, 2]
                w2 = I[2, 0] * L[b, 0] + I[2, 1] * L[b, 1] + I[2, 2] * L[b, 2]
                c += angular_quadratic * math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
            if axis == 3:
                ax = 1.0
            elif axis == 4:
                ay = 1.0
            else:
                az = 1.0
        _row_flow(table, work, s, c, b, -1, lx, ly, lz, ax, ay, az, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, P, L)


@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_dissipation(model, spring, drag, table, work, h, x, q, P, L) -> None:  # noqa: ANN001
    """D(h) on the joints' tangent space (module docstring): every damper's and drag row's exact flow over
    h/2, forward then backward through the rows. Needs the factor of A at (x, q) in work (joints/stages.py
    factor_at) and momenta with G V = 0. Tables may be None (kernel form)."""
    half = 0.5 * h
    if spring is not None:
        for row in range(spring.damping.shape[0]):
            _damper_row(model, spring, table, work, row, half, x, q, P, L)
    if drag is not None:
        for row in range(drag.body.shape[0]):
            _drag_rows(model, drag, table, work, row, half, q, P, L, True)
        for row in range(drag.body.shape[0] - 1, -1, -1):
            _drag_rows(model, drag, table, work, row, half, q, P, L, False)
    if spring is not None:
        for row in range(spring.damping.shape[0] - 1, -1, -1):
            _damper_row(model, spring, table, work, row, half, x, q, P, L)
