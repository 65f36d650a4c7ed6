"""The dissipative terms (spring dampers, drag) as their own flow, for the splitting integrators.

split2's kick K(h): P += h F, L += h tau, with F evaluated once at the stage midpoint, is symmetric only
when F does not depend on P and L. A damper or drag does, so the step was no longer time-symmetric and
the Suzuki composition (split4) fell to first order on every damped scene. With the wrench split into
its conservative part F_c (evaluated with `dissipative=False`) and the dissipation D, the kick becomes
  K_c(h/2) D(h) K_c(h/2)
and D(h), with x and q held (it only changes momenta), is itself a palindrome of exact flows, one per
row: D_1(h/2) ... D_n(h/2) D_n(h/2) ... D_1(h/2). Every piece is an exact flow (or, for quadratic angular
drag, the implicit midpoint rule), so every piece is symmetric and the step stays symmetric and second
order: split2 keeps order 2, split4 order 4 (tests/physics/test_damped_orders.py).

Exact flows, with x and q held:
  damper row (c, ends a and b at world offsets r_a, r_b, unit direction e = d / |d| from b to a):
    the stretching rate s = e . (v_a + omega_a x r_a - v_b - omega_b x r_b) obeys ds/dt = -c w s with
    w = 1/M_a + (r_a x e) . I_a^-1 (r_a x e) + (the same for b) (I^-1 = R diag(1/I) R^T, world), so
    s(h) = s0 exp(-c w h), and the momentum change is the impulse j = (s0 - s(h)) / w along -e at a,
    +e at b (so the pair's total momentum and angular momentum about any point are kept, as the force).
    |d| = 0: the force is zero there (spring.py), so is the flow.
  translational drag F = -(b + c |v|) v: the direction of v is kept and its speed obeys
    ds/dt = -(b s + c s^2) / M (Bernoulli): s(h) = b s0 E / (b + c s0 (1 - E)), E = exp(-b h / M), and
    s0 / (1 + c s0 h / M) for b = 0.
  angular drag tau = -b_r omega (c_r = 0): in the principal frame dm_k/dt = -b_r m_k / I_k, so
    m_k(h) = m_k exp(-b_r h / I_k), L = R m.
  angular drag with c_r != 0: m' = m - h (b_r + c_r |w|) w, w = (m + m') / (2 I): the implicit
    midpoint rule (symmetric), solved by fixed-point iteration (it contracts: h (b_r + 2 c_r |w|) / I < 2
    at any sane dt; at most 50 iterations, to a relative change of 1e-15).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.forces.body_point import rotate, rotate_inverse
from rbcli.physics.forces.tables import DAMPER_COLUMNS

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources

_MIDPOINT_ITERATIONS = 50


@numba.njit(cache=True)
def dissipation_present(spring, drag) -> bool:  # noqa: ANN001
    """True when a damper or drag row has a nonzero coefficient (tables may be None: kernel form)."""
    if spring is not None:
        for row in range(spring.damping.shape[0]):
            if spring.damping[row] != 0.0:
                return True
    if drag is not None:
        for row in range(drag.body.shape[0]):
            if drag.linear[row] != 0.0 or drag.quadratic[row] != 0.0:
                return True
            if drag.angular_linear[row] != 0.0 or drag.angular_quadratic[row] != 0.0:
                return True
    return False


@numba.njit(cache=True, inline="always")
def damper_line(spring, row, x, q):  # noqa: ANN001, ANN201 - numba scalars
    """Damper `row`'s line: the unit direction e from end b's point to end a's, the points' world offsets
    r_a, r_b from their centres of mass (r_b = 0 for a world anchor) and the length |d| (0: no direction,
    e then undefined): (ex, ey, ez, rax, ray, raz, rbx, rby, rbz, length)."""
    a = spring.body_a[row]
    pa = spring.point_a[row]
    rax, ray, raz = rotate(q, a, pa[0], pa[1], pa[2])
    dx, dy, dz = x[a, 0] + rax, x[a, 1] + ray, x[a, 2] + raz
    b = spring.body_b[row]
    pb = spring.point_b[row]
    rbx, rby, rbz = 0.0, 0.0, 0.0
    if b >= 0:
        rbx, rby, rbz = rotate(q, b, pb[0], pb[1], pb[2])
        dx -= x[b, 0] + rbx
        dy -= x[b, 1] + rby
        dz -= x[b, 2] + rbz
    else:
        dx -= pb[0]
        dy -= pb[1]
        dz -= pb[2]
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0.0:
        return 0.0, 0.0, 0.0, rax, ray, raz, rbx, rby, rbz, 0.0
    return dx / length, dy / length, dz / length, rax, ray, raz, rbx, rby, rbz, length


# A damper row's constants over one D(h): x and q are held, so its line, moment arms, I^-1 n and weight are
# the same for both of its flows (forward and backward through the rows); they are computed once per D(h)
# into these columns, and the sweeps only apply the impulses. Each row flow used to be a call taking the
# model's and the table's arrays, with the line and four turns computed again (~170 ns a row flow: the
# 1,000-body spring chain spent 334 of its 377 us split2 step in D(h), now ~80).
_E = 0  # e, the unit direction from end b's point to end a's (3)
_NA = 3  # n_a = r_a x e (3)
_GA = 6  # g_a = I_a^-1 n_a, world (3)
_NB = 9  # n_b = r_b x e (3)
_GB = 12  # g_b = I_b^-1 n_b (3)
_INV_MASS_A = 15
_INV_MASS_B = 16
_WEIGHT = 17  # w = 1/M_a + n_a . g_a (+ the same for b); 0: the row does not act (c = 0 or |d| = 0)
_DECAY = 18  # expm1(-c w h/2)
assert DAMPER_COLUMNS == _DECAY + 1


@numba.njit(cache=True)
def _damper_constants(model, spring, half, x, q, rows) -> None:  # noqa: ANN001
    """Every damper row's constants (the columns above) for flows over `half`, at the held x and q."""
    inv = model.body_inertia_inv
    for row in range(spring.damping.shape[0]):
        c = spring.damping[row]
        rows[row, _WEIGHT] = 0.0
        if c == 0.0:
            continue
        a, b = spring.body_a[row], spring.body_b[row]
        ex, ey, ez, rax, ray, raz, rbx, rby, rbz, length = damper_line(spring, row, x, q)
        if length == 0.0:
            continue
        # end a: the moment arm n = r x e and g = I^-1 n = R diag(1/I) R^T n
        nax, nay, naz = ray * ez - raz * ey, raz * ex - rax * ez, rax * ey - ray * ex
        lx, ly, lz = rotate_inverse(q, a, nax, nay, naz)
        gx, gy, gz = rotate(q, a, lx * inv[a, 0], ly * inv[a, 1], lz * inv[a, 2])
        inv_mass_a = 1.0 / model.body_mass[a]
        weight = inv_mass_a + (nax * gx + nay * gy + naz * gz)
        nbx, nby, nbz, hx, hy, hz, inv_mass_b = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        if b >= 0:
            nbx, nby, nbz = rby * ez - rbz * ey, rbz * ex - rbx * ez, rbx * ey - rby * ex
            lx, ly, lz = rotate_inverse(q, b, nbx, nby, nbz)
            hx, hy, hz = rotate(q, b, lx * inv[b, 0], ly * inv[b, 1], lz * inv[b, 2])
            inv_mass_b = 1.0 / model.body_mass[b]
            weight += inv_mass_b + (nbx * hx + nby * hy + nbz * hz)
        rows[row, _E], rows[row, _E + 1], rows[row, _E + 2] = ex, ey, ez
        rows[row, _NA], rows[row, _NA + 1], rows[row, _NA + 2] = nax, nay, naz
        rows[row, _GA], rows[row, _GA + 1], rows[row, _GA + 2] = gx, gy, gz
        rows[row, _NB], rows[row, _NB + 1], rows[row, _NB + 2] = nbx, nby, nbz
        rows[row, _GB], rows[row, _GB + 1], rows[row, _GB + 2] = hx, hy, hz
        rows[row, _INV_MASS_A], rows[row, _INV_MASS_B] = inv_mass_a, inv_mass_b
        rows[row, _WEIGHT] = weight
        rows[row, _DECAY] = math.expm1(-c * weight * half)


@numba.njit(cache=True)
def _damper_sweep(body_a, body_b, rows, first, stop, stride, P, L) -> None:  # noqa: ANN001
    """The exact flows of damper rows first, first + stride, ... (before stop), in that order (module
    docstring), from their constants."""
    for row in range(first, stop, stride):
        weight = rows[row, _WEIGHT]
        if weight == 0.0:
            continue
        a, b = body_a[row], body_b[row]
        ex, ey, ez = rows[row, _E], rows[row, _E + 1], rows[row, _E + 2]
        # e . (v + omega x r) = e . v + omega . (r x e) = e . P / M + (I^-1 n) . L  (I^-1 is symmetric, so
        # the g = I^-1 n of the effective mass also gives the rotational rate: no omega needed)
        rate = rows[row, _INV_MASS_A] * (ex * P[a, 0] + ey * P[a, 1] + ez * P[a, 2]) + (
            rows[row, _GA] * L[a, 0] + rows[row, _GA + 1] * L[a, 1] + rows[row, _GA + 2] * L[a, 2]
        )
        if b >= 0:
            rate -= rows[row, _INV_MASS_B] * (ex * P[b, 0] + ey * P[b, 1] + ez * P[b, 2]) + (
                rows[row, _GB] * L[b, 0] + rows[row, _GB + 1] * L[b, 1] + rows[row, _GB + 2] * L[b, 2]
            )
        # j = s0 (1 - exp(-c w h)) / w, with -expm1 so a small c w h keeps its digits
        j = -rate * rows[row, _DECAY] / weight
        P[a, 0] -= j * ex
        P[a, 1] -= j * ey
        P[a, 2] -= j * ez
        L[a, 0] -= j * rows[row, _NA]
        L[a, 1] -= j * rows[row, _NA + 1]
        L[a, 2] -= j * rows[row, _NA + 2]
        if b >= 0:
            P[b, 0] += j * ex
            P[b, 1] += j * ey
            P[b, 2] += j * ez
            L[b, 0] += j * rows[row, _NB]
            L[b, 1] += j * rows[row, _NB + 1]
            L[b, 2] += j * rows[row, _NB + 2]


@numba.njit(cache=True)
def _drag_sweep(body_mass, inertia_inv, drag, h, first, stop, stride, q, P, L) -> None:  # noqa: ANN001
    """The flows over time h of drag rows first, first + stride, ... (before stop) alone, in that order
    (module docstring), q held. One loop, not a call per row taking the model's arrays (~40 ns a row flow)."""
    inv = inertia_inv
    for row in range(first, stop, stride):
        b = drag.body[row]
        linear, quadratic = drag.linear[row], drag.quadratic[row]
        if linear != 0.0 or quadratic != 0.0:
            mass = body_mass[b]
            px, py, pz = P[b, 0], P[b, 1], P[b, 2]
            speed = math.sqrt(px * px + py * py + pz * pz) / mass
            if speed > 0.0:
                if linear != 0.0:
                    decay = math.exp(-linear * h / mass)
                    # s(h) / s0 = b E / (b + c s0 (1 - E)), 1 - E = -expm1(-b h / M)
                    factor = linear * decay / (linear - quadratic * speed * math.expm1(-linear * h / mass))
                else:
                    factor = 1.0 / (1.0 + quadratic * speed * h / mass)
                P[b, 0], P[b, 1], P[b, 2] = px * factor, py * factor, pz * factor
        angular_linear, angular_quadratic = drag.angular_linear[row], drag.angular_quadratic[row]
        if angular_linear == 0.0 and angular_quadratic == 0.0:
            continue
        m0, m1, m2 = rotate_inverse(q, b, L[b, 0], L[b, 1], L[b, 2])
        if angular_quadratic == 0.0:
            m0 *= math.exp(-angular_linear * h * inv[b, 0])
            m1 *= math.exp(-angular_linear * h * inv[b, 1])
            m2 *= math.exp(-angular_linear * h * inv[b, 2])
        else:  # implicit midpoint: n = m - h (b_r + c_r |w|) w, w = (m + n) / (2 I)
            n0, n1, n2 = m0, m1, m2
            for _ in range(_MIDPOINT_ITERATIONS):
                w0, w1, w2 = 0.5 * (m0 + n0) * inv[b, 0], 0.5 * (m1 + n1) * inv[b, 1], 0.5 * (m2 + n2) * inv[b, 2]
                rate = h * (angular_linear + angular_quadratic * math.sqrt(w0 * w0 + w1 * w1 + w2 * w2))
                k0, k1, k2 = m0 - rate * w0, m1 - rate * w1, m2 - rate * w2
                change = abs(k0 - n0) + abs(k1 - n1) + abs(k2 - n2)
                n0, n1, n2 = k0, k1, k2
                if change <= 1e-15 * (abs(n0) + abs(n1) + abs(n2)):
                    break
            m0, m1, m2 = n0, n1, n2
        L[b, 0], L[b, 1], L[b, 2] = rotate(q, b, m0, m1, m2)


@numba.njit(cache=True)
def dissipation_flow(model, spring, drag, rows, h, x, q, P, L) -> None:  # noqa: ANN001
    """D(h): the palindrome of every damper's and drag row's flow, each over h/2 forward then backward
    through the rows (symmetric, second order; module docstring). Tables may be None (kernel form).
    rows: the dampers' constants, ForceData.damper (a row per spring row where any spring damps)."""
    half = 0.5 * h
    # the passes' bounds as int64 values, not literals: a literal 0, 1 or -1 typed each pass apart, and
    # numba compiled each sweep twice (once per direction) for every damped scene's first run
    zero, one = np.int64(0), np.int64(1)
    dampers = False
    if spring is not None:
        count = spring.damping.shape[0]
        dampers = rows.shape[0] >= count > 0
        if not dampers and dissipation_present(spring, None):  # a ForceData made without the force tables
            raise ValueError("ForceData.damper has fewer rows than the spring table: make_force_data(forces=...)")
        if dampers:
            _damper_constants(model, spring, half, x, q, rows)
            _damper_sweep(spring.body_a, spring.body_b, rows, zero, count, one, P, L)
    if drag is not None:
        count = drag.body.shape[0]
        _drag_sweep(model.body_mass, model.body_inertia_inv, drag, half, zero, count, one, q, P, L)
        _drag_sweep(model.body_mass, model.body_inertia_inv, drag, half, count - one, -one, -one, q, P, L)
    if spring is not None:
        if dampers:
            count = spring.damping.shape[0]
            _damper_sweep(spring.body_a, spring.body_b, rows, count - one, -one, -one, P, L)


def dissipation_flow_numpy(model, spring, drag, h, x, q, P, L) -> None:  # noqa: ANN001
    """Numpy twin of `dissipation_flow` (row by row: the rows act in sequence)."""
    from rbcli.physics.rotation import quat_rotate, quat_rotate_inverse

    def inv_inertia(b: int, v: np.ndarray) -> np.ndarray:
        return quat_rotate(q[b], model.body_inertia_inv[b] * quat_rotate_inverse(q[b], v))

    def damper(row: int, s: float) -> None:
        c = spring.damping[row]
        if c == 0.0:
            return
        a, b = spring.body_a[row], spring.body_b[row]
        ra = quat_rotate(q[a], spring.point_a[row])
        rb = quat_rotate(q[b], spring.point_b[row]) if b >= 0 else np.zeros(3)
        d = x[a] + ra - (x[b] + rb if b >= 0 else spring.point_b[row])
        if not np.any(d):
            return
        e = d / np.linalg.norm(d)
        ends = [(a, ra, 1.0)] + ([(b, rb, -1.0)] if b >= 0 else [])
        rate = sum(sign * (e @ P[k] / model.body_mass[k] + inv_inertia(k, L[k]) @ np.cross(r, e))
                   for k, r, sign in ends)  # fmt: skip
        weight = sum(1.0 / model.body_mass[k] + np.cross(r, e) @ inv_inertia(k, np.cross(r, e)) for k, r, _ in ends)
        j = rate * (1.0 - np.exp(-c * weight * s)) / weight
        for k, r, sign in ends:
            P[k] -= sign * j * e
            L[k] -= sign * j * np.cross(r, e)

    def drag_row(row: int, s: float) -> None:
        b = drag.body[row]
        lin, quad = drag.linear[row], drag.quadratic[row]
        speed = np.linalg.norm(P[b]) / model.body_mass[b]
        if (lin or quad) and speed > 0.0:
            mass = model.body_mass[b]
            E = np.exp(-lin * s / mass)
            P[b] *= lin * E / (lin + quad * speed * (1.0 - E)) if lin else 1.0 / (1.0 + quad * speed * s / mass)
        al, aq = drag.angular_linear[row], drag.angular_quadratic[row]
        if not (al or aq):
            return
        inv = model.body_inertia_inv[b]
        m = quat_rotate_inverse(q[b], L[b])
        if not aq:
            m = m * np.exp(-al * s * inv)
        else:
            n = m.copy()
            for _ in range(_MIDPOINT_ITERATIONS):
                w = 0.5 * (m + n) * inv
                n = m - s * (al + aq * np.linalg.norm(w)) * w
        L[b] = quat_rotate(q[b], m if not aq else n)

    rows = range(spring.damping.shape[0])
    for row in rows:
        damper(row, 0.5 * h)
    for row in range(drag.body.shape[0]):
        drag_row(row, 0.5 * h)
    for row in reversed(range(drag.body.shape[0])):
        drag_row(row, 0.5 * h)
    for row in reversed(rows):
        damper(row, 0.5 * h)
