"""Forces at body-fixed points: F += s(t) f, tau += r x s(t) f, with r = R r0 the point's world offset.

f is a world vector, or a body-frame vector turning with the body (f = R f0, a "follower" force such
as a thruster). An unscheduled world-frame force is conservative: V = -f . (x + R r0).
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.forces.body_point import add_force_at, rotate
from rbcli.physics.forces.schedule import schedule_value, schedule_values_numpy
from rbcli.physics.forces.tables import NO_SCHEDULE, PointForceTable, ScheduleTable
from rbcli.physics.rotation import quat_to_matrix

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True)
def accumulate_point_force(point_force, schedule, t, q, F, tau) -> int:  # noqa: ANN001 - numba types
    """Add every row's force and its moment about the centre of mass; returns the rows evaluated."""
    evaluated = 0
    for row in range(point_force.body.shape[0]):
        s = schedule_value(schedule, point_force.schedule[row], t)
        if s == 0.0:
            continue
        b = point_force.body[row]
        fx, fy, fz = point_force.vector[row, 0], point_force.vector[row, 1], point_force.vector[row, 2]
        if point_force.body_frame[row]:
            fx, fy, fz = rotate(q, b, fx, fy, fz)
        p = point_force.point[row]
        rx, ry, rz = rotate(q, b, p[0], p[1], p[2])
        add_force_at(F, tau, b, rx, ry, rz, s * fx, s * fy, s * fz)
        evaluated += 1
    return evaluated


def _world(table_vector: np.ndarray, body_frame: np.ndarray, R: np.ndarray) -> np.ndarray:
    """World vectors of rows: R v where the row's vector turns with its body, v otherwise."""
    return np.where(body_frame[:, None], np.einsum("rij,rj->ri", R, table_vector), table_vector)


def point_force_numpy(
    point_force: PointForceTable, schedule: ScheduleTable, t: float, x, q
) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """Plain numpy reference of `accumulate_point_force`: (F, tau), each (body_count, 3)."""
    F, tau = np.zeros_like(x), np.zeros_like(x)
    R = quat_to_matrix(q[point_force.body])
    f = schedule_values_numpy(schedule, point_force.schedule, t)[:, None] * _world(
        point_force.vector, point_force.body_frame, R
    )
    r = np.einsum("rij,rj->ri", R, point_force.point)
    np.add.at(F, point_force.body, f)
    np.add.at(tau, point_force.body, np.cross(r, f))
    return F, tau


def point_force_is_conservative(point_force: PointForceTable) -> np.ndarray:
    """Rows with a potential: unscheduled and fixed in the world frame, (row_count,) bool."""
    return (point_force.schedule == NO_SCHEDULE) & ~point_force.body_frame


def point_force_potential(point_force: PointForceTable, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """V = -f . (x + R r0) [J] summed over unscheduled world-frame rows; x (..., body_count, 3) -> (...)."""
    keep = point_force_is_conservative(point_force)
    body, f = point_force.body[keep], point_force.vector[keep]
    pos = x[..., body, :] + np.einsum("...rij,rj->...ri", quat_to_matrix(q[..., body, :]), point_force.point[keep])
    return -np.einsum("ri,...ri->...", f, pos)
