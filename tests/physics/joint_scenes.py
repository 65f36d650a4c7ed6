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
