"""Plain numpy reference of the contact force stage, by brute force over all pairs (tests).

It evaluates every contact as a fresh one (no history: xi = 0) at the start of a step (s = 0), which is
what the compiled stage computes on an empty history with its clock at t; comparing the two checks the
broad phase (a pair it missed or counted twice changes the sums) and the force law together.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.contact.tables import PLANE_PARTNER_BASE, ContactTable
from rbcli.physics.rotation import quat_multiply, quat_rotate, quat_rotate_inverse


def _excluded(contact: ContactTable, a: int, b: int) -> bool:
    """Whether bodies a and b never collide (a joint's two bodies), by a plain scan of the pair keys."""
    n = contact.body_inv_contact_mass.shape[0]
    return any(int(k) == min(a, b) * n + max(a, b) for k in contact.excluded_pair)


def sphere_positions_numpy(contact: ContactTable, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """World centres of the contact spheres, (sphere_count, 3)."""
    b = contact.sphere_body
    return x[b] + quat_rotate(q[b], contact.sphere_offset)


def contact_wrench_numpy(model, contact: ContactTable, x, q, P, L) -> tuple[np.ndarray, np.ndarray, int]:  # noqa: ANN001
    """(F, tau, contacts) of every sphere-sphere and sphere-plane overlap, fresh contacts, O(n^2)."""
    F, tau, count, _ = contact_wrench_history_numpy(model, contact, x, q, P, L, {}, 0.0)
    return F, tau, count


def contact_wrench_history_numpy(
    model, contact: ContactTable, x, q, P, L, history: dict, s: float,  # noqa: ANN001
) -> tuple[np.ndarray, np.ndarray, int, dict]:  # fmt: skip
    """(F, tau, contacts, proposals) of every overlap at offset s into a step, O(n^2), given the
    history {(owner, partner): xi [m]} of the step's start (owner: the lower sphere index, or the sphere
    of a plane contact; partner: the other sphere, or PLANE_PARTNER_BASE - plane). proposals maps each
    contact with friction to (u, n, c, limit): the spring's elongation at the evaluation, the normal, the
    contact point and the Coulomb limit mu f_n / k_t of |xi| (force.py's module docstring)."""
    F, tau = np.zeros_like(x), np.zeros_like(x)
    v = P / model.body_mass[:, None]
    omega = quat_rotate(q, quat_rotate_inverse(q, L) / model.body_inertia)
    pos = sphere_positions_numpy(contact, x, q)
    r = contact.sphere_radius
    body = contact.sphere_body
    count = 0
    proposals: dict = {}

    def velocity(b: int, c: np.ndarray) -> np.ndarray:
        return v[b] + np.cross(omega[b], c - x[b])

    def apply(key: tuple[int, int], a: int, b: int, n: np.ndarray, overlap: float, c: np.ndarray, k: float,
              zeta: float, mu: float) -> None:  # fmt: skip
        inv_b = contact.body_inv_contact_mass[b] if b >= 0 else 0.0
        m_eff = 1.0 / (contact.body_inv_contact_mass[a] + inv_b)
        rel = velocity(a, c) - (velocity(b, c) if b >= 0 else 0.0)
        vn = rel @ n
        vt = rel - vn * n
        fn = max(0.0, k * overlap - 2.0 * zeta * np.sqrt(k * m_eff) * vn)
        f = fn * n
        if mu > 0.0:
            kt = contact.tangential_ratio * k
            xi = np.array(history.get(key, np.zeros(3)), dtype=np.float64)
            along = xi @ n
            if along * along > 1e-12 * (xi @ xi):  # turned into the tangent plane, its length kept
                kept = xi - along * n
                xi = kept * np.sqrt((xi @ xi) / (kept @ kept))
            u = xi + s * vt
            ft = -kt * u - 2.0 * zeta * np.sqrt(kt * m_eff) * vt
            norm = np.linalg.norm(ft)
            if norm > mu * fn:  # sliding: at the Coulomb limit, the spring stretched to match
                ft *= mu * fn / norm
                u = -(ft + 2.0 * zeta * np.sqrt(kt * m_eff) * vt) / kt
            proposals[key] = (u, n, c, mu * fn / kt)
            f = f + ft
        for body_index, sign in ((a, 1.0), (b, -1.0)):
            if body_index >= 0:
                F[body_index] += sign * f
                tau[body_index] += np.cross(c - x[body_index], sign * f)

    for i in range(len(r)):
        a = body[i]
        if contact.body_inv_contact_mass[a] == 0.0:
            continue
        for p in range(contact.plane_point.shape[0]):
            n = contact.plane_normal[p]
            overlap = r[i] - (pos[i] - contact.plane_point[p]) @ n
            if overlap > 0.0:
                count += 1
                zeta = min(contact.body_damping_ratio[a], contact.plane_damping_ratio[p])
                mu = np.sqrt(contact.body_friction[a] * contact.plane_friction[p])
                c = pos[i] - (r[i] - 0.5 * overlap) * n
                apply((i, PLANE_PARTNER_BASE - p), a, -1, n, overlap, c, contact.body_plane_stiffness[a], zeta, mu)
    for i in range(len(r)):
        for j in range(i + 1, len(r)):
            a, b = body[i], body[j]
            if a == b or (contact.body_inv_contact_mass[a] == 0.0 and contact.body_inv_contact_mass[b] == 0.0):
                continue
            if _excluded(contact, a, b):
                continue
            d = pos[i] - pos[j]
            dist = float(np.linalg.norm(d))
            overlap = r[i] + r[j] - dist
            if overlap <= 0.0 or dist == 0.0:
                continue
            count += 1
            n = d / dist
            c = pos[j] + (r[j] - 0.5 * overlap) * n
            ka, kb = contact.body_stiffness[a], contact.body_stiffness[b]
            zeta = min(contact.body_damping_ratio[a], contact.body_damping_ratio[b])
            mu = np.sqrt(contact.body_friction[a] * contact.body_friction[b])
            apply((i, j), a, b, n, overlap, c, 2.0 * ka * kb / (ka + kb), zeta, mu)
    for b in contact.static_body:
        F[b] = 0.0
        tau[b] = 0.0
    return F, tau, count, proposals


def contact_energy_numpy(contact: ContactTable, x: np.ndarray, q: np.ndarray, history: dict | None = None) -> float:
    """V_c [J] of one state, O(n^2): 1/2 k d^2 per overlap (k mixed as the force stage mixes it) plus
    1/2 k_t |xi|^2 per contact with friction whose elongation xi [m] `history` holds (keys as in
    `contact_wrench_history_numpy`)."""
    history = history or {}
    pos = sphere_positions_numpy(contact, x, q)
    r, body, inv = contact.sphere_radius, contact.sphere_body, contact.body_inv_contact_mass
    energy = 0.0

    def add(key: tuple[int, int], k: float, overlap: float, mu: float) -> float:
        xi = np.asarray(history.get(key, np.zeros(3))) if mu > 0.0 else np.zeros(3)
        return 0.5 * k * overlap**2 + 0.5 * contact.tangential_ratio * k * float(xi @ xi)

    for i in range(len(r)):
        if inv[body[i]] == 0.0:
            continue
        for p in range(contact.plane_point.shape[0]):
            overlap = r[i] - (pos[i] - contact.plane_point[p]) @ contact.plane_normal[p]
            if overlap > 0.0:
                mu = np.sqrt(contact.body_friction[body[i]] * contact.plane_friction[p])
                energy += add((i, PLANE_PARTNER_BASE - p), contact.body_plane_stiffness[body[i]], overlap, mu)
    for i in range(len(r)):
        for j in range(i + 1, len(r)):
            a, b = body[i], body[j]
            if a == b or (inv[a] == 0.0 and inv[b] == 0.0) or _excluded(contact, a, b):
                continue
            dist = float(np.linalg.norm(pos[i] - pos[j]))
            overlap = r[i] + r[j] - dist
            if overlap > 0.0 and dist > 0.0:
                ka, kb = contact.body_stiffness[a], contact.body_stiffness[b]
                mu = np.sqrt(contact.body_friction[a] * contact.body_friction[b])
                energy += add((i, j), 2.0 * ka * kb / (ka + kb), overlap, mu)
    return energy


def contact_step_numpy(
    model, contact: ContactTable, x, q, P, L, history: dict, h: float, force: np.ndarray,  # noqa: ANN001
) -> dict:  # fmt: skip
    """One semi-implicit Euler step of length h (integrators/semi_implicit.py) in place, with the contact
    wrench of `contact_wrench_history_numpy` plus a constant `force` [N] (body_count, 3) (gravity), and
    the history committed as force.commit_contacts does: each contact with friction found at the start
    of the step (s = 0) keeps xi = u + h v_t, v_t at its contact point with the end-of-step velocities,
    cut back to its Coulomb limit; returns the new history (contacts not found are forgotten)."""
    F, tau, _, proposals = contact_wrench_history_numpy(model, contact, x, q, P, L, history, 0.0)
    P += h * (F + force)
    x += h * P / model.body_mass[:, None]
    L += h * tau
    omega = quat_rotate(q, quat_rotate_inverse(q, L) / model.body_inertia)
    half = 0.5 * h * omega  # q <- exp((0, h omega / 2)) q
    angle = np.linalg.norm(half, axis=1)
    sinc = np.where(angle > 0.0, np.sin(angle) / np.where(angle > 0.0, angle, 1.0), 1.0)
    turn = np.concatenate([np.cos(angle)[:, None], sinc[:, None] * half], axis=1)
    q[:] = quat_multiply(turn, q)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    v = P / model.body_mass[:, None]
    body = contact.sphere_body
    committed = {}
    for (owner, partner), (u, n, c, limit) in proposals.items():
        a = body[owner]
        rel = v[a] + np.cross(omega[a], c - x[a])
        if partner >= 0:
            b = body[partner]
            rel = rel - (v[b] + np.cross(omega[b], c - x[b]))
        xi = u + h * (rel - (rel @ n) * n)
        length = np.linalg.norm(xi)
        committed[(owner, partner)] = xi * (limit / length) if length > limit else xi
    return committed
