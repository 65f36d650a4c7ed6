"""Errors of a run against a reference: the exact reference where a scene admits one, error metrics,
invariant drift, and the empirical order of convergence.

A scene admits the exact reference when its only force term is uniform gravity: every centre of mass
then moves as x0 + v0 t + g t^2 / 2 and every body rotates torque-free (Euler-Poinsot, `exact.py`),
with R0 and omega0 from the compiled initial state.

Rotation error is the geodesic angle between two orientations, angle(R_a^T R_b) in [0, pi], computed
from quaternions as 2 atan2(|vec(q_a^* q_b)|, |w(q_a^* q_b)|) (`exact.quat_geodesic_angle`): unlike
arccos((tr - 1) / 2) it keeps full relative precision for tiny angles (arccos loses half the digits
near 1), which is where high-order methods live. The angle is the same in any body frame (R E^T vs R),
so user-frame and principal-frame orientations compare alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rbcli.analysis.exact import quat_geodesic_angle
from rbcli.physics.conservation import conserved_invariants
from rbcli.physics.energy import INVARIANT_NAMES
from rbcli.physics.forces import force_terms_present
from rbcli.physics.forces.spring import spring_ends
from rbcli.physics.frames import body_angular_velocity, body_velocity, user_orientation
from rbcli.physics.rotation import quat_to_matrix
from rbcli.record.memory_sink import Trajectory
from rbcli.scene.compile import CompiledScene

# Force terms whose motion the exact reference covers.
EXACT_FORCE_TERMS = frozenset({"gravity"})
# Errors at or above this angle [rad] are outside the asymptotic range: the geodesic angle stops
# growing like dt^p long before it saturates at pi (sin-like bending is ~1.5 % at 0.3 rad).
ROTATION_SATURATION = 0.3
# Round-off floor: accumulated round-off grows about like eps sqrt(steps) (a random walk of one
# rounding per step); the factor 100 covers the tens of flops per step, so points below the floor are
# noise, not truncation error. Amplified round-off above the floor is caught by MIN_SLOPE below.
ROUNDOFF_FACTOR = 1.0e2
# Points whose neighbouring local slopes differ by more than this are not in one asymptotic regime.
SLOPE_SPREAD = 0.25
# A local slope below this is not truncation error of any method of order >= 1: round-off (often
# amplified far above the floor, e.g. by the unstable intermediate-axis motion, where the error then
# grows as dt shrinks and the steps multiply) or a saturated, chaotic regime.
MIN_SLOPE = 0.5
# Two points always give a slope, even from noise; an order needs two consecutive consistent slopes.
MIN_FIT_POINTS = 3


def rotation_error(q_a: np.ndarray, q_b: np.ndarray) -> np.ndarray:
    """Geodesic angle [rad] between unit quaternions (w, x, y, z), shape (..., 4) -> (...)."""
    return quat_geodesic_angle(q_a, q_b)


def position_error(x_a: np.ndarray, x_b: np.ndarray) -> np.ndarray:
    """Euclidean distance [m] between positions, shape (..., 3) -> (...)."""
    return np.linalg.norm(np.asarray(x_a) - np.asarray(x_b), axis=-1)


def scalar_drift(series: np.ndarray, scale: float | None = None) -> float:
    """max_t |s(t) - s(0)| / scale, scale = |s(0)| by default (absolute drift when that is 0)."""
    s = np.asarray(series, dtype=np.float64)
    if s.size == 0:
        return float("nan")
    ref = abs(float(s[0])) if scale is None else float(scale)
    return float(np.max(np.abs(s - s[0])) / (ref if ref > 0.0 else 1.0))


def vector_drift(series: np.ndarray) -> float:
    """max_t |V(t) - V(0)| / |V(0)| for a (T, 3) series (absolute when V(0) = 0)."""
    v = np.asarray(series, dtype=np.float64)
    if v.shape[0] == 0:
        return float("nan")
    ref = float(np.linalg.norm(v[0]))
    return float(np.max(np.linalg.norm(v - v[0], axis=-1)) / (ref if ref > 0.0 else 1.0))


def roundoff_floor(steps: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Error level [scale units] below which a run's error is round-off: 100 eps sqrt(steps) scale."""
    return ROUNDOFF_FACTOR * np.finfo(np.float64).eps * np.sqrt(np.asarray(steps, dtype=np.float64)) * scale


@dataclass(frozen=True)
class OrderFit:
    """Empirical order p of error ~ C dt^p: least-squares slope of log(error) against log(dt).

    order is None (and points 0) when fewer than MIN_FIT_POINTS points are in the asymptotic range.
    dt_min/dt_max [s] bound the points used; points counts them.
    """

    order: float | None
    points: int
    dt_min: float | None = None
    dt_max: float | None = None

    def as_dict(self) -> dict:
        return {"order": self.order, "points": self.points, "dt_min": self.dt_min, "dt_max": self.dt_max}


def fit_order(dt: np.ndarray, error: np.ndarray, floor: np.ndarray | float = 0.0, ceiling: float = np.inf) -> OrderFit:
    """Fit the slope over the asymptotic range of (dt, error) pairs.

    Points are dropped when non-finite, below the round-off floor or at/above the ceiling
    (saturation). Of the remaining points (sorted by dt), the fit uses the longest contiguous run whose
    local slopes are all >= MIN_SLOPE and within SLOPE_SPREAD of each other (the smallest dts on a
    tie): that cuts both a pre-asymptotic coarse end and a round-off-dominated fine end that slipped
    past the floor (amplified round-off grows as dt shrinks: a slope <= 0).
    """
    dt = np.asarray(dt, dtype=np.float64)
    error = np.asarray(error, dtype=np.float64)
    floor = np.broadcast_to(np.asarray(floor, dtype=np.float64), dt.shape)
    keep = np.isfinite(error) & (error > floor) & (error < ceiling) & (dt > 0)
    order = np.argsort(dt[keep])
    log_dt = np.log(dt[keep][order])
    log_err = np.log(error[keep][order])
    n = log_dt.size
    if n < MIN_FIT_POINTS:
        return OrderFit(None, 0)
    slopes = np.diff(log_err) / np.diff(log_dt)
    best = (0, 0)  # point indices [i, j] inclusive
    for i in range(n - 1):
        for j in range(i + 1, n):
            window = slopes[i:j]
            if window.min() < MIN_SLOPE or window.max() - window.min() > SLOPE_SPREAD:
                break
            if j - i > best[1] - best[0]:
                best = (i, j)
    i, j = best
    if j - i + 1 < MIN_FIT_POINTS:
        return OrderFit(None, 0)
    slope = float(np.polyfit(log_dt[i : j + 1], log_err[i : j + 1], 1)[0])
    return OrderFit(slope, j - i + 1, float(np.exp(log_dt[i])), float(np.exp(log_dt[j])))


def admits_exact_solution(compiled: CompiledScene) -> bool:
    """True when every force term is uniform gravity and no joint holds a body: free flight plus
    torque-free rotation is then exact (a jointed body's motion is not that)."""
    terms = set(force_terms_present(compiled.forces, compiled.model.contact))
    return terms <= EXACT_FORCE_TERMS and not compiled.spec.forces and not compiled.spec.joints


def conserved_quantities(compiled: CompiledScene) -> tuple[str, ...]:
    """Which invariants the exact motion keeps, whole: "energy" (the total), "momentum" and
    "angular_momentum" (about the origin) when every component is kept. The rules per component are
    `physics/conservation.py` (the labels `rbsim info` shows): energy with conservative terms only
    (gravity, undamped springs, unscheduled fields with a symmetric gradient); momentum without external
    force (springs between two bodies, pure torques); angular momentum without external torque.
    """
    kept = conserved_invariants(compiled.model, compiled.forces, INVARIANT_NAMES)
    conserved = []
    if kept["energy_total"]:
        conserved.append("energy")
    if all(kept[f"momentum_{axis}"] for axis in "xyz"):
        conserved.append("momentum")
    if all(kept[f"angular_momentum_{axis}"] for axis in "xyz"):
        conserved.append("angular_momentum")
    return tuple(conserved)


def smoothness_notes(compiled: CompiledScene) -> list[str]:
    """Why a scene's fitted orders can stay below the methods' own: force terms that are not smooth
    along the motion (empty when none is known).

    A damper's force c (e . v) e has the direction e = d / |d| of its spring: undefined at |d| = 0,
    where it is set to 0 (forces/spring.py), though its limit along a motion through there is not 0. A
    damped zero-rest-length spring whose ends coincide at the start (a chain laid out end to end) makes
    every method's first step an O(dt^2) error: rk4, dopri5, split4 and exact4 all fitted 2 on
    scenes/forces/spring_chain.yaml, and 4 / 5 / 4 / 4 from t = 0.1 s (tests/physics/test_damped_orders.py).
    """
    spring = compiled.forces.spring
    damped = spring.damping != 0.0
    if not np.any(damped):
        return []
    state = compiled.initial_state
    _, _, pa, pb, _, _ = spring_ends(compiled.model, spring, state.x, state.q)
    scale = max(1.0, float(np.abs(state.x).max()))
    at_zero = damped & (np.linalg.norm(pa - pb, axis=-1) <= 1e-12 * scale)
    count = int(np.count_nonzero(at_zero))
    if not count:
        return []
    return [
        f"{count} dampers start at zero length, where a damper's direction is undefined: the motion is "
        "not smooth at t = 0 and every method's error there is O(dt^2), so fitted orders above 2 are "
        "not expected (start the springs stretched, or study from a later state)"
    ]


@dataclass(frozen=True)
class ReferencePath:
    """Reference motion at the output times: x (T, N, 3) [m], q (T, N, 4) wxyz user frame."""

    x: np.ndarray
    q: np.ndarray


def exact_reference(compiled: CompiledScene, times: np.ndarray) -> ReferencePath:
    """Free flight of every centre of mass and torque-free rotation of every body, at `times` [s]."""
    from rbcli.analysis.exact import free_flight, torque_free

    model, state = compiled.model, compiled.initial_state
    n = model.body_count
    g = compiled.forces.gravity if compiled.forces.has_gravity else np.zeros(3)
    v0 = body_velocity(model, state.P)
    omega0_world = body_angular_velocity(model, state.q, state.L)
    R0 = quat_to_matrix(state.q)  # world-from-principal
    x = np.empty((times.size, n, 3))
    q = np.empty((times.size, n, 4))
    for b in range(n):  # once per body at set-up
        x[:, b] = free_flight(state.x[b], v0[b], g, times)[0]
        if np.any(state.L[b] != 0.0):
            omega0_body = R0[b].T @ omega0_world[b]
            q[:, b] = torque_free(model.body_inertia[b], R0[b], omega0_body, times, frame="body").q
        else:
            q[:, b] = state.q[b]
    return ReferencePath(x, user_orientation(model, q))


@dataclass(frozen=True)
class Pendulum:
    """A scene that is one rigid pendulum: one body on one hinge to the world, released from rest under
    gravity perpendicular to the axis, nothing else. pivot [m] and axis [1] world; theta0 [rad] the
    centre of mass's angle from straight down (positive about the axis); omega0 = sqrt(M g d / I_pivot)."""

    pivot: np.ndarray
    axis: np.ndarray
    theta0: float
    omega0: float

    @property
    def period(self) -> float:
        """4 K(sin^2(theta0 / 2)) / omega0 [s]."""
        from rbcli.analysis.exact import pendulum_period

        return pendulum_period(self.theta0, self.omega0)


def pendulum_of(compiled: CompiledScene) -> Pendulum | None:
    """The Pendulum a scene is, or None (any other body, joint, force, drive, limit or initial motion)."""
    from rbcli.physics.joints.tables import JOINT_HINGE

    joint, model, state = compiled.model.joint, compiled.model, compiled.initial_state
    if joint is None or model.body_count != 1 or joint.kind.shape[0] != 1 or compiled.spec.forces:
        return None
    if (
        set(force_terms_present(compiled.forces, compiled.model.contact)) != {"gravity"}
        or compiled.spec.contact is not None
    ):
        return None
    drives = joint.damping[0] > 0.0 or joint.motor_cap[0] > 0.0
    if joint.kind[0] != JOINT_HINGE or joint.body_b[0] >= 0 or drives or np.isfinite(joint.limit_lower[0]):
        return None
    if np.isfinite(joint.limit_upper[0]) or np.any(state.P != 0.0) or np.any(state.L != 0.0):
        return None
    R0 = quat_to_matrix(state.q[0])
    axis = R0 @ joint.axis_a[0]
    g = np.asarray(compiled.forces.gravity, dtype=np.float64)
    g_norm = float(np.linalg.norm(g))
    if abs(float(g @ axis)) > 1e-12 * g_norm:  # gravity along the axis too: not a plane pendulum
        return None
    pivot = np.asarray(joint.anchor_b[0], dtype=np.float64)
    offset = state.x[0] - pivot
    arm = offset - (offset @ axis) * axis  # the centre of mass's distance from the axis
    d = float(np.linalg.norm(arm))
    if d == 0.0:
        return None
    down = g / g_norm
    inertia = float(axis @ (R0 @ np.diag(model.body_inertia[0]) @ R0.T) @ axis) + float(model.body_mass[0]) * d * d
    theta0 = float(np.arctan2(axis @ np.cross(down, arm), down @ arm))
    return Pendulum(pivot, axis, theta0, float(np.sqrt(model.body_mass[0] * g_norm * d / inertia)))


def pendulum_reference(compiled: CompiledScene, pendulum: Pendulum, times: np.ndarray) -> ReferencePath:
    """The pendulum's exact motion at `times` [s] (exact.pendulum_angle): every point of the body turns
    about the axis through the pivot by theta(t) - theta0."""
    from rbcli.analysis.exact import pendulum_angle
    from rbcli.physics.rotation import quat_from_axis_angle, quat_multiply, quat_rotate

    state = compiled.initial_state
    turned = pendulum_angle(pendulum.theta0, pendulum.omega0, times) - pendulum.theta0
    x = np.empty((times.size, 1, 3))
    q = np.empty((times.size, 1, 4))
    for k, angle in enumerate(turned):  # once per output time, at set-up
        r = quat_from_axis_angle(pendulum.axis, float(angle))
        x[k, 0] = pendulum.pivot + quat_rotate(r, state.x[0] - pendulum.pivot)
        q[k, 0] = quat_multiply(r, state.q[0])
    return ReferencePath(x, user_orientation(compiled.model, q))


def run_errors(traj: Trajectory, ref: ReferencePath) -> tuple[float, float, float, float]:
    """(rotation max, position max, rotation final, position final) over bodies and frames."""
    k = traj.t.size
    rot = rotation_error(traj.q, ref.q[:k])
    pos = position_error(traj.x, ref.x[:k])
    return float(rot.max()), float(pos.max()), float(rot[-1].max()), float(pos[-1].max())


def invariant_drifts(traj: Trajectory, conserved: tuple[str, ...]) -> tuple[float | None, float | None, float | None]:
    """Relative drift of (energy, total momentum, angular momentum about the origin) over a run, each
    None unless `conserved` names it; the energy is scaled by max(|E(0)|, T(0)) so that a total energy
    near 0 (a potential's arbitrary zero) does not inflate it."""
    inv = traj.invariants
    energy = momentum = angular = None
    if "energy" in conserved:
        scale = max(abs(float(inv["energy_total"][0])), abs(float(inv["energy_kinetic"][0])))
        energy = scalar_drift(inv["energy_total"], scale)
    if "momentum" in conserved:
        momentum = vector_drift(np.stack([inv[f"momentum_{a}"] for a in "xyz"], -1))
    if "angular_momentum" in conserved:
        angular = vector_drift(np.stack([inv[f"angular_momentum_{a}"] for a in "xyz"], -1))
    return energy, momentum, angular
