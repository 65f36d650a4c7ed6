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


@numba.njit(cache=True)
def _inverse_inertia_times(model, q, b, vx, vy, vz):  # noqa: ANN001, ANN202
    """I_b^-1 v in world axes: R diag(1/I) R^T v."""
    lx, ly, lz = rotate_inverse(q, b, vx, vy, vz)
    inv = model.body_inertia_inv
    return rotate(q, b, lx * inv[b, 0], ly * inv[b, 1], lz * inv[b, 2])


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


# the row flows are calls (a reference-count update per array they take, 200-400 ns per row application):
# inline="always" saved that but, with the turns inlined too, quadrupled split2/split4 compile times
@numba.njit(cache=True)
def _damper_flow(model, spring, row, h, x, q, P, L) -> None:  # noqa: ANN001
    """The exact flow over time h of damper `row` alone (module docstring), x and q held."""
    c = spring.damping[row]
    if c == 0.0:
        return
    a, b = spring.body_a[row], spring.body_b[row]
    ex, ey, ez, rax, ray, raz, rbx, rby, rbz, length = damper_line(spring, row, x, q)
    if length == 0.0:
        return
    # end a: the moment arm n = r x e, the velocity along e and the inverse effective mass
    nax, nay, naz = ray * ez - raz * ey, raz * ex - rax * ez, rax * ey - ray * ex
    gx, gy, gz = _inverse_inertia_times(model, q, a, nax, nay, naz)
    inv_mass_a = 1.0 / model.body_mass[a]
    # e . (v + omega x r) = e . v + omega . (r x e) = e . P / M + (I^-1 n) . L  (I^-1 is symmetric, so
    # the g = I^-1 n of the effective mass also gives the rotational rate: no omega needed)
    rate = inv_mass_a * (ex * P[a, 0] + ey * P[a, 1] + ez * P[a, 2]) + (gx * L[a, 0] + gy * L[a, 1] + gz * L[a, 2])
    weight = inv_mass_a + (nax * gx + nay * gy + naz * gz)
    if b >= 0:
        nbx, nby, nbz = rby * ez - rbz * ey, rbz * ex - rbx * ez, rbx * ey - rby * ex
        hx, hy, hz = _inverse_inertia_times(model, q, b, nbx, nby, nbz)
        inv_mass_b = 1.0 / model.body_mass[b]
        rate -= inv_mass_b * (ex * P[b, 0] + ey * P[b, 1] + ez * P[b, 2]) + (hx * L[b, 0] + hy * L[b, 1] + hz * L[b, 2])
        weight += inv_mass_b + (nbx * hx + nby * hy + nbz * hz)
    # j = s0 (1 - exp(-c w h)) / w, with -expm1 so a small c w h keeps its digits
    j = -rate * math.expm1(-c * weight * h) / weight
    P[a, 0] -= j * ex
    P[a, 1] -= j * ey
    P[a, 2] -= j * ez
    L[a, 0] -= j * nax
    L[a, 1] -= j * nay
    L[a, 2] -= j * naz
    if b >= 0:
        P[b, 0] += j * ex
        P[b, 1] += j * ey
        P[b, 2] += j * ez
        L[b, 0] += j * nbx
        L[b, 1] += j * nby
        L[b, 2] += j * nbz


@numba.njit(cache=True)
def _drag_flow(model, drag, row, h, q, P, L) -> None:  # noqa: ANN001
    """The flow over time h of drag `row` alone (module docstring), q held."""
    b = drag.body[row]
    linear, quadratic = drag.linear[row], drag.quadratic[row]
    if linear != 0.0 or quadratic != 0.0:
        mass = model.body_mass[b]
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
        return
    inv = model.body_inertia_inv
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
def dissipation_flow(model, spring, drag, h, x, q, P, L) -> None:  # noqa: ANN001
    """D(h): the palindrome of every damper's and drag row's flow, each over h/2 forward then backward
    through the rows (symmetric, second order; module docstring). Tables may be None (kernel form)."""
    half = 0.5 * h
    if spring is not None:
        for row in range(spring.damping.shape[0]):
            _damper_flow(model, spring, row, half, x, q, P, L)
    if drag is not None:
        for row in range(drag.body.shape[0]):
            _drag_flow(model, drag, row, half, q, P, L)
        for row in range(drag.body.shape[0] - 1, -1, -1):
            _drag_flow(model, drag, row, half, q, P, L)
    if spring is not None:
        for row in range(spring.damping.shape[0] - 1, -1, -1):
            _damper_flow(model, spring, row, half, x, q, P, L)


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
