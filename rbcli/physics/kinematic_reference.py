"""Plain numpy reference of the kinematic bodies' closed-form motion (physics/kinematic.py has the formulas
and the compiled stages). Numpy only: scene/compile_contact.py sets the initial state with it, and
`rbsim validate` must not import numba.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.kinematic_table import KinematicTable
from rbcli.physics.rotation import quat_multiply, quat_rotate


def kinematic_state_numpy(
    table: KinematicTable,
    schedule_integral_value: np.ndarray,
    schedule_rate: np.ndarray,
    mass: np.ndarray,
    inertia: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Plain numpy reference of the closed form for every row, given S(t) and s(t) per row and each row's
    mass and isotropic moment [kg m^2]: (x, q, P, L), each (row_count, k)."""
    w = table.angular_velocity
    speed = np.linalg.norm(w, axis=1)
    angle = speed * schedule_integral_value
    axis = np.divide(w, speed[:, None], out=np.zeros_like(w), where=speed[:, None] > 0)
    dq = np.concatenate([np.cos(0.5 * angle)[:, None], np.sin(0.5 * angle)[:, None] * axis], axis=1)
    arm = np.array([quat_rotate(d, a) for d, a in zip(dq, table.position - table.pivot, strict=True)]).reshape(-1, 3)
    x = table.pivot + table.velocity * schedule_integral_value[:, None] + arm
    q = np.array([quat_multiply(d, q0) for d, q0 in zip(dq, table.orientation, strict=True)]).reshape(-1, 4)
    P = mass[:, None] * schedule_rate[:, None] * (table.velocity + np.cross(w, arm))
    L = inertia[:, None] * schedule_rate[:, None] * w
    return x, q, P, L
