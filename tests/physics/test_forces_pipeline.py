"""The step models only what a scene names, by construction: tables list only the terms and bodies a
scene touches, the wrench's stage counters (`term_evaluations`) count exactly their rows, and a
torque-free scene never writes tau. Plus the compile-time errors, each located."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import make_body, make_scene, random_bodies

from rbcli.api import prepare
from rbcli.physics.forces import TERM_NAMES, force_terms_present
from rbcli.physics.forces.tables import make_force_data, table_rows
from rbcli.physics.forces.wrench import accumulate_wrench
from rbcli.runner.simulation import Simulation
from rbcli.scene.force_specs import (
    BodyPoint,
    ForceAtPoint,
    ForceDrag,
    ForceField,
    ForceImpulse,
    ForceSpring,
    ForceTorque,
    Schedule,
)
from rbcli.scene.spec import SceneError, SourceLocation

G = np.array([0.0, 0.0, -9.81])
STEPS = 20


def run_and_count(forces, bodies=10, gravity=G):  # noqa: ANN001, ANN201
    """Compile, run STEPS euler-matrix steps (1 wrench evaluation each), return (compiled, counts)."""
    scene = replace(make_scene(random_bodies(bodies), dt=1e-3, duration=STEPS * 1e-3, gravity=gravity),
                    forces=tuple(forces))  # fmt: skip
    compiled = prepare(scene)
    sim = Simulation(compiled)
    sim.step(STEPS)
    return compiled, dict(zip(TERM_NAMES, sim.data.force.term_evaluations.tolist(), strict=True))


def test_gravity_only_scene_evaluates_gravity_and_nothing_else():
    compiled, counts = run_and_count([])
    tables = compiled.forces
    assert force_terms_present(tables, None) == ("gravity",)
    assert not tables.has_torque
    for name in ("schedule", "field", "point_force", "torque", "spring", "drag", "impulse"):
        assert table_rows(getattr(tables, name)) == 0, name
    assert counts == {**dict.fromkeys(TERM_NAMES, 0), "gravity": STEPS * 10}


def test_empty_scene_evaluates_no_term():
    compiled, counts = run_and_count([], gravity=None)
    assert force_terms_present(compiled.forces, compiled.model.contact) == ()
    assert set(counts.values()) == {0}


def test_one_spring_on_one_body_of_ten_touches_one_row():
    spring = ForceSpring(end_a=BodyPoint(body="b3", point=np.array([0.1, 0.0, 0.0])), anchor=np.zeros(3), stiffness=1.0)
    compiled, counts = run_and_count([spring])
    assert force_terms_present(compiled.forces, compiled.model.contact) == ("gravity", "spring")
    assert compiled.forces.spring.body_a.tolist() == [3]
    assert counts == {**dict.fromkeys(TERM_NAMES, 0), "gravity": STEPS * 10, "spring": STEPS}


def test_particle_field_visits_only_the_particles_of_the_bodies_it_names():
    """Particle world positions are computed for the named bodies' particles only (5 per body here)."""
    field = ForceField(per="particle", bodies=("b1", "b7"), value=np.array([0.0, 1.0, 0.0]))
    compiled, counts = run_and_count([field], gravity=None)
    assert compiled.forces.field.body.tolist() == [1, 7]
    particles = int(compiled.model.body_particle_count[[1, 7]].sum())
    assert particles == 10 < compiled.model.particle_count
    assert counts == {**dict.fromkeys(TERM_NAMES, 0), "field": STEPS * particles}


def test_every_term_counts_exactly_its_rows():
    forces = [
        ForceField(per="mass", bodies=("b0",), value=np.ones(3)),
        ForceAtPoint(at=BodyPoint(body="b2", point=np.ones(3)), vector=np.ones(3)),
        ForceTorque(body="b4", vector=np.ones(3)),
        ForceTorque(body="b5", vector=np.ones(3), schedule=Schedule(start=1.0)),  # never active in 20 ms
        ForceSpring(end_a=BodyPoint(body="b1"), end_b=BodyPoint(body="b2"), stiffness=1.0),
        ForceDrag(bodies=("b8", "b9"), linear=0.1),
        ForceImpulse(at=BodyPoint(body="b6"), time=0.0, vector=np.ones(3)),
    ]
    compiled, counts = run_and_count(forces)
    assert force_terms_present(compiled.forces, compiled.model.contact) == tuple(
        n for n in TERM_NAMES if n != "contact"
    )  # no contact section
    # the impulse row: the runner's call of apply_impulses is pending (docs/forces.md), so 0 or 1
    assert counts.pop("impulse") in (0, 1)
    assert counts == {"gravity": STEPS * 10, "field": STEPS * 5, "point_force": STEPS, "torque": STEPS,
                      "spring": STEPS, "drag": 2 * STEPS, "contact": 0}  # fmt: skip


def test_torque_free_scenes_never_write_tau():
    """has_torque False: the wrench must leave tau untouched; a NaN sentinel in tau would show any write."""
    torque_free = [
        ForceSpring(end_a=BodyPoint(body="b0"), anchor=np.zeros(3), stiffness=5.0, damping=1.0),
        ForceSpring(end_a=BodyPoint(body="b1"), end_b=BodyPoint(body="b2"), stiffness=5.0, rest_length=1.0),
        ForceAtPoint(at=BodyPoint(body="b3"), vector=np.ones(3), schedule=Schedule(kind="sine", frequency=1.0)),
        ForceDrag(linear=0.1, quadratic=0.2),
        ForceImpulse(at=BodyPoint(body="b1", point=np.ones(3)), time=0.5, vector=np.ones(3)),
    ]
    compiled = prepare(replace(make_scene(random_bodies(4), gravity=G), forces=tuple(torque_free)))
    assert not compiled.forces.has_torque
    s = compiled.initial_state
    F, tau = np.full((4, 3), np.nan), np.full((4, 3), np.nan)
    force_data, km = make_force_data(compiled.model), compiled.model.kernel()
    accumulate_wrench(km, compiled.forces, km.contact, force_data, 0.1, s.x, s.q, s.P, s.L, F, tau)
    assert np.isfinite(F).all() and np.isnan(tau).all()


@pytest.mark.parametrize(
    "spec",
    [
        ForceField(value=np.ones(3)),
        ForceAtPoint(at=BodyPoint(body="b0", particle=1), vector=np.ones(3)),
        ForceTorque(body="b0", vector=np.ones(3)),
        ForceSpring(end_a=BodyPoint(body="b0", point=np.array([0.0, 0.0, 1.0])), anchor=np.zeros(3), stiffness=1.0),
        ForceDrag(angular_linear=0.1),
    ],
)
def test_terms_that_can_turn_a_body_switch_torque_on(spec):
    assert prepare(replace(make_scene(random_bodies(2)), forces=(spec,))).forces.has_torque


def test_zero_drag_adds_no_rows():
    compiled = prepare(replace(make_scene(random_bodies(3)), forces=(ForceDrag(bodies=None),)))
    assert force_terms_present(compiled.forces, compiled.model.contact) == ()


HERE = SourceLocation("scene.yaml", 12, 5)


@pytest.mark.parametrize(
    "spec, message",
    [
        (ForceTorque(body="nobody", vector=np.ones(3), location=HERE), "no body named 'nobody'"),
        (ForceAtPoint(at=BodyPoint(body="h", particle=4), vector=np.ones(3), location=HERE), "particle 4"),
        (ForceAtPoint(at=BodyPoint(body="h", point=np.ones(3), particle=0), vector=np.ones(3), location=HERE),
         "either a point or a particle"),
        (ForceAtPoint(at=BodyPoint(body="h"), vector=np.ones(3), frame="local", location=HERE), "frame must be"),
        (ForceAtPoint(at=BodyPoint(body="h"), vector=np.array([1.0, np.nan, 0.0]), location=HERE), "finite"),
        (ForceSpring(end_a=BodyPoint(body="h"), stiffness=1.0, location=HERE), "exactly one of"),
        (ForceSpring(end_a=BodyPoint(body="h"), anchor=np.zeros(3), stiffness=-1.0, location=HERE), "stiffness"),
        (ForceSpring(end_a=BodyPoint(body="h"), end_b=BodyPoint(body="h"), stiffness=1.0, location=HERE),
         "both ends"),
        (ForceDrag(bodies=("h", "h"), linear=1.0, location=HERE), "listed twice"),
        (ForceField(per="volume", location=HERE), "per must be"),
        (ForceTorque(body="h", vector=np.ones(3), schedule=Schedule(kind="square"), location=HERE), "kind"),
        (ForceTorque(body="h", vector=np.ones(3), schedule=Schedule(start=2.0, stop=1.0), location=HERE),
         "start < stop"),
        (ForceTorque(body="h", vector=np.ones(3), location=HERE,
                     schedule=Schedule(kind="piecewise_linear", times=(1.0, 0.0), values=(0.0, 1.0))), "not decrease"),
    ],
)  # fmt: skip
def test_invalid_force_specs_are_reported_with_their_location(spec, message):
    with pytest.raises(SceneError) as info:
        prepare(replace(make_scene([make_body("h")]), forces=(spec,)))
    (issue,) = info.value.issues
    assert issue.location == HERE and message in issue.message, issue.message
    assert str(issue).startswith("scene.yaml:12:5: error: force ")


def test_every_invalid_spec_is_reported_at_once():
    specs = (ForceTorque(body="x", vector=np.ones(3)), ForceDrag(bodies=("y",), linear=1.0))
    with pytest.raises(SceneError) as info:
        prepare(replace(make_scene([make_body("h")]), forces=specs))
    assert len(info.value.issues) == 2
