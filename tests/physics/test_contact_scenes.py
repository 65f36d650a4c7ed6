"""The example scenes of scenes/contact/ load, run stably, and do what their comments say.

Short runs keep the suite fast; each check is a physical claim of the scene's header (a brick settles
flat, the balls separate at their restitution, the pile stays in its box, the dominoes all fall).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import rbcli
from rbcli.physics.rotation import quat_to_matrix

SCENES = Path(__file__).resolve().parents[2] / "scenes" / "contact"
EXPECTED = {"box_drop", "box_stack", "container_mix", "dominoes", "head_on", "newtons_cradle", "poured_capsules",
            "shaker", "sphere_pile"}  # fmt: skip


def test_the_contact_scenes_are_these():
    assert {p.stem for p in SCENES.glob("*.yaml")} == EXPECTED


def energy(sim: rbcli.Simulation, g: float = 9.81) -> float:
    s = sim.state
    m = sim.model.body_mass
    stored = float(sim.data.force.contact.stats[2])
    return float(0.5 * (m[:, None] * s.v**2).sum() + 0.5 * (s.omega * s.L).sum() + g * (m * s.x[:, 2]).sum()) + stored


@pytest.mark.parametrize("name", sorted(EXPECTED - {"box_drop", "head_on", "shaker"}))
def test_scene_runs_stably(name):
    """The first 0.2 s: finite, the energy never above its start (contacts only dissipate), inside its box."""
    sim = rbcli.Simulation(SCENES / f"{name}.yaml")
    steps = int(round(0.2 / sim.dt))
    start = energy(sim)
    for _ in range(10):
        sim.step(steps // 10)
        assert energy(sim) <= start + 1e-9 * abs(start)
    assert np.isfinite(sim.state.x).all()
    if sim.compiled.spec.contact.planes:
        assert sim.state.x[:, 2].min() > 0.0


def test_shaker_throws_the_balls_then_they_settle():
    """The plate follows z = 0.1 + A sin(2 pi f t) exactly while it shakes (2.7 g peak: the balls fly
    higher than its whole stroke), then stops at 0.1 m, and the balls stop bouncing and stay on it (one
    may roll on slowly: there is no rolling resistance, docs/contact.md)."""
    sim = rbcli.Simulation(SCENES / "shaker.yaml")
    amplitude, frequency = 0.003, 15.0
    highest = 0.0
    for _ in range(60):  # 1.5 s of shaking
        sim.step(50)
        t = sim.time
        assert sim.data.state.x[0, 2] == pytest.approx(0.1 + amplitude * np.sin(2 * np.pi * frequency * t), abs=1e-14)
        highest = max(highest, float(sim.state.x[1:, 2].max() - sim.state.x[0, 2]))
    assert highest - 0.04 > 3 * amplitude  # a ball's bottom well above the plate's top (0.02 + 0.02 m)
    sim.step(sim.compiled.settings.steps - sim.data.state.step)
    assert sim.data.state.x[0, 2] == pytest.approx(0.1, abs=1e-14)
    assert np.abs(sim.state.v[1:, 2]).max() < 1e-4 and np.linalg.norm(sim.state.v[1:], axis=1).max() < 0.01
    assert (sim.state.x[1:, 2] > 0.1).all()


def test_box_drop_settles_flat():
    sim = rbcli.Simulation(SCENES / "box_drop.yaml")
    sim.step(sim.compiled.settings.steps)
    up = np.abs(quat_to_matrix(sim.state.q[0])[2])
    assert up.max() > np.cos(np.radians(1.0)) and np.linalg.norm(sim.state.v[0]) < 1e-3
    assert sim.state.x[0, 2] == pytest.approx(0.025, abs=1e-3)


def test_box_stack_stands():
    """Ten boxes touching as boxes: after they settle (1 s) the top one moves < 1 mm in the 9 s left, and
    no box moves sideways."""
    sim = rbcli.Simulation(SCENES / "box_stack.yaml")
    sim.step(1000)
    settled = sim.state.x.copy()
    sim.step(sim.compiled.settings.steps - 1000)
    assert np.abs(sim.state.x - settled).max() < 1e-3
    assert np.abs(sim.state.x[:, :2]).max() < 1e-9


def test_head_on_balls_separate_at_their_restitution():
    sim = rbcli.Simulation(SCENES / "head_on.yaml")
    P0 = sim.state.P.sum(axis=0)
    sim.step(sim.compiled.settings.steps)
    np.testing.assert_allclose(sim.state.P.sum(axis=0), P0, atol=1e-14)
    assert sim.state.v[1, 0] - sim.state.v[0, 0] == pytest.approx(0.8 * 2.0, rel=0.05)
    assert np.abs(sim.state.omega).max() < 1e-12  # frictionless: no spin (the lattice centre is ~1e-18 m off)


@pytest.mark.parametrize("suffix", [".mcap", ".rrd"])
def test_contact_invariants_are_recorded(tmp_path, suffix):
    """Contact count, deepest overlap and the springs' energy per frame, in both formats; the total
    energy (the springs' included) never rises while the brick bounces and settles."""
    compiled = rbcli.prepare(SCENES / "box_drop.yaml", duration=1.0)
    rbcli.run_to_file(compiled, tmp_path / f"box{suffix}")
    invariants = rbcli.read_recording(tmp_path / f"box{suffix}").invariants
    count, overlap = invariants["contact_count"], invariants["contact_max_overlap"]
    # lying on its 0.2 x 0.1 face: the 4 corners of its box (issue 47 slice 2; its 16 x 8 lattice spheres before)
    assert count[0] == 0 and count[-1] == 4
    assert 0 < overlap[-1] < 0.01 * 0.025  # under 1 % of its half thickness at rest (the sink is 0.25 %)
    energy = invariants["energy_total"]
    assert np.all(np.diff(energy) <= 1e-9 * abs(energy[0]))


def test_no_shipped_scene_warns_about_its_contacts_or_its_cost():
    """Issue 47 item 4: every shipped scene with contact (scenes/**, sweeps aside) validates without a
    warning of its contacts (the stable step, a deep impact, the sub-steps a speed needs) or of its run's
    cost. The joints' redundant rows of the door and the four-bar are what those scenes show, and stay."""
    root = SCENES.parent
    contact_scenes = [p for p in sorted(root.rglob("*.yaml")) if not p.name.endswith(".sweep.yaml")
                      and "contact:" in p.read_text()]  # fmt: skip
    assert len(contact_scenes) >= 12
    for path in contact_scenes:
        warnings = [w.message for w in rbcli.prepare(path).warnings if "repeat constraints" not in w.message]
        assert not warnings, (path.name, warnings)


def test_poured_capsules_pile_up_in_their_box_at_rest_without_sinking():
    """scenes/contact/poured_capsules.yaml (issue 47 item 4): 60 capsules dropped from 0.3-0.9 m into a
    0.6 m box, touching as capsules with the default (landing) stiffness. After 3 s every capsule is at
    rest (< 1 mm/s; measured 6e-6 m/s), inside the box, its segment's ends no deeper into the floor or a
    wall than 10 % of its radius at any of the 30 checks (measured 0.9 %), and the pile is lower than
    the lowest layer started (every centre below 0.3 m)."""
    from rbcli.physics.rotation import quat_rotate

    sim = rbcli.Simulation(SCENES / "poured_capsules.yaml")
    contact = sim.model.contact
    assert np.count_nonzero(contact.primitive_kind >= 0) == 60
    deepest = 0.0
    for _ in range(30):
        sim.step(100)
        s = sim.data.state
        centre = s.x + quat_rotate(s.q, contact.primitive_offset)
        axis = quat_rotate(s.q, contact.primitive_rotation[:, :, 2])
        radius, half = contact.primitive_size[:, 0], contact.primitive_size[:, 1]
        for end in (centre - half[:, None] * axis, centre + half[:, None] * axis):
            into_floor = radius - end[:, 2]
            into_wall = np.abs(end[:, :2]).max(axis=1) + radius - 0.3
            deepest = max(deepest, float((np.maximum(into_floor, into_wall) / radius).max()))
    assert sim.time > 2.99
    assert deepest <= 0.1, deepest
    assert np.linalg.norm(sim.state.v, axis=1).max() < 1e-3
    assert (sim.state.x[:, 2] < 0.3).all() and (np.abs(sim.state.x[:, :2]) < 0.3).all()
