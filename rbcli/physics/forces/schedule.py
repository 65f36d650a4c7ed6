"""Schedules: time profiles s(t) [1] that scale a force, torque or field row (see ScheduleTable).

s(t) = 0 outside start <= t < stop; inside: constant `offset`; piecewise-linear through knots (held
at the end values outside them; right-continuous, so a repeated knot time is a step whose later value
holds from that time on); or offset + amplitude sin(2 pi frequency t + phase). Its integral from 0,
`schedule_integral`, moves kinematic bodies on a schedule (physics/kinematic.py) in closed form.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.forces.tables import (
    NO_SCHEDULE,
    SCHEDULE_CONSTANT,
    SCHEDULE_SINE,
    schedule_values_numpy,
)

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources

__all__ = ["SCHEDULE_STEP_FLOOR", "schedule_integral", "schedule_value", "schedule_values_numpy"]

# A window edge (s jumps at start or stop) is a jump of the force: adaptive stepping judges a step
# shorter than SCHEDULE_STEP_FLOOR dt by its error per step (physics/adaptive.py). Steps of smooth
# motion at useful tolerances are far longer, so only the steps closing in on an edge are affected.
SCHEDULE_STEP_FLOOR = 0.01


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


@numba.njit(cache=True)
def _profile_antiderivative(schedule, index: int, t: float) -> float:  # noqa: ANN001
    """G(t), an antiderivative of the in-window profile of row `index` (the window is not applied):
    constant: offset t; sine: offset t - amplitude cos(2 pi f t + phase) / (2 pi f) (f = 0: the
    constant offset + amplitude sin(phase)); piecewise linear: the area from the first knot (held
    values outside the knots, trapezoids between them; a repeated knot time adds nothing)."""
    kind = schedule.kind[index]
    if kind == SCHEDULE_CONSTANT:
        return schedule.offset[index] * t
    if kind == SCHEDULE_SINE:
        f = schedule.frequency[index]
        if f == 0.0:
            return (schedule.offset[index] + schedule.amplitude[index] * np.sin(schedule.phase[index])) * t
        w = 2.0 * np.pi * f
        return schedule.offset[index] * t - schedule.amplitude[index] * np.cos(w * t + schedule.phase[index]) / w
    k0 = schedule.knot_start[index]
    k1 = k0 + schedule.knot_count[index] - 1
    times, values = schedule.knot_time, schedule.knot_value
    if t <= times[k0]:
        return values[k0] * (t - times[k0])
    area = 0.0
    k = k0
    while k < k1 and times[k + 1] <= t:
        area += 0.5 * (values[k] + values[k + 1]) * (times[k + 1] - times[k])
        k += 1
    if k == k1:
        return area + values[k1] * (t - times[k1])
    value_t = values[k] + (values[k + 1] - values[k]) * ((t - times[k]) / (times[k + 1] - times[k]))
    return area + 0.5 * (values[k] + value_t) * (t - times[k])


@numba.njit(cache=True)
def schedule_integral(schedule, index: int, t: float) -> float:  # noqa: ANN001 - numba types
    """S(t) = integral of s over [0, t] for schedule row `index` (t for NO_SCHEDULE), in closed form:
    the profile's antiderivative between the window's ends clipped to [0, t] (s = 0 outside it)."""
    if index == NO_SCHEDULE:
        return t
    lo = max(schedule.start[index], 0.0)
    hi = min(schedule.stop[index], t)
    if hi <= lo:
        return 0.0
    return _profile_antiderivative(schedule, index, hi) - _profile_antiderivative(schedule, index, lo)
