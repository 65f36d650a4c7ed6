"""Deep impacts (issue 28 item 3): the speed bound of what a scene allows, the sub-step travel rule, the
depth estimate and the warnings that name the speed a scene cannot take.

Checks against closed forms (the spring-dashpot's peak compression against a direct integration, a free
fall's speed), against a run without the rule (two small fast balls pass through each other at one
sub-step and rebound with the travel rule), and against the recorded deepest overlap of a brick hitting
the ground at 20 m/s, sampled every 1e-5 s (its contact lasts ~80 samples, so the peak is resolved).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import rbcli
from rbcli.physics.contact.parameters import (
    DEPTH_FRACTION,
    IMPACT_DEPTH,
    MAX_AUTO_SUBSTEPS,
    PENETRATION_AT_REST,
    TRAVEL_FRACTION,
    peak_compression,
    substeps_for,
)
from rbcli.scene.load import load_scene_text

ROOT = Path(__file__).resolve().parents[2]
G = 9.81


@pytest.mark.parametrize("zeta", [0.0, 0.2, 0.5, 0.99, 1.0, 2.5])
def test_peak_compression_is_the_damped_oscillators(zeta):
    """max d of d'' + 2 zeta d' + d = 0, d(0) = 0, d'(0) = 1, by RK4 at h = 1e-4 (error ~1e-15 per unit
    time; the peak's location is found to h, its value to h^2 ~ 1e-8)."""

    def rate(y: np.ndarray) -> np.ndarray:
        return np.array([y[1], -2.0 * zeta * y[1] - y[0]])

    y, h, peak = np.array([0.0, 1.0]), 1e-4, 0.0
    while y[1] > 0.0:
        k1 = rate(y)
        k2 = rate(y + 0.5 * h * k1)
        k3 = rate(y + 0.5 * h * k2)
        k4 = rate(y + h * k3)
        y = y + h / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
        peak = max(peak, y[0])
    assert peak_compression(zeta) == pytest.approx(peak, rel=1e-6)


def _ball_scene(height: float, velocity: float, contact: str, dt: float = 1e-3, steps: int = 400,
                radius: float = 0.05, extra: str = "") -> str:  # fmt: skip
    return (
        f"simulation: {{dt: {dt!r}, steps: {steps}, record: {{every: 1}}}}\n"
        "gravity: [0, 0, -9.81]\n"
        f"contact:\n{contact}"
        "bodies:\n"
        f"  - {{name: ball, particles: {{positions: [[0, 0, 0]], masses: [0.5], radius: [{radius!r}]}}, "
        f"position: [0, 0, {height!r}], velocity: [0, 0, {-velocity!r}]}}\n" + extra
    )


def test_the_speed_bound_of_a_drop_is_its_fall_speed():
    """A ball (one sphere at its centre) thrown down at 3 m/s from 2 m: the bound is sqrt(v0^2 + 2 g h)
    exactly, and the speed it reaches at first touch (centre at h = r) is just below it."""
    spec = load_scene_text(_ball_scene(2.0, 3.0, "  ground: 0\n", steps=600))
    impact = spec.compiled_model.contact.impact
    assert impact.speed == pytest.approx(math.sqrt(9.0 + 2 * G * 2.0), rel=1e-12)
    assert impact.approach_speed == impact.speed and impact.fall == pytest.approx(2.0)
    sim = rbcli.Simulation(spec)
    fastest = 0.0
    while sim.state.x[0, 2] > 0.05:
        sim.step(1)
        fastest = max(fastest, float(np.linalg.norm(sim.state.v[0])))
    assert math.sqrt(9.0 + 2 * G * 1.95) * 0.99 < fastest <= impact.speed


def test_two_falling_bodies_without_a_floor_meet_at_their_initial_speeds():
    """Uniform gravity does not change relative velocities: with nothing to land on, no fall counts."""
    extra = ("  - {name: other, particles: {positions: [[0, 0, 0]], masses: [0.5], radius: [0.05]}, "
             "position: [0, 0, -1], velocity: [0, 0, 2]}\n")  # fmt: skip
    spec = load_scene_text(_ball_scene(2.0, 3.0, "  substeps: auto\n", extra=extra))
    assert spec.compiled_model.contact.impact.approach_speed == pytest.approx(5.0, rel=1e-12)


def _head_on_small(substeps: str, dt: float, gap: float) -> rbcli.Simulation:
    """Two 5 mm balls of 10 g closing at 20 m/s, `gap` [m] apart, 4.5e4 N/m: the stability rule asks for
    7 sub-steps of dt = 2 ms, the travel rule for 16."""
    ball = (
        "{{name: {n}, particles: {{positions: [[0, 0, 0]], masses: [0.01], radius: [0.005]}}, position: [{x!r}, 0, 0], "
    )
    text = (
        f"simulation: {{dt: {dt!r}, steps: 20, record: {{every: 1}}}}\n"
        f"contact:\n  substeps: {substeps}\n  material: {{stiffness: 4.5e4, restitution: 0.9, friction: 0}}\n"
        "bodies:\n"
        f"  - {ball.format(n='a', x=-0.005 - gap / 2)}velocity: [10, 0, 0]}}\n"
        f"  - {ball.format(n='b', x=0.005 + gap / 2)}velocity: [-10, 0, 0]}}\n"
    )
    return rbcli.Simulation(load_scene_text(text))


def _first_overlap(h: float) -> float:
    """The overlap [m] at which the contact is first found, stepping at h, the gap chosen so that the
    touch falls just after a force evaluation (split2's, mid-step): the next one finds 0.95 of what the
    balls close in one step."""
    sim = _head_on_small("1", h, gap=20.0 * h * 3.55)
    while True:
        sim.step(1)
        if sim.data.force.contact.stats[0] > 0:
            return float(sim.data.force.contact.stats[1])


def test_auto_substeps_find_a_contact_within_the_travel_fraction_of_its_touch():
    """A contact found late acts on an overlap the balls never had at its start (the impact is then
    stiffer than the spring and loses or gains energy). With `substeps: auto` the fastest sphere moves at
    most TRAVEL_FRACTION r per sub-step, so two balls meeting head-on at 10 m/s each are found within
    twice that; at the sub-step the stability rule alone gives, later."""
    auto = _head_on_small("auto", 0.002, gap=0.01)
    h = 0.002 / auto.settings.substeps
    assert auto.settings.substeps == math.ceil(0.002 * 10.0 / (TRAVEL_FRACTION * 0.005) - 1e-9)
    stable = 0.002 / substeps_for(0.002, auto.model.contact.stable_step)
    assert stable > 2 * h  # the travel rule is what sets h here
    assert _first_overlap(h) <= 2 * TRAVEL_FRACTION * 0.005 * (1 + 1e-9)
    assert _first_overlap(stable) > 1.5 * 2 * TRAVEL_FRACTION * 0.005
    auto.step(20)  # and the collision: a rebound at about the restitution, momentum kept
    assert auto.state.v[0, 0] == pytest.approx(-9.0, rel=0.05) and abs(auto.state.P.sum(axis=0)).max() < 1e-15


def _brick(velocity: float, stiffness: str | None, dt: float = 1e-5, duration: float = 0.04,
           primitives: bool = True) -> str:  # fmt: skip
    """scenes/contact/box_drop.yaml (sub-steps auto) thrown down at `velocity` [m/s]; with `primitives`
    false its brick touches through its lattice's carpet of spheres."""
    text = (ROOT / "scenes/contact/box_drop.yaml").read_text()
    assert "\n  substeps: auto" in text
    material = "{restitution: 0.3, friction: 0.6" + (f", stiffness: {stiffness}" if stiffness else "") + "}"
    carpet = "" if primitives else "\n  primitives: false"
    text = text.replace("  material: {restitution: 0.3, friction: 0.6}", f"  material: {material}{carpet}")
    text = text.replace(
        "angular_velocity: [2, -3, 5]", f"angular_velocity: [2, -3, 5]\n    velocity: [0, 0, {-velocity}]"
    )
    return text.replace(
        "dt: 0.001, duration: 4.0, record: {every: 10}", f"dt: {dt!r}, duration: {duration!r}, record: {{every: 1}}"
    )


def _deepest(text: str) -> tuple[float, list[str]]:
    spec = load_scene_text(text, file="brick.yaml")
    warnings = [str(w) for w in rbcli.prepare(spec).warnings]
    trajectory = rbcli.simulate(spec)
    contact = spec.compiled_model.model.contact
    radius = float(contact.sphere_radius.min())
    if contact.primitive_kind[0] >= 0:  # the brick touches the ground as its box: depths against its size
        radius = float(contact.primitive_size[0].min())
    return float(trajectory.invariants["contact_max_overlap"].max()) / radius, warnings


def test_a_brick_at_20_m_s_goes_no_deeper_than_half_a_radius_with_the_stiffness_validation_names():
    """Touching through its lattice's spheres (`primitives: false`), the brick's default stiffness (0.25 %
    sink at rest) cannot stop it at 20 m/s within 0.5 r, and no sub-stepping changes that (the spring's
    own peak: measured at 2 to 100 sub-steps). Validation says so, naming the speed; with the stiffness it
    names, the deepest recorded overlap is within 0.5 r."""
    text = _brick(20.0, None, primitives=False)
    spec = load_scene_text(text, file="brick.yaml")
    deep = spec.compiled_model.contact.impact.deep
    assert deep is not None and deep.body == "brick" and 20.0 < deep.speed < 22.0
    depth, warnings = _deepest(text)
    assert depth > 2 * DEPTH_FRACTION  # the warning is true
    assert any(f"{deep.speed:.3g} m/s" in w and f"{deep.stiffness_needed:.3g} N/m" in w for w in warnings), warnings
    depth, warnings = _deepest(_brick(20.0, f"{deep.stiffness_needed:.3g}", primitives=False))
    assert depth <= DEPTH_FRACTION, depth
    assert not [w for w in warnings if "deep" in w or "sub-steps" in w], warnings


def test_a_primitive_bricks_default_stiffness_stops_it_at_20_m_s_within_the_impact_depth():
    """As its box, the brick's default stiffness follows its landing (scene/compile_contact.py: one
    corner stops its mass at its speed bound within IMPACT_DEPTH of its half thickness): at 20 m/s the
    deepest recorded overlap stays within IMPACT_DEPTH (the bound is an upper one: the first corner
    carries the whole mass only at the first instant), with no warning; with the rest rule alone (the
    stiffness it would have had, given) it goes past DEPTH_FRACTION."""
    text = _brick(20.0, None)
    spec = load_scene_text(text, file="brick.yaml")
    assert spec.compiled_model.contact.impact.deep is None
    depth, warnings = _deepest(text)
    assert depth <= IMPACT_DEPTH, depth
    assert not [w for w in warnings if "deep" in w or "sub-steps" in w], warnings
    contact, mass = spec.compiled_model.model.contact, float(spec.compiled_model.model.body_mass[0])
    rest = mass * 9.81 / (PENETRATION_AT_REST * float(contact.primitive_size[0].min())) / 4
    assert contact.body_plane_stiffness[0] > 10 * rest
    depth, _ = _deepest(_brick(20.0, f"{rest!r}"))
    assert depth > DEPTH_FRACTION, depth


def test_a_speed_the_sub_steps_cannot_take_is_named():
    """2 km/s at dt = 1 ms would need more than MAX_AUTO_SUBSTEPS sub-steps: a warning with the speed,
    the count it would need and the speed the cap takes; the run uses the cap."""
    spec = load_scene_text(_brick(2000.0, "8.5e6", dt=1e-3, duration=0.01), file="brick.yaml")
    compiled = rbcli.prepare(spec)
    assert compiled.settings.substeps == MAX_AUTO_SUBSTEPS
    warnings = [str(w) for w in compiled.warnings if "sub-steps per step" in str(w)]
    assert len(warnings) == 1, [str(w) for w in compiled.warnings]
    taken = TRAVEL_FRACTION * 0.00625 / (1e-3 / MAX_AUTO_SUBSTEPS)
    assert "2e+03 m/s" in warnings[0] and f"takes {taken:.3g} m/s" in warnings[0], warnings[0]
