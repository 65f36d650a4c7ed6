"""Pure torques (couples): tau += s(t) tau0, a world vector or one turning with the body (R tau0).

No force, so no change of P; not conservative in general (the rotation vector is not a coordinate).
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.forces.body_point import rotate
from rbcli.physics.forces.schedule import schedule_value, schedule_values_numpy
from rbcli.physics.forces.tables import ScheduleTable, TorqueTable
from rbcli.physics.rotation import quat_to_matrix

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True)
def accumulate_torque(torque, schedule, t, q, tau) -> int:  # noqa: ANN001 - numba types
    """Add every row's torque to tau (world); returns the rows evaluated."""
    evaluated = 0
    for row in range(torque.body.shape[0]):
        s = schedule_value(schedule, torque.schedule[row], t)
        if s == 0.0:
            continue
        b = torque.body[row]
        cx, cy, cz = torque.vector[row, 0], torque.vector[row, 1], torque.vector[row, 2]
        if torque.body_frame[row]:
            cx, cy, cz = rotate(q, b, cx, cy, cz)
        tau[b, 0] += s * cx
        tau[b, 1] += s * cy
        tau[b, 2] += s * cz
        evaluated += 1
    return evaluated


def torque_numpy(torque: TorqueTable, schedule: ScheduleTable, t: float, x, q) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """Plain numpy reference of `accumulate_torque`: (F = 0, tau), each (body_count, 3)."""
    tau = np.zeros_like(x)
    R = quat_to_matrix(q[torque.body])
    c = np.where(torque.body_frame[:, None], np.einsum("rij,rj->ri", R, torque.vector), torque.vector)
    np.add.at(tau, torque.body, schedule_values_numpy(schedule, torque.schedule, t)[:, None] * c)
    return np.zeros_like(x), tau
