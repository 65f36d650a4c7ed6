"""Adaptive dopri5 (a tolerance) with contact (issue 18): accurate against the exact bounce and a fine
fixed-step run, at the configured restitution, and a rejected attempt leaves no trace in the state or
the contact history.

The exact reference: a ball dropped on the ground is free flight, then (in contact) the linear
oscillator m z'' = -m g + max(0, k (r - z) - c z'), until that force vanishes; each phase integrated by
scipy's DOP853 to 1e-13 with its end found as an event, so the touch-down and release times are exact.
Fixed steps straddle the touch-down, where the dashpot force jumps by c |v|, so they are first order
through a contact (rk4 at dt = 1e-5 s: 4e-6 m); the adaptive steps find it by rejection.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

import rbcli
from rbcli.physics.adaptive import COUNT_REJECTED
from rbcli.physics.contact.force import begin_contact_step
from rbcli.physics.integrators import dopri5
from rbcli.scene.load import load_scene_text

DROP = 0.25  # [m] from the ball's lowest point to the ground
RADIUS = 0.05
E = 0.8


def _bounce(integrator: str, dt: float, tolerance: float | None = None, friction: float = 0.0) -> str:
    """A ball (one contact sphere) dropped from rest DROP above the ground, moving sideways at 0.3 m/s."""
    tol = f", tolerance: {tolerance!r}" if tolerance is not None else ""
    return f"""name: bounce
simulation: {{dt: {dt!r}, duration: 0.8, integrator: {integrator}{tol}}}
gravity: [0, 0, -9.81]
contact: {{ground: 0, material: {{restitution: {E}, friction: {friction}}}}}
bodies:
  - {{name: ball, particles: {{positions: [[0, 0, 0]], masses: [0.5], radius: [{RADIUS}]}},
     position: [0, 0, {RADIUS + DROP!r}], velocity: [0.3, 0, 0]}}
"""


def _heights(text: str, every: int) -> tuple[np.ndarray, rbcli.Simulation]:
    """z of the ball at t = 0, every-th step, ... (the output grid of the adaptive runs, 1 ms)."""
    sim = rbcli.Simulation(load_scene_text(text))
    z = [sim.data.state.x[0, 2]]
    for _ in range(sim.settings.steps // every):
        sim.step(every)
        z.append(sim.data.state.x[0, 2])
    return np.array(z), sim


def _exact_heights(sim: rbcli.Simulation, times: np.ndarray) -> np.ndarray:
    """z(t) of the dropped ball, phase by phase (module docstring), with the scene's k and c."""
    contact = sim.model.contact
    k = contact.body_stiffness[0]  # a plane contact takes the body's stiffness
    m = sim.model.body_mass[0]
    zeta = min(contact.body_damping_ratio[0], contact.plane_damping_ratio[0])
    c = 2.0 * zeta * math.sqrt(k * m)  # the ball is one contact sphere: m_eff = m

    def touch(t: float, y: np.ndarray) -> float:
        return y[0] - RADIUS

    def release(t: float, y: np.ndarray) -> float:
        return k * (RADIUS - y[0]) - c * y[1]

    touch.terminal = release.terminal = True  # type: ignore[attr-defined]
    touch.direction = release.direction = -1  # type: ignore[attr-defined]
    phases = (
        (lambda t, y: [y[1], -9.81], touch),
        (lambda t, y: [y[1], -9.81 + max(0.0, k * (RADIUS - y[0]) - c * y[1]) / m], release),
    )
    t, y, out, phase = 0.0, np.array([RADIUS + DROP, 0.0]), np.empty(len(times)), 0
    while t < times[-1]:
        rate, event = phases[phase]
        sol = solve_ivp(rate, (t, times[-1]), y, method="DOP853", rtol=1e-13, atol=1e-15, events=event,
                        dense_output=True)  # fmt: skip
        end = sol.t_events[0][0] if len(sol.t_events[0]) else times[-1]
        inside = (times >= t) & (times <= end)
        out[inside] = sol.sol(times[inside])[0]
        t, y = end, sol.y_events[0][0] if len(sol.t_events[0]) else sol.y[:, -1]
        phase = 1 - phase
    return out


def test_adaptive_bounce_matches_the_exact_bounce_a_fine_fixed_step_run_and_the_restitution():
    fixed, sim = _heights(_bounce("rk4", 1e-5), every=100)
    exact = _exact_heights(sim, np.arange(len(fixed)) * 1e-3)
    fixed_error = float(np.max(np.abs(fixed - exact)))
    assert fixed_error < 2e-5  # first order through the touch-downs (measured 4.1e-6; 5.8e-4 at dt = 1e-4)
    for tolerance in (1e-5, 1e-7):
        z, sim = _heights(_bounce("dopri5", 1e-3, tolerance), every=1)
        # the global error is below the tolerance (measured 0.005x and 0.016x): the run's error budget
        assert float(np.max(np.abs(z - exact))) < tolerance
        assert float(np.max(np.abs(z - fixed))) < fixed_error + tolerance
        assert sim.data.adaptive_counters[COUNT_REJECTED] > 0  # touch-downs found by rejecting steps across them
        # restitution from the first rebound's apex (free flight after the contact: v^2 = 2 g h)
        first = int(np.argmax(np.diff(z) > 0))  # the first frame moving up again
        apex = float(z[first:].max()) - RADIUS
        assert math.sqrt(apex / DROP) == pytest.approx(E, rel=0.05)


def test_a_rejected_attempt_leaves_no_trace():
    """Two identical adaptive runs with friction (so each contact carries a tangential spring), one of
    which makes an extra attempt mid-contact that is thrown away (the stages of a huge step, then
    `restore`, as the controller does on rejection): both continue bitwise alike."""
    a = rbcli.Simulation(load_scene_text(_bounce("dopri5", 1e-3, 1e-6, friction=0.5)))
    b = rbcli.Simulation(load_scene_text(_bounce("dopri5", 1e-3, 1e-6, friction=0.5)))
    a.step(228)  # the first touch-down: in contact, sliding sideways with a stretched tangential spring
    b.step(228)
    work = b.data.force.contact
    assert work.hist_count.sum() == 1 and np.abs(work.hist_xi).max() > 0.0
    before = [np.copy(getattr(work, name)) for name in ("hist_count", "hist_partner", "hist_xi")]
    s, d = b.data.state, b.data
    t = s.step * b.dt
    begin_contact_step(work, t, 0.004)
    model, forces, contact = b.model.kernel_bodies(), b._kforces, b._kmodel.contact  # as the loop passes them
    dopri5.begin(model, forces, contact, d.force, t, s.x, s.q, s.P, s.L, d.F, d.tau, d.adaptive_work)
    dopri5.advance(model, forces, contact, d.force, t, 0.004, s.x, s.q, s.P, s.L, d.F, d.tau, d.adaptive_work)
    err = dopri5.error_norm(model, forces, contact, d.force, t, 0.004, 1e-6 * 0.004 / 0.8, s.x, s.q, s.P, s.L, d.F,
                            d.tau, d.adaptive_work)  # fmt: skip
    assert err > 1.0  # the controller would reject it
    dopri5.restore(s.x, s.q, s.P, s.L, d.adaptive_work)
    for name, old in zip(("hist_count", "hist_partner", "hist_xi"), before, strict=True):
        assert np.array_equal(getattr(work, name), old)
    a.step(200)
    b.step(200)
    for name in ("x", "q", "P", "L"):
        assert np.array_equal(getattr(a.data.state, name), getattr(b.data.state, name)), name
    assert np.array_equal(a.data.force.contact.hist_xi, b.data.force.contact.hist_xi)
