"""Which invariants a scene's force terms keep (physics/conservation.py), the labels `rbsim info` shows.

The rules come from dP/dt = F_ext and dL/dt = tau_ext about the origin: uniform gravity g adds M g to
dP/dt and M x_com x g to dL/dt, so P_i is kept where g_i = 0 and L_i only along g; internal spring pairs
cancel in both; damping, drag, pure torques, impulses and turning or scheduled forces do work. Three
cases are checked against a real run as well: what is called kept must stay constant to the
integrator's accuracy.
"""

from __future__ import annotations

import numpy as np
import pytest

from rbcli.api import conserved_invariants, force_terms, simulate
from rbcli.physics.energy import INVARIANT_NAMES
from rbcli.scene.load import load_scene_text

BODY = """\
  - name: {name}
    particles:
      positions: [[0.1, 0, 0], [-0.1, 0, 0], [0, 0.2, 0], [0, -0.2, 0], [0, 0, 0.3], [0, 0, -0.3]]
      masses: [1, 1, 0.5, 0.5, 0.25, 0.25]
    position: {position}
    velocity: [0.3, -0.2, 1.0]
    angular_momentum: [0.02, 0.05, 0.01]
"""


def scene(*, gravity: str = "", forces: str = "", bodies: int = 1) -> str:
    text = "name: c\nsimulation: {dt: 0.001, duration: 0.2, integrator: rk4}\n"
    text += f"gravity: {gravity}\n" if gravity else ""
    text += "bodies:\n" + "".join(
        BODY.format(name=f"b{i}", position=f"[{0.5 * i}, {0.1 * i}, 1.0]") for i in range(bodies)
    )
    return text + (f"forces:\n{forces}" if forces else "")


def kept(text: str) -> set[str]:
    spec = load_scene_text(text)
    labels = conserved_invariants(spec, INVARIANT_NAMES)
    return {name for name, is_kept in labels.items() if is_kept}


ENERGIES = {"energy_kinetic", "energy_potential", "energy_total"}
MOMENTA = {f"momentum_{a}" for a in "xyz"}
ANGULAR = {f"angular_momentum_{a}" for a in "xyz"} | {"angular_momentum_norm"}
SPRING = "  - {type: spring, bodies: [b0, b1], points: [[0.1, 0, 0], [-0.1, 0, 0]], stiffness: 50, damping: %s}\n"


def test_a_free_body_keeps_everything():
    assert kept(scene()) == set(INVARIANT_NAMES)


def test_gravity_changes_the_momentum_along_it_and_the_angular_momentum_across_it():
    # g = (0, 0, -9.81): P_x, P_y kept, P_z changes; tau = M x_com x g has no z component
    assert kept(scene(gravity="[0, 0, -9.81]")) == {
        "energy_total", "momentum_x", "momentum_y", "angular_momentum_z", "quaternion_norm_defect"
    }  # fmt: skip
    # a tilted g has no axis of its own among x, y, z: no angular momentum component is kept
    tilted = kept(scene(gravity="[3, 0, -9]"))
    assert tilted & ANGULAR == set() and tilted & MOMENTA == {"momentum_y"}


def test_springs_between_bodies_keep_the_momenta_and_only_undamped_ones_the_energy():
    undamped = kept(scene(bodies=2, forces=SPRING % 0))
    assert undamped == {"energy_total", *MOMENTA, *ANGULAR, "quaternion_norm_defect"}
    damped = kept(scene(bodies=2, forces=SPRING % 0.5))
    assert damped == {*MOMENTA, *ANGULAR, "quaternion_norm_defect"}


def test_external_terms_change_what_they_act_on():
    anchored = "  - {type: spring, body: b0, point: [0.1, 0, 0], anchor: [0, 0, 1], stiffness: 50}\n"
    assert kept(scene(forces=anchored)) == {"energy_total", "quaternion_norm_defect"}
    drag = "  - {type: drag, bodies: all, linear: 0.1}\n"
    assert kept(scene(forces=drag)) == {"energy_potential", "quaternion_norm_defect"}
    torque = "  - {type: torque, body: b0, vector: [0, 0, 0.2], frame: world}\n"
    assert kept(scene(forces=torque)) == {"energy_potential", *MOMENTA, "quaternion_norm_defect"}


POINT_FORCE = "  - {type: force, body: b0, point: [0.1, 0.2, 0], vector: [0, 2, 1], frame: %s}\n"


def test_a_constant_world_force_has_a_potential_and_a_turning_or_scheduled_one_does_not():
    # V = -f . (x + R r0) for a world-frame force (forces/point_force.py): the total energy is kept
    assert kept(scene(forces=POINT_FORCE % "world")) == {"energy_total", "quaternion_norm_defect"}
    assert kept(scene(forces=POINT_FORCE % "body")) == {"quaternion_norm_defect"}
    scheduled = POINT_FORCE.replace("frame: %s}", "frame: world, schedule: {start: 0.1, stop: 0.2}}")
    assert kept(scene(forces=scheduled)) == {"quaternion_norm_defect"}


def test_force_terms_are_named_as_the_scene_has_them():
    assert force_terms(load_scene_text(scene(gravity="[0, 0, -9.81]", bodies=2, forces=SPRING % 0))) == (
        "gravity",
        "spring",
    )


@pytest.mark.parametrize(
    "text",
    [scene(gravity="[0, 0, -9.81]"), scene(bodies=2, forces=SPRING % 0), scene(forces=POINT_FORCE % "world")],
    ids=["gravity", "internal-spring", "world-point-force"],
)
def test_what_is_called_kept_stays_constant_in_a_run(text):
    # rk4 at dt = 1e-3 over 0.2 s: energy error ~ (omega dt)^4 per unit time, far below 1e-8 relative;
    # momenta are kept to round-off by every method here (their updates are sums of equal and opposite
    # or axis-free terms)
    trajectory = simulate(load_scene_text(text))
    for name in kept(text):
        series = np.asarray(trajectory.invariants[name])
        scale = max(abs(series[0]), float(np.abs(series).max()), 1e-300)
        change = float(np.abs(series - series[0]).max())
        assert change <= 1e-8 * scale or change <= 1e-13, (name, change, scale)
