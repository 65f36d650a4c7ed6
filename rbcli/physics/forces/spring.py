"""Springs-dampers from a body point to a world anchor or to another body's point.

With d = p_a - p_b, l = |d|, e = d / l and dl/dt = e . (v_a - v_b) (v the world velocity of the
attachment point, v + omega x r): f = -(k (l - l0) + c dl/dt) e acts on end a at p_a and -f on end b
at p_b, so the pair exerts no net force or moment on the system (Newton's third law, exactly, since
both ends use the same f). Potential V = k (l - l0)^2 / 2 (the damper has none). At l = 0 the line
of action is undefined: f = 0 there (a zero-rest-length spring has -k d = 0 there anyway).
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.forces.body_point import add_force_at, point_velocity, rotate
from rbcli.physics.forces.tables import SpringTable
from rbcli.physics.frames import body_angular_velocity
from rbcli.physics.rotation import quat_to_matrix

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True)
def accumulate_spring(model, spring, x, q, P, L, F, tau, dissipative=True) -> int:  # noqa: ANN001 - numba types
    """Add every spring's force and moments to both ends; returns the rows evaluated. dissipative=False
    leaves the dampers out (the splitting integrators integrate them as their own flow, damping.py)."""
    for row in range(spring.body_a.shape[0]):
        a = spring.body_a[row]
        pa = spring.point_a[row]
        rax, ray, raz = rotate(q, a, pa[0], pa[1], pa[2])
        vax, vay, vaz = point_velocity(model, q, P, L, a, rax, ray, raz)
        dx, dy, dz = x[a, 0] + rax, x[a, 1] + ray, x[a, 2] + raz
        b = spring.body_b[row]
        pb = spring.point_b[row]
        if b >= 0:
            rbx, rby, rbz = rotate(q, b, pb[0], pb[1], pb[2])
            vbx, vby, vbz = point_velocity(model, q, P, L, b, rbx, rby, rbz)
            dx -= x[b, 0] + rbx
            dy -= x[b, 1] + rby
            dz -= x[b, 2] + rbz
            vax -= vbx
            vay -= vby
            vaz -= vbz
        else:  # world anchor: fixed, at rest
            rbx, rby, rbz = 0.0, 0.0, 0.0
            dx -= pb[0]
            dy -= pb[1]
            dz -= pb[2]
        length = np.sqrt(dx * dx + dy * dy + dz * dz)
        if length == 0.0:
            continue
        ex, ey, ez = dx / length, dy / length, dz / length
        rate = ex * vax + ey * vay + ez * vaz
        damping = spring.damping[row] if dissipative else 0.0
        magnitude = -(spring.stiffness[row] * (length - spring.rest_length[row]) + damping * rate)
        fx, fy, fz = magnitude * ex, magnitude * ey, magnitude * ez
        add_force_at(F, tau, a, rax, ray, raz, fx, fy, fz)
        if b >= 0:
            add_force_at(F, tau, b, rbx, rby, rbz, -fx, -fy, -fz)
    return spring.body_a.shape[0]


def spring_ends(model, spring: SpringTable, x, q, P=None, L=None):  # noqa: ANN001, ANN202
    """World offsets r, positions p and (when P, L given) velocities v of both ends, leading axes kept."""
    other = spring.body_b >= 0
    b = np.where(other, spring.body_b, 0)
    ra = np.einsum("...rij,rj->...ri", quat_to_matrix(q[..., spring.body_a, :]), spring.point_a)
    rb = np.where(other[:, None], np.einsum("...rij,rj->...ri", quat_to_matrix(q[..., b, :]), spring.point_b), 0.0)
    pa = x[..., spring.body_a, :] + ra
    pb = np.where(other[:, None], x[..., b, :] + rb, spring.point_b)
    if P is None:
        return ra, rb, pa, pb, None, None
    omega = body_angular_velocity(model, q, L)
    v = P / model.body_mass[:, None]
    va = v[..., spring.body_a, :] + np.cross(omega[..., spring.body_a, :], ra)
    vb = np.where(other[:, None], v[..., b, :] + np.cross(omega[..., b, :], rb), 0.0)
    return ra, rb, pa, pb, va, vb


def spring_numpy(model, spring: SpringTable, x, q, P, L) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """Plain numpy reference of `accumulate_spring`: (F, tau), each (body_count, 3)."""
    F, tau = np.zeros_like(x), np.zeros_like(x)
    ra, rb, pa, pb, va, vb = spring_ends(model, spring, x, q, P, L)
    d = pa - pb
    length = np.linalg.norm(d, axis=-1)
    e = np.divide(d, length[:, None], out=np.zeros_like(d), where=length[:, None] > 0)
    rate = np.einsum("ri,ri->r", e, va - vb)
    f = -(spring.stiffness * (length - spring.rest_length) + spring.damping * rate)[:, None] * e
    other = spring.body_b >= 0
    np.add.at(F, spring.body_a, f)
    np.add.at(tau, spring.body_a, np.cross(ra, f))
    np.add.at(F, spring.body_b[other], -f[other])
    np.add.at(tau, spring.body_b[other], -np.cross(rb[other], f[other]))
    return F, tau


def spring_potential(spring: SpringTable, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """V = sum k (l - l0)^2 / 2 [J]; x (..., body_count, 3) -> (...)."""
    _, _, pa, pb, _, _ = spring_ends(None, spring, x, q)
    stretch = np.linalg.norm(pa - pb, axis=-1) - spring.rest_length
    return 0.5 * np.einsum("r,...r->...", spring.stiffness, stretch**2)
