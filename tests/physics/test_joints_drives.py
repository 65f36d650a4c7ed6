"""Joint dampers and velocity motors against their exact motions: a flywheel on a damped hinge decays
as exp(-c t / I), a slider's block as exp(-c t / M), and a motor with a torque cap spins a flywheel up at
cap / I until it reaches its speed, then holds it (physics/joints/stages.py: _drive); the motors also in
joint coordinates (physics/tree/limits.py; their dampers: tests/physics/test_tree_integrate.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rbcli.runner.simulation import Simulation
from rbcli.scene.load import load_scene_text

# a ring of four 0.25 kg particles 0.5 m from its centre in the xz plane: I_yy = 4 * 0.25 * 0.25 = 0.25
RING = """
simulation: {{dt: 0.001, steps: 10, integrator: split2}}
bodies:
  - name: wheel
    particles: {{positions: [[0.5, 0, 0], [-0.5, 0, 0], [0, 0, 0.5], [0, 0, -0.5]], masses: 0.25}}
    position: [0, 0, 1]
    angular_velocity: [0, {omega0!r}, 0]
    velocity: [{v0!r}, 0, 0]
joints:
  - {{type: {kind}, bodies: [wheel, world], anchor: [0, 0, 1], axis: [{axis}], {drive}}}
"""
INERTIA, MASS, DT = 0.25, 1.0, 1e-3


def run(
    kind: str, drive: str, steps: int, omega0: float = 0.0, v0: float = 0.0, integrator: str = "split2"
) -> tuple[np.ndarray, np.ndarray]:
    """The wheel's angular velocity y and velocity x after each of `steps` steps."""
    axis = "0, 1, 0" if kind == "hinge" else "1, 0, 0"
    text = RING.format(omega0=omega0, v0=v0, kind=kind, axis=axis, drive=drive)
    sim = Simulation(load_scene_text(text.replace("integrator: split2", f"integrator: {integrator}")))
    assert sim.model.body_mass[0] == MASS
    omega, v = np.empty(steps), np.empty(steps)
    for n in range(steps):
        sim.step(1)
        omega[n], v[n] = sim.state.omega[0, 1], sim.state.v[0, 0]
    return omega, v


def test_a_damped_hinge_decays_at_the_analytic_rate():
    """omega(t) = omega0 exp(-c t / I), c = 0.05 N m s/rad: the damper is the exact flow of dr/dt = -c k r
    within the constraints (k = 1 / I here), so every step matches to round-off (1e-12 relative)."""
    omega, _ = run("hinge", "damping: 0.05", 1000, omega0=3.0)
    exact = 3.0 * np.exp(-0.05 * DT * np.arange(1, 1001) / INERTIA)
    np.testing.assert_allclose(omega, exact, rtol=1e-12, atol=0)


def test_a_damped_slider_decays_at_the_analytic_rate():
    """v(t) = v0 exp(-c t / M) along the slider's axis, c = 0.4 N s/m; the wheel does not turn."""
    omega, v = run("slider", "damping: 0.4", 1000, v0=2.0)
    np.testing.assert_allclose(v, 2.0 * np.exp(-0.4 * DT * np.arange(1, 1001) / MASS), rtol=1e-12, atol=0)
    assert np.abs(omega).max() == 0.0


INTEGRATORS = ["split2", "reduced-euler", "reduced-rk4"]  # maximal coordinates and both joint-coordinate ones


@pytest.mark.parametrize("integrator", INTEGRATORS)
@pytest.mark.parametrize("speed", [2.0, -2.0])
def test_a_capped_motor_reaches_its_speed_with_the_capped_torque(speed, integrator):
    """From rest, a motor of speed s and max_torque 0.5 N m accelerates the flywheel at 0.5 / I = 2 rad/s^2
    (the cap binds) until omega = s at t = |s| I / 0.5 = 1 s, then holds it: omega_n = sign(s)
    min(2 n dt, |s|) to round-off."""
    omega, _ = run("hinge", f"motor: {{speed: {speed!r}, max_torque: 0.5}}", 1500, integrator=integrator)
    exact = math.copysign(1.0, speed) * np.minimum(0.5 / INERTIA * DT * np.arange(1, 1501), abs(speed))
    np.testing.assert_allclose(omega, exact, rtol=0, atol=1e-12)


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_motor_drives_a_slider_against_its_force_cap(integrator):
    """A slider motor of 0.3 m/s with max_force 0.6 N: v = min(0.6 t / M, 0.3), reached at t = 0.5 s."""
    _, v = run("slider", "motor: {speed: 0.3, max_force: 0.6}", 800, integrator=integrator)
    np.testing.assert_allclose(v, np.minimum(0.6 / MASS * DT * np.arange(1, 801), 0.3), rtol=0, atol=1e-12)
