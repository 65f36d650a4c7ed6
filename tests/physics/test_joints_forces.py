"""Joints with the other forces (issue 27 item 3): drag on a jointed body dissipates while the joint
holds; an impulse on a free-floating jointed system changes its total momentum by the impulse exactly
(the joints' forces are internal)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import rbcli
from rbcli.physics.joints.reference import joint_rows_numpy
from rbcli.scene.load import load_scene_text
from tests.physics.joint_scenes import G, angle_and_rate, pendulum_text


def _rows(sim: rbcli.Simulation) -> float:
    s = sim.data.state
    return float(np.abs(joint_rows_numpy(sim.model.joint, s.x, s.q)[0]).max())


def test_a_pendulum_with_linear_drag_loses_energy_monotonically_and_keeps_its_hinge():
    """The rod of the pendulum tests (1 kg) from 60 degrees with drag F = -0.5 v (and its angular part):
    dE/dt = -c |v|^2 - c_w |w|^2 <= 0, so E sampled every 20 steps never rises (the integrator's own
    O(dt^2) energy wobble, ~1e-6 J here, is far below the 20 steps' loss except near rest) and after 3 s
    it has lost most of its energy; the hinge holds to round-off throughout."""
    text = pendulum_text(math.pi / 3.0, 0.001, steps=10)
    text += "forces:\n  - {type: drag, bodies: all, linear: 0.5, angular_linear: 0.05}\n"
    sim = rbcli.Simulation(load_scene_text(text))
    mass = sim.model.body_mass

    def energy() -> float:
        s = sim.state
        return 0.5 * float(np.sum(s.P * s.v) + np.sum(s.L * s.omega)) + float(np.sum(mass * G * s.x[:, 2]))

    energies, worst = [energy()], 0.0
    for _ in range(150):
        sim.step(20)
        energies.append(energy())
        worst = max(worst, _rows(sim))
    e = np.array(energies)
    lowest = e.min()  # at rest at the bottom
    assert np.all(np.diff(e) <= 1e-9 * (e[0] - lowest)), np.diff(e).max()
    assert e[-1] - lowest < 0.2 * (e[0] - lowest)
    assert worst <= 1e-12, worst


# (reduced-euler, first order, lets this fast tumble's momentum drift by ~1 % in 0.2 s: O(h), not the kick's;
# test_tree_limits.py checks its kick alone)
@pytest.mark.parametrize(("integrator", "momentum_tolerance"), [("split2", 1e-12), ("reduced-rk4", 1e-8)])
def test_an_impulse_on_a_free_floating_chain_changes_its_momentum_by_the_impulse(integrator, momentum_tolerance):
    """Three rods ball-jointed end to end, floating with no gravity; an impulse J = (0, 2, 1) N s at the
    tip of the first rod at t = 0.05 s: the total momentum changes by J to round-off (joint impulses act
    in equal and opposite pairs), the total angular momentum about the origin by r_tip x J to 1e-5 of it
    (measured 3e-6: not round-off, since the joint impulse's lever arms are taken at the step's midpoint
    pose while x x P moves with the end pose, an O(h v) difference per step, joints/stages.py), and the
    joints hold to round-off. In joint coordinates the kick is projected onto the trees' rates (the same
    exact impulsive reaction) and the joints hold by construction; reduced-rk4's own drift of the total
    momentum over the 0.2 s of tumbling (order 4, measured 1.3e-9 N s) sets its tolerance."""
    rods = []
    joints = []
    for k in range(3):
        rods.append(f"  - {{name: r{k}, particles: {{positions: [[-0.25, 0, 0], [0, 0, 0], [0.25, 0, 0]], "
                    f"masses: 0.3, radius: 0.02}}, position: [{0.5 * k}, 0, 0]}}")  # fmt: skip
        if k:
            joints.append(f"  - {{type: ball, bodies: [r{k - 1}, r{k}], anchor: [{0.5 * k - 0.25}, 0, 0]}}")
    text = (f"simulation: {{dt: 0.001, steps: 10, integrator: {integrator}}}\ngravity: [0, 0, 0]\nbodies:\n"
            + "\n".join(rods) + "\njoints:\n" + "\n".join(joints) + "\nforces:\n"
            "  - {type: impulse, body: r0, time: 0.05, point: [-0.25, 0, 0], vector: [0, 2, 1],"
            " frame: world}\n")  # fmt: skip
    sim = rbcli.Simulation(load_scene_text(text))
    J = np.array([0.0, 2.0, 1.0])
    tip = np.array([-0.25, 0.0, 0.0])
    P0 = sim.state.P.sum(axis=0)
    L0 = (np.cross(sim.state.x, sim.state.P) + sim.state.L).sum(axis=0)
    worst = 0.0
    for _ in range(20):
        sim.step(10)
        worst = max(worst, _rows(sim))
    s = sim.state
    np.testing.assert_allclose(s.P.sum(axis=0) - P0, J, rtol=0, atol=momentum_tolerance)
    np.testing.assert_allclose((np.cross(s.x, s.P) + s.L).sum(axis=0) - L0, np.cross(tip, J), rtol=0, atol=1e-5 * 0.56)
    assert np.abs(s.v[2]).max() > 0.1  # the kick reached the far rod through the joints
    assert worst <= 1e-12, worst


SPRING_SLIDER = """\
name: spring-on-a-slider
simulation: {{dt: {dt}, steps: {steps}, integrator: split2}}
bodies:
  - name: plate
    particles: {{positions: [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], masses: [1.0, 1.0, 0.5, 0.5]}}
    velocity: [0.0, 0.3, -0.2]
joints:
  - {{type: slider, bodies: [plate, world], anchor: [0, 0, 0], axis: [1, 0, 0]}}
forces:
  - {{type: spring, body: plate, point: [0, 0, 0], anchor: [-1, 0, 0], stiffness: 30, rest_length: 0.8, damping: 0}}
"""


def test_a_spring_on_a_slider_oscillates_at_sqrt_k_over_m_at_second_order():
    """A 3 kg plate on a slider along x (to the world), pulled by a spring (k = 30 N/m, rest length
    0.8 m) to the world point (-1, 0, 0) on the slider's line: x(t) = -0.2 + 0.2 cos(sqrt(k / M) t)
    exactly, from rest at x = 0 (the sideways velocity it is given is the slider's to take at once). Over
    1.25 periods the error falls at split2's second order, y and z stay 0 and the slider's rows hold to
    round-off: a spring force enters the joint stages' kick like any other."""
    omega = math.sqrt(30.0 / 3.0)
    duration = 1.25 * 2.0 * math.pi / omega  # ends where x crosses the centre: the phase error shows at first
    # order in it (at a turning point it would show squared, at h^4)
    errors = []
    for steps in (1000, 2000):
        dt = duration / steps
        sim = rbcli.Simulation(load_scene_text(SPRING_SLIDER.format(dt=dt, steps=steps)))
        worst = 0.0
        for k in range(10):
            sim.step(steps // 10)
            worst = max(worst, _rows(sim))
            t = (k + 1) * (steps // 10) * dt
            assert abs(sim.state.x[0, 0] - (-0.2 + 0.2 * math.cos(omega * t))) < 1e-3
        assert worst <= 1e-12, worst
        np.testing.assert_allclose(sim.state.x[0, 1:], 0.0, atol=1e-12)
        np.testing.assert_allclose(sim.state.v[0, 1:], 0.0, atol=1e-12)
        errors.append(abs(sim.state.x[0, 0] - (-0.2 + 0.2 * math.cos(omega * steps * dt))))
    order = math.log2(errors[0] / errors[1])
    assert 1.8 < order < 2.2, (errors, order)


def _reaction_balance(sim: rbcli.Simulation, steps: int, track: list | None = None) -> tuple[float, float]:
    """Over `steps` single steps (after a first one): the largest gap between each moving body's momentum
    change and gravity's plus its joints' reported reactions (Simulation.joint_reactions) times dt, in
    P [N s] and in L [N m s] (gravity acts at the centre of mass: no torque). split2 changes P and L by
    the forces' kick and the joints' impulses alone, so the gap is round-off when every joint's rows,
    motor, damper and limit are in its reaction."""
    table, dt = sim.model.joint, sim.dt
    mass, g = sim.model.body_mass, np.asarray(sim.forces.gravity)
    sim.step(1)
    gap_p = gap_l = 0.0
    for _ in range(steps):
        before = sim.state
        sim.step(1)
        after, reactions = sim.state, list(sim.joint_reactions.values())
        if track is not None:
            track.append(angle_and_rate(after.x[0], after.v[0])[0])
        dP = after.P - before.P - dt * mass[:, None] * g
        dL = after.L - before.L
        for j, wrench in enumerate(reactions):
            for end, body in enumerate((table.body_a[j], table.body_b[j])):
                if body >= 0:
                    dP[body] -= dt * wrench[end, :3]
                    dL[body] -= dt * wrench[end, 3:]
        moving = ~np.asarray(table.body_ground)
        gap_p = max(gap_p, float(np.abs(dP[moving]).max()))
        gap_l = max(gap_l, float(np.abs(dL[moving]).max()))
    return gap_p, gap_l


def test_joint_reactions_account_for_every_bodys_momentum_change():
    """Simulation.joint_reactions: the pendulum (a hinge to the world), the double pendulum (a joint
    between two bodies: its forces on them are equal and opposite), a pendulum swinging into a hinge limit,
    and the motor-driven four-bar (a loop whose redundant rows are dropped): each body's momentum change
    over a step is gravity's and its joints' reactions, to round-off."""
    pendulum = pendulum_text(math.pi / 3.0, 0.001, steps=10)
    limited = pendulum.replace("type: hinge, axis: [0, 1, 0]", "type: hinge, axis: [0, 1, 0], limits: [-0.8, 0.8]")
    scenes = {"pendulum": load_scene_text(pendulum), "limit": load_scene_text(limited)}
    root = Path(__file__).resolve().parents[2] / "scenes" / "joints"
    scenes |= {name: root / f"{name}.yaml" for name in ("double_pendulum", "four_bar")}
    for name, scene in scenes.items():
        sim = rbcli.Simulation(scene)
        assert set(sim.joint_reactions) == {j.name for j in sim.compiled.spec.joints}
        angles: list[float] = []
        gap_p, gap_l = _reaction_balance(sim, 800 if name == "limit" else 300, angles)
        assert gap_p < 1e-13 and gap_l < 1e-13, (name, gap_p, gap_l)
        if name == "limit":  # free, it would swing 2.09 rad from its start: the limit stopped it at 0.8
            swing = np.abs(np.array(angles) - math.pi / 3.0)
            assert 0.8 - 1e-3 < swing.max() < 0.8 + 1e-6, swing.max()
        if name == "double_pendulum":  # the elbow pulls the two arms equally and oppositely
            elbow = sim.joint_reactions["elbow"]
            np.testing.assert_allclose(elbow[1, :3], -elbow[0, :3], rtol=0, atol=1e-12 * np.abs(elbow).max())
    assert rbcli.Simulation(root.parent / "tutorial.yaml").joint_reactions == {}
