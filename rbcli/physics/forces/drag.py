"""Drag at the centre of mass, linear and quadratic: F = -(b + c |v|) v, tau = -(b_r + c_r |omega|) omega.

v = P / M and omega = R diag(1/I) R^T L, both world. Dissipative: dE/dt = F . v + tau . omega <= 0.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.forces.body_point import angular_velocity
from rbcli.physics.forces.tables import DragTable
from rbcli.physics.frames import body_angular_velocity

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True)
def accumulate_drag(model, drag, q, P, L, F, tau) -> int:  # noqa: ANN001 - numba types
    """Add every row's drag force and torque; returns the rows evaluated."""
    for row in range(drag.body.shape[0]):
        b = drag.body[row]
        linear, quadratic = drag.linear[row], drag.quadratic[row]
        if linear != 0.0 or quadratic != 0.0:
            inv_mass = 1.0 / model.body_mass[b]
            vx, vy, vz = P[b, 0] * inv_mass, P[b, 1] * inv_mass, P[b, 2] * inv_mass
            coefficient = linear + quadratic * np.sqrt(vx * vx + vy * vy + vz * vz)
            F[b, 0] -= coefficient * vx
            F[b, 1] -= coefficient * vy
            F[b, 2] -= coefficient * vz
        angular_linear, angular_quadratic = drag.angular_linear[row], drag.angular_quadratic[row]
        if angular_linear != 0.0 or angular_quadratic != 0.0:
            wx, wy, wz = angular_velocity(model, q, L, b)
            coefficient = angular_linear + angular_quadratic * np.sqrt(wx * wx + wy * wy + wz * wz)
            tau[b, 0] -= coefficient * wx
            tau[b, 1] -= coefficient * wy
            tau[b, 2] -= coefficient * wz
    return drag.body.shape[0]


def drag_numpy(model, drag: DragTable, x, q, P, L) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """Plain numpy reference of `accumulate_drag`: (F, tau), each (body_count, 3)."""
    F, tau = np.zeros_like(x), np.zeros_like(x)
    v = (P / model.body_mass[:, None])[drag.body]
    omega = body_angular_velocity(model, q, L)[drag.body]
    speed, spin = np.linalg.norm(v, axis=-1), np.linalg.norm(omega, axis=-1)
    np.add.at(F, drag.body, -(drag.linear + drag.quadratic * speed)[:, None] * v)
    np.add.at(tau, drag.body, -(drag.angular_linear + drag.angular_quadratic * spin)[:, None] * omega)
    return F, tau
