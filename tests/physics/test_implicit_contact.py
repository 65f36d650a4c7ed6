"""reduced-implicit: contact springs and dashpots linearly implicit (tree/implicit_contact.py), so a stiff
contact runs at steps several times its explicit stable step with no sub-steps.

Every scene here is one kind (free shape bodies as one-link trees, primitives, gravity, a plane), so the
file compiles one loop. Each test runs at a step above the contacts' explicit stable step (asserted from
the compiled scene: explicit Euler is unstable there) and checks closed forms: the static sink of a body
on its springs, Coulomb's slope law (held below tan a = mu, sliding at g (sin a - mu cos a) above it),
and momentum to round-off in an impact of two bodies. The capsule ragdoll (scenes/joints/capsule_ragdoll.yaml,
which names reduced-implicit) is tested in test_joints_contact_scenes.py: its limits and cones take part
in the contact solve there.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import rbcli
from rbcli.physics.contact.tables import STAT_CONTACTS
from rbcli.scene.load import load_scene_text

G = 9.81
BOX = "shape: {type: box, size: [0.2, 0.1, 0.05]}, spacing: 0.0125, density: 600"
CAPSULE = "shape: {type: capsule, radius: 0.03, height: 0.12, axis: y}, spacing: 0.01, density: 800"
STIFF = 1e7  # [N/m] per contact point: the explicit stable step of these bodies is ~0.1-0.3 ms


def test_the_kept_contacts_and_the_solve_s_rows_fit_their_arrays():
    """The columns implicit_rows.py and implicit_contact.py write fit the widths contact/tables.py allocates
    (numpy only, so it cannot import them)."""
    from rbcli.physics.contact import implicit_rows
    from rbcli.physics.contact.tables import IMPLICIT_COLUMNS, IMPLICIT_ROW_COLUMNS
    from rbcli.physics.tree import implicit_contact

    kept = [v for k, v in vars(implicit_rows).items() if k.startswith("IMP_")]
    assert max(kept) + 3 <= IMPLICIT_COLUMNS  # the last is a vector (IMP_FT_LAW)
    rows = [v for k, v in vars(implicit_contact).items() if k.startswith("ROW_")]
    assert max(rows) < IMPLICIT_ROW_COLUMNS


def scene(bodies: str, contact: str, *, dt: float = 2e-3) -> rbcli.Simulation:
    text = (
        f"name: t\nsimulation: {{dt: {dt!r}, steps: 1, integrator: reduced-implicit}}\n"
        "gravity: [0, 0, -9.81]\ncontact:\n" + contact + "  substeps: 1\nbodies:\n" + bodies + "\n"
    )
    sim = rbcli.Simulation(load_scene_text(text))
    # the step is above the explicit stable step: an explicit step would gain energy in every contact
    assert sim.compiled.settings.substeps == 1 and dt > 3.0 * sim.compiled.contact.stable_step
    return sim


def test_a_stiff_capsule_lands_and_rests_at_its_static_sink():
    """Dropped 0.3 m at dt = 2 ms (about 10 explicit stable steps): it lands, comes to rest on its two end
    balls and sinks M g / (2 k), the springs' static balance (at rest the correction is zero, so the rest
    is the explicit law's own), and never gains energy over its fall."""
    r = 0.03
    sim = scene(f"  - {{name: rod, {CAPSULE}, position: [0, 0, 0.3]}}",
                f"  ground: 0\n  material: {{stiffness: {STIFF}, restitution: 0.3, friction: 0.5}}\n")  # fmt: skip
    m = float(sim.model.body_mass[0])
    start = m * G * 0.3
    for _ in range(50):
        sim.step(10)
        z, v = float(sim.state.x[0, 2]), sim.state.v[0]
        energy = 0.5 * m * float(v @ v) + m * G * z
        assert energy <= start + 1e-9, energy  # no step gains energy (kinetic + potential, springs aside)
    assert sim.data.force.contact.stats[STAT_CONTACTS] == 2
    assert np.linalg.norm(sim.state.v[0]) < 1e-6
    assert r - float(sim.state.x[0, 2]) == pytest.approx(m * G / (2 * STIFF), rel=1e-6)


@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_a_stiff_box_on_a_slope_is_held_below_tan_mu_and_slides_at_g_sin_minus_mu_cos_above(ratio):
    """A box on its face on a plane tilted to tan a = ratio mu, dt = 2 ms (4 x the explicit slope test's):
    held by its four sticking corners (no creep) at 0.8, sliding at g (sin a - mu cos a) at 1.25 (1 %):
    its sliding corners' friction follows their normal force inside the solve."""
    mu = 0.5
    a = math.atan(ratio * mu)
    normal = np.array([-math.sin(a), 0.0, math.cos(a)])
    downhill = -np.array([math.cos(a), 0.0, math.sin(a)])
    contact = (f"  planes: [{{point: [0, 0, 0], normal: {normal.tolist()}, friction: {mu}}}]\n"
               f"  material: {{stiffness: {STIFF}, friction: {mu}}}\n")  # fmt: skip
    tilt = f"orientation: {{axis_angle: {{axis: [0, 1, 0], angle: {-math.degrees(a)}, degrees: true}}}}"
    sim = scene(f"  - {{name: box, {BOX}, position: {(0.025 * normal).tolist()}, {tilt}}}", contact)
    sim.step(100)  # settle onto the plane
    assert sim.data.force.contact.stats[STAT_CONTACTS] == 4
    s0, u0 = float(sim.state.x[0] @ downhill), float(sim.state.v[0] @ downhill)
    steps = 400
    sim.step(steps)
    t = steps * 2e-3
    travelled = float(sim.state.x[0] @ downhill) - s0
    if ratio < 1:
        assert abs(travelled) < 1e-4
    else:
        accel = G * (math.sin(a) - mu * math.cos(a))
        assert travelled == pytest.approx(u0 * t + 0.5 * accel * t * t, rel=0.01)
        assert sim.data.force.contact.stats[STAT_CONTACTS] == 4


def test_two_stiff_spheres_meeting_keep_their_momentum_and_do_not_pass():
    """Two spheres (exact spheres, 1 : 2 in mass) meeting head-on in free fall, frictionless: the implicit
    solve's forces are equal and opposite and central, so nothing turns and the momentum changes by
    gravity alone, M g t, to round-off (a free root's update is exact without rotation); they part, the
    light one rebounding, and never pass each other. (A capsule resting on the ground far away keeps this
    file's one kind of scene.)"""
    contact = f"  ground: 0\n  material: {{stiffness: {STIFF}, restitution: 0.5, friction: 0.0}}\n"
    bodies = (f"  - {{name: rod, {CAPSULE}, position: [5, 0, 0.03]}}\n"
              "  - {name: a, shape: {type: sphere, radius: 0.05}, count: 50, mass: 1.0, position: [-0.2, 0, 2],"
              " velocity: [3, 0, 0]}\n"
              "  - {name: b, shape: {type: sphere, radius: 0.05}, count: 50, mass: 2.0, position: [0.2, 0, 2],"
              " velocity: [-1, 0, 0]}")  # fmt: skip
    sim = scene(bodies, contact)
    m = sim.model.body_mass[1:]
    before = sim.state.P[1:].sum(axis=0)
    touched = False
    for k in range(1, 101):
        sim.step(2)
        touched = touched or sim.data.force.contact.stats[STAT_CONTACTS] > 2
        assert sim.state.x[1, 0] < sim.state.x[2, 0]  # a stays on its side of b
        expected = before + np.array([0.0, 0.0, -G * m.sum() * 2 * k * 2e-3])
        assert np.abs(sim.state.P[1:].sum(axis=0) - expected).max() <= 1e-12 * np.abs(before).max()
        assert np.abs(sim.state.omega[1:]).max() < 1e-12  # round-off in the contact point only
    assert touched
    assert sim.state.v[1, 0] < 0.0 < sim.state.v[2, 0]  # they parted


def test_contacts_past_the_solve_s_capacity_keep_their_force_and_the_run_says_so(tmp_path):
    """36 boxes resting on the ground touch at 4 corners each, 144 contacts a step, past the solve's 128: the
    rest keep their explicit force (the boxes still rest, at this moderate stiffness), the count is kept,
    and `rbsim run` warns, naming the capacity."""
    from typer.testing import CliRunner

    from rbcli.cli.app import app
    from rbcli.physics.contact.tables import IMPLICIT_CAPACITY

    boxes = "\n".join(
        f"  - {{name: b{i}, {BOX}, position: [{0.3 * (i % 6)}, {0.3 * (i // 6)}, 0.025]}}" for i in range(36)
    )
    text = (
        "name: t\nsimulation: {dt: 0.001, duration: 0.05, integrator: reduced-implicit}\n"
        "gravity: [0, 0, -9.81]\ncontact:\n  ground: 0\nbodies:\n" + boxes + "\n"
    )
    path = tmp_path / "boxes.yaml"
    path.write_text(text)
    result = CliRunner().invoke(app, ["run", str(path), "-o", str(tmp_path / "boxes.mcap")])
    assert result.exit_code == 0, result.output
    assert f"past the implicit solve's {IMPLICIT_CAPACITY} contacts a step" in result.output, result.output
    sim = rbcli.Simulation(load_scene_text(text))
    sim.step(20)  # settled on every corner
    before = int(sim.data.force.contact.implicit_count[1])
    sim.step(10)
    assert sim.data.force.contact.implicit_count[1] - before == 10 * (4 * 36 - IMPLICIT_CAPACITY)
    assert np.abs(sim.state.v).max() < 1e-3
