"""Schedules: time profiles s(t) [1] that scale a force, torque or field row (see ScheduleTable).

s(t) = 0 outside start <= t < stop; inside: constant `offset`; piecewise-linear through knots (held
at the end values outside them; right-continuous, so a repeated knot time is a step whose later value
holds from that time on); or offset + amplitude sin(2 pi frequency t + phase).
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics.forces.tables import (
    NO_SCHEDULE,
    SCHEDULE_CONSTANT,
    SCHEDULE_PIECEWISE_LINEAR,
    SCHEDULE_SINE,
    ScheduleTable,
)


@numba.njit(cache=True)
def schedule_value(schedule, index: int, t: float) -> float:  # noqa: ANN001 - numba types
    """s(t) of schedule row `index`; 1 for NO_SCHEDULE."""
    if index == NO_SCHEDULE:
        return 1.0
    if t < schedule.start[index] or t >= schedule.stop[index]:
        return 0.0
    kind = schedule.kind[index]
    if kind == SCHEDULE_CONSTANT:
        return schedule.offset[index]
    if kind == SCHEDULE_SINE:
        phase = 2.0 * np.pi * schedule.frequency[index] * t + schedule.phase[index]
        return schedule.offset[index] + schedule.amplitude[index] * np.sin(phase)
    # piecewise linear, right-continuous: find k with times[k] <= t < times[k+1] by a linear scan
    # (schedules have a handful of knots); a repeated time is a step, its later value holds from then on
    k0 = schedule.knot_start[index]
    k1 = k0 + schedule.knot_count[index] - 1
    times, values = schedule.knot_time, schedule.knot_value
    if t < times[k0]:
        return values[k0]
    if t >= times[k1]:
        return values[k1]
    k = k0
    while times[k + 1] <= t:
        k += 1
    span = times[k + 1] - times[k]  # > 0, since times[k] <= t < times[k + 1]
    return values[k] + (values[k + 1] - values[k]) * ((t - times[k]) / span)


def schedule_values_numpy(schedule: ScheduleTable, index: np.ndarray, t: float) -> np.ndarray:
    """Plain numpy reference of `schedule_value` for an array of row indices (NO_SCHEDULE -> 1)."""
    index = np.asarray(index, dtype=np.int64)
    out = np.ones(index.shape)
    for n, j in enumerate(index.tolist()):  # tests only: one schedule at a time is clearest
        if j == NO_SCHEDULE:
            continue
        if not (schedule.start[j] <= t < schedule.stop[j]):
            out[n] = 0.0
        elif schedule.kind[j] == SCHEDULE_CONSTANT:
            out[n] = schedule.offset[j]
        elif schedule.kind[j] == SCHEDULE_SINE:
            out[n] = schedule.offset[j] + schedule.amplitude[j] * np.sin(
                2 * np.pi * schedule.frequency[j] * t + schedule.phase[j]
            )
        elif schedule.kind[j] == SCHEDULE_PIECEWISE_LINEAR:
            knots = slice(schedule.knot_start[j], schedule.knot_start[j] + schedule.knot_count[j])
            times, values = schedule.knot_time[knots], schedule.knot_value[knots]
            k = int(np.searchsorted(times, t, side="right")) - 1  # times[k] <= t < times[k + 1]
            if k < 0 or k == len(times) - 1:
                out[n] = values[max(k, 0)]
            else:
                out[n] = values[k] + (values[k + 1] - values[k]) * (t - times[k]) / (times[k + 1] - times[k])
    return out
