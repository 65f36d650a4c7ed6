"""The kinematic bodies' table (read-only, the model's `kinematic`): one row per kinematic body, its
prescribed motion. The closed form and the stages that set it: physics/kinematic.py.

This module imports numpy only, so scene/compile.py builds the table cheaply.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rbcli.physics.table_arrays import frozen_floats, frozen_ints


class KinematicTable(NamedTuple):
    """The prescribed motions of a scene's kinematic bodies, one row each."""

    body: np.ndarray  # int64 (row_count,)
    # int64 (row_count,): NO_SCHEDULE (s = 1) or a row of the force terms' ScheduleTable (ForceTables.schedule,
    # which holds the time profiles of forces and motions alike: forces/tables.py)
    schedule: np.ndarray
    velocity: np.ndarray  # v0 [m/s] (row_count, 3), world
    angular_velocity: np.ndarray  # w0 [rad/s] (row_count, 3), world
    pivot: np.ndarray  # p0 [m] (row_count, 3), world, at t = 0
    position: np.ndarray  # x0 [m] (row_count, 3), world, centre of mass at t = 0
    orientation: np.ndarray  # q0 (row_count, 4) wxyz, world-from-principal at t = 0


def kinematic_table(
    body=(),  # noqa: ANN001
    schedule=(),  # noqa: ANN001
    velocity=(),  # noqa: ANN001
    angular_velocity=(),  # noqa: ANN001
    pivot=(),  # noqa: ANN001
    position=(),  # noqa: ANN001
    orientation=(),  # noqa: ANN001
) -> KinematicTable:
    """A KinematicTable with consistent dtypes (empty: a scene without kinematic bodies)."""

    return KinematicTable(
        frozen_ints(body),
        frozen_ints(schedule),
        frozen_floats(velocity, 3),
        frozen_floats(angular_velocity, 3),
        frozen_floats(pivot, 3),
        frozen_floats(position, 3),
        frozen_floats(orientation, 4),
    )
