"""Per-particle force fields: a(x) = value + gradient x evaluated at each particle's world position.

per mass:     F_i = s(t) m_i a(x_i)   (e.g. a non-uniform gravity or a tidal field)
per particle: F_i = s(t) a(x_i)       (e.g. the same force on every particle of a body)
F_b = sum_i F_i, tau_b = sum_i r_i x F_i with r_i = R r0_i, x_i = x_b + r_i (the tutorial's particle
update, done here only for the bodies a field row touches). Potential, for a symmetric gradient G
(a = -grad phi with phi(x) = -(value . x + x.G x / 2)) and no schedule: V = sum_i w_i phi(x_i),
w_i = m_i or 1. A non-symmetric gradient has a curl and no potential.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.forces.schedule import schedule_value, schedule_values_numpy
from rbcli.physics.forces.tables import NO_SCHEDULE, FieldTable, ScheduleTable
from rbcli.physics.rotation import quat_to_matrix

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources

# A gradient counts as symmetric (conservative) when |G - G^T| <= this times |G|: round-off of a
# symmetric matrix typed in by hand is exact, so anything above ~1e-15 relative is a real curl.
SYMMETRY_TOLERANCE = 1e-12


@numba.njit(cache=True)
def accumulate_field(model, field, schedule, t, x, q, F, tau) -> int:  # noqa: ANN001 - numba types
    """Add every field row's force and torque to F, tau (world); returns the particles evaluated."""
    evaluated = 0
    for row in range(field.body.shape[0]):
        s = schedule_value(schedule, field.schedule[row], t)
        if s == 0.0:
            continue
        b = field.body[row]
        # R(q_b) once per row as nine scalars (no allocation); unit quaternion (w, x, y, z)
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        r00, r01, r02 = 1.0 - 2.0 * (qy * qy + qz * qz), 2.0 * (qx * qy - w * qz), 2.0 * (qx * qz + w * qy)
        r10, r11, r12 = 2.0 * (qx * qy + w * qz), 1.0 - 2.0 * (qx * qx + qz * qz), 2.0 * (qy * qz - w * qx)
        r20, r21, r22 = 2.0 * (qx * qz - w * qy), 2.0 * (qy * qz + w * qx), 1.0 - 2.0 * (qx * qx + qy * qy)
        a0, G = field.value[row], field.gradient[row]
        per_mass = field.per_mass[row]
        fx_sum, fy_sum, fz_sum, tx_sum, ty_sum, tz_sum = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
        start = model.body_particle_start[b]
        for i in range(start, start + model.body_particle_count[b]):
            o = model.particle_offset[i]
            rx = r00 * o[0] + r01 * o[1] + r02 * o[2]
            ry = r10 * o[0] + r11 * o[1] + r12 * o[2]
            rz = r20 * o[0] + r21 * o[1] + r22 * o[2]
            px, py, pz = x[b, 0] + rx, x[b, 1] + ry, x[b, 2] + rz
            weight = s * model.particle_mass[i] if per_mass else s
            fx = weight * (a0[0] + G[0, 0] * px + G[0, 1] * py + G[0, 2] * pz)
            fy = weight * (a0[1] + G[1, 0] * px + G[1, 1] * py + G[1, 2] * pz)
            fz = weight * (a0[2] + G[2, 0] * px + G[2, 1] * py + G[2, 2] * pz)
            fx_sum += fx
            fy_sum += fy
            fz_sum += fz
            tx_sum += ry * fz - rz * fy
            ty_sum += rz * fx - rx * fz
            tz_sum += rx * fy - ry * fx
        F[b, 0] += fx_sum
        F[b, 1] += fy_sum
        F[b, 2] += fz_sum
        tau[b, 0] += tx_sum
        tau[b, 1] += ty_sum
        tau[b, 2] += tz_sum
        evaluated += model.body_particle_count[b]
    return evaluated


def _rows_particles(model, field: FieldTable) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """(row of each evaluated particle, particle index), vectorised over rows."""
    counts = model.body_particle_count[field.body]
    row_of = np.repeat(np.arange(field.body.shape[0]), counts)
    first = np.repeat(model.body_particle_start[field.body] - np.concatenate([[0], np.cumsum(counts)[:-1]]), counts)
    return row_of, first + np.arange(row_of.shape[0])


def field_numpy(model, field: FieldTable, schedule: ScheduleTable, t: float, x, q) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """Plain numpy reference of `accumulate_field`: (F, tau), each (body_count, 3)."""
    F, tau = np.zeros_like(x), np.zeros_like(x)
    row_of, particle = _rows_particles(model, field)
    body = field.body[row_of]
    r = np.einsum("pij,pj->pi", quat_to_matrix(q[body]), model.particle_offset[particle])
    pos = x[body] + r
    a = field.value[row_of] + np.einsum("pij,pj->pi", field.gradient[row_of], pos)
    weight = np.where(field.per_mass[row_of], model.particle_mass[particle], 1.0)
    f = (schedule_values_numpy(schedule, field.schedule, t)[row_of] * weight)[:, None] * a
    np.add.at(F, body, f)
    np.add.at(tau, body, np.cross(r, f))
    return F, tau


def field_is_conservative(field: FieldTable) -> np.ndarray:
    """Rows with a potential: unscheduled and a symmetric gradient, (row_count,) bool."""
    G = field.gradient
    asym = np.abs(G - np.swapaxes(G, -1, -2)).max(axis=(-2, -1), initial=0.0)
    scale = np.abs(G).max(axis=(-2, -1), initial=0.0)
    return (field.schedule == NO_SCHEDULE) & (asym <= SYMMETRY_TOLERANCE * scale)


def field_potential(model, field: FieldTable, x: np.ndarray, q: np.ndarray) -> np.ndarray:  # noqa: ANN001
    """V = sum_i w_i phi(x_i) [J] over the conservative rows; x (..., body_count, 3) -> (...)."""
    keep = field_is_conservative(field)
    V = np.zeros(x.shape[:-2])
    if not keep.any():
        return V
    row_of, particle = _rows_particles(model, field)
    mask = keep[row_of]
    row_of, particle = row_of[mask], particle[mask]
    body = field.body[row_of]
    r = np.einsum("...pij,pj->...pi", quat_to_matrix(q[..., body, :]), model.particle_offset[particle])
    pos = x[..., body, :] + r
    phi = -(np.einsum("pi,...pi->...p", field.value[row_of], pos)
            + 0.5 * np.einsum("...pi,pij,...pj->...p", pos, field.gradient[row_of], pos))  # fmt: skip
    weight = np.where(field.per_mass[row_of], model.particle_mass[particle], 1.0)
    return V + (weight * phi).sum(axis=-1)
