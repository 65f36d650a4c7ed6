"""Scenes and measurements shared by the joint tests: a compound pendulum built from its parameters,
its exact period, and the angle's crossings of zero found by cubic Hermite interpolation."""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ellipk

G = 9.81
PIVOT = np.array([0.0, 0.0, 1.0])
# the rod of scenes/joints/pendulum.yaml: five 0.2 kg particles 0.2 m apart below the pivot, radius 0.02 m
ROD_Z = (-0.2, -0.4, -0.6, -0.8, -1.0)
ROD_MASS, ROD_RADIUS = 0.2, 0.02


def pendulum_text(
    theta0: float, dt: float, *, joint: str = "hinge", steps: int = 10, integrator: str = "split2"
) -> str:
    """A compound pendulum (the rod) released from rest at theta0 [rad] about y, held at the pivot by a
    hinge about y or a ball joint."""
    d = -float(np.mean(ROD_Z))
    com = PIVOT + d * np.array([-math.sin(theta0), 0.0, -math.cos(theta0)])
    positions = ", ".join(f"[0, 0, {z!r}]" for z in ROD_Z)
    spec = {"hinge": "type: hinge, axis: [0, 1, 0]", "ball": "type: ball"}[joint]
    pivot = ", ".join(repr(float(p)) for p in PIVOT)
    return f"""
name: pendulum-test
simulation: {{dt: {dt!r}, steps: {steps}, integrator: {integrator}}}
gravity: [0, 0, {-G!r}]
bodies:
  - name: rod
    particles: {{positions: [{positions}], masses: {ROD_MASS!r}, radius: {ROD_RADIUS!r}}}
    position: [{float(com[0])!r}, {float(com[1])!r}, {float(com[2])!r}]
    orientation: {{axis_angle: {{axis: [0, 1, 0], angle: {theta0!r}}}}}
joints:
  - {{name: pivot, {spec}, bodies: [rod, world], anchor: [{pivot}]}}
"""


def rod_pivot_inertia() -> tuple[float, float, float]:
    """(M [kg], d [m], I_pivot [kg m^2]) of the rod about the pivot's y axis: sum m z^2 + 2/5 m a^2 each."""
    masses = ROD_MASS * np.ones(len(ROD_Z))
    z = np.array(ROD_Z)
    return float(masses.sum()), float(-np.mean(z)), float(np.sum(masses * z**2) + 0.4 * np.sum(masses) * ROD_RADIUS**2)


def exact_period(theta0: float) -> float:
    """T = 4 K(m) sqrt(l_eff / g), m = sin^2(theta0 / 2), l_eff = I_pivot / (M d) (compound pendulum;
    scipy's ellipk takes the parameter m = k^2)."""
    M, d, inertia = rod_pivot_inertia()
    return float(4.0 * ellipk(math.sin(theta0 / 2.0) ** 2) * math.sqrt(inertia / (M * d) / G))


def angle_and_rate(x: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """theta = atan2(-c_x, -c_z) of the centre of mass about the pivot (c = x - pivot), and d theta/dt."""
    cx, cz = x[0] - PIVOT[0], x[2] - PIVOT[2]
    r2 = cx * cx + cz * cz
    return math.atan2(-cx, -cz), (cz * v[0] - cx * v[2]) / r2


def crossings(times: np.ndarray, theta: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Times where theta crosses zero, each from the cubic Hermite interpolant of (theta, rate) over its
    step (error O(dt^4), far below the integrators' O(dt^2))."""
    found = []
    for k in np.flatnonzero(np.sign(theta[:-1]) * np.sign(theta[1:]) < 0):
        h = times[k + 1] - times[k]
        p0, p1, m0, m1 = theta[k], theta[k + 1], rate[k] * h, rate[k + 1] * h
        s = p0 / (p0 - p1)  # Newton on the cubic from the linear guess
        for _ in range(20):
            h00, h10, h01, h11 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s, -2 * s**3 + 3 * s**2, s**3 - s**2
            f = h00 * p0 + h10 * m0 + h01 * p1 + h11 * m1
            df = (6 * s**2 - 6 * s) * p0 + (3 * s**2 - 4 * s + 1) * m0
            df += (-6 * s**2 + 6 * s) * p1 + (3 * s**2 - 2 * s) * m1
            s -= f / df
        found.append(times[k] + s * h)
    return np.array(found)


# A box of eight 0.125 kg corner particles (0.4 x 0.2 x 0.1 m: three different principal moments) and a
# cloud of four unequal spheres: bodies whose free turn is not about a fixed axis (issue 46)
BOX_CORNERS = [[sx * 0.2, sy * 0.1, sz * 0.05] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
CLOUD_POSITIONS = [[0.1, 0.0, 0.0], [-0.05, 0.12, 0.0], [0.0, -0.03, 0.2], [-0.05, -0.09, -0.1]]
CLOUD_MASSES = [0.3, 0.2, 0.25, 0.35]
TILTED_AXIS = np.array([1.0, 1.0, 0.0]) / math.sqrt(2.0)
TILTED_PIVOT = np.array([0.0, 0.0, 1.0])
TILTED_ANCHOR = np.array([0.15, 0.12, 0.25])  # the pivot in the box's frame: off every principal axis


def _axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return np.concatenate([[math.cos(angle / 2.0)], math.sin(angle / 2.0) * axis])


def _vector(v: np.ndarray) -> str:
    return "[" + ", ".join(repr(float(c)) for c in v) + "]"


def _points(points: list[list[float]]) -> str:
    return "[" + ", ".join(_vector(np.array(p)) for p in points) + "]"


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    w, u = q[0], q[1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.concatenate([[a[0] * b[0] - a[1:] @ b[1:]], a[0] * b[1:] + b[0] * a[1:] + np.cross(a[1:], b[1:])])


def tilted_hinge_text(theta0: float, dt: float) -> str:
    """The box on a hinge about (1, 1, 0)/sqrt 2 through TILTED_PIVOT, its anchor TILTED_ANCHOR in the box's
    frame, the box turned 0.7 rad about (0.3, -0.5, 0.8) and then about the hinge so that its centre of
    mass is theta0 [rad] from hanging (tilted_hinge_angle), released from rest: a pendulum whose body
    turns about no principal axis."""
    q0 = _axis_angle([0.3, -0.5, 0.8], 0.7)
    offset = -_rotate(q0, TILTED_ANCHOR)  # centre of mass - pivot
    turn = _axis_angle(TILTED_AXIS, theta0 - tilted_hinge_angle(TILTED_PIVOT + offset, np.zeros(3))[0])
    q, com = _quat_mul(turn, q0), TILTED_PIVOT + _rotate(turn, offset)
    return f"""
name: tilted-hinge
simulation: {{dt: {dt!r}, steps: 10, integrator: split2}}
gravity: [0, 0, {-G!r}]
bodies:
  - name: box
    particles: {{positions: {_points(BOX_CORNERS)}, masses: 0.125, radius: 0.01}}
    position: {_vector(com)}
    orientation: {{wxyz: {_vector(q)}}}
joints:
  - {{name: pivot, type: hinge, bodies: [box, world], anchor: {_vector(TILTED_PIVOT)}, axis: {_vector(TILTED_AXIS)}}}
"""


def tilted_hinge_angle(x: np.ndarray, v: np.ndarray) -> tuple[float, float]:
    """(theta, d theta/dt): the centre of mass's angle about the hinge from hanging, and its rate, from
    its world position x and velocity v (d = the part of x - pivot across the axis: theta' = u.(d x v)/|d|^2)."""
    d = x - TILTED_PIVOT
    d = d - (d @ TILTED_AXIS) * TILTED_AXIS
    down = np.array([0.0, 0.0, -1.0])
    return math.atan2(TILTED_AXIS @ np.cross(down, d), down @ d), float(TILTED_AXIS @ np.cross(d, v) / (d @ d))


def tilted_hinge_period(theta0: float) -> float:
    """T = 4 K(sin^2(theta0/2)) sqrt(l_eff / g), l_eff = I_u / (M d): I_u the box's moment about the hinge
    line (its own about the parallel axis through its centre plus M d^2), d its centre's distance from it."""
    corners, mass, radius = np.array(BOX_CORNERS), 0.125, 0.01
    # box frame, about the centre: the corners as points and each particle's own 2/5 m a^2 (a sphere)
    inertia = mass * (np.sum(corners**2) * np.eye(3) - corners.T @ corners + len(corners) * 0.4 * radius**2 * np.eye(3))
    q0 = _axis_angle([0.3, -0.5, 0.8], 0.7)  # the hinge turn keeps the axis: R(q0)^T u is its body frame
    u_box = _rotate(q0 * np.array([1.0, -1.0, -1.0, -1.0]), TILTED_AXIS)
    d_box = -TILTED_ANCHOR - (-TILTED_ANCHOR @ u_box) * u_box
    total = mass * len(corners)
    moment = u_box @ inertia @ u_box + total * (d_box @ d_box)
    length = moment / (total * math.sqrt(d_box @ d_box))
    return float(4.0 * ellipk(math.sin(theta0 / 2.0) ** 2) * math.sqrt(length / G))


def double_pendulum_3d_text(dt: float) -> str:
    """A 3-D double pendulum: the box on a ball joint to the world at (0, 0, 2) (its anchor TILTED_ANCHOR)
    and the four-sphere cloud on a ball joint to the box's corner region, both tumbling (initial angular
    velocities, which the first step makes consistent with the joints)."""
    q1, q2 = _axis_angle([0.3, -0.5, 0.8], 0.7), _axis_angle([-0.6, 0.2, 0.5], 1.1)
    pivot = np.array([0.0, 0.0, 2.0])
    x1 = pivot - _rotate(q1, TILTED_ANCHOR)
    elbow = x1 + _rotate(q1, np.array([-0.2, -0.1, -0.05]))
    x2 = elbow + np.array([0.2, 0.1, -0.3])
    return f"""
name: double-pendulum-3d
simulation: {{dt: {dt!r}, steps: 10, integrator: split2}}
gravity: [0, 0, {-G!r}]
bodies:
  - name: box
    particles: {{positions: {_points(BOX_CORNERS)}, masses: 0.125, radius: 0.01}}
    position: {_vector(x1)}
    orientation: {{wxyz: {_vector(q1)}}}
    angular_velocity: [3.0, -2.0, 5.0]
  - name: cloud
    particles: {{positions: {_points(CLOUD_POSITIONS)}, masses: {CLOUD_MASSES!r}, radius: 0.02}}
    position: {_vector(x2)}
    orientation: {{wxyz: {_vector(q2)}}}
    angular_velocity: [-4.0, 6.0, 2.0]
joints:
  - {{name: shoulder, type: ball, bodies: [box, world], anchor: {_vector(pivot)}}}
  - {{name: elbow, type: ball, bodies: [cloud, box], anchor: {_vector(elbow)}}}
"""


def hanging_double_pendulum_3d_text(dt: float) -> str:
    """The box and the cloud of double_pendulum_3d_text hanging near their equilibrium: the box's anchor
    straight above its centre of mass, tilted 0.05 rad, the elbow as far below the centre as the pivot
    above it, the cloud's centre 0.2 m below the elbow tilted back; both turning slowly about axes off
    their principal axes. Small swings and slow turns: a regular (not chaotic) motion, over which a
    symmetric step's energy error is quasi-periodic and its running mean settles."""
    up, a = np.array([0.0, 0.0, 1.0]), TILTED_ANCHOR / np.linalg.norm(TILTED_ANCHOR)
    upright = _axis_angle(np.cross(a, up), math.acos(a @ up))  # the anchor's direction turned to world up
    q1 = _quat_mul(_axis_angle([1.0, 0.3, 0.0], 0.05), upright)
    q2 = _axis_angle([-0.6, 0.2, 0.5], 1.1)
    pivot = np.array([0.0, 0.0, 2.0])
    x1 = pivot - _rotate(q1, TILTED_ANCHOR)
    elbow = x1 - _rotate(q1, TILTED_ANCHOR)
    x2 = elbow + _rotate(_axis_angle([0.2, 1.0, 0.0], -0.05), np.array([0.0, 0.0, -0.2]))
    return f"""
name: hanging-double-pendulum-3d
simulation: {{dt: {dt!r}, steps: 10, integrator: split2}}
gravity: [0, 0, {-G!r}]
bodies:
  - name: box
    particles: {{positions: {_points(BOX_CORNERS)}, masses: 0.125, radius: 0.01}}
    position: {_vector(x1)}
    orientation: {{wxyz: {_vector(q1)}}}
    angular_velocity: [0.3, -0.2, 0.0]
  - name: cloud
    particles: {{positions: {_points(CLOUD_POSITIONS)}, masses: {CLOUD_MASSES!r}, radius: 0.02}}
    position: {_vector(x2)}
    orientation: {{wxyz: {_vector(q2)}}}
    angular_velocity: [0.2, 0.4, 0.0]
joints:
  - {{name: shoulder, type: ball, bodies: [box, world], anchor: {_vector(pivot)}}}
  - {{name: elbow, type: ball, bodies: [cloud, box], anchor: {_vector(elbow)}}}
"""
