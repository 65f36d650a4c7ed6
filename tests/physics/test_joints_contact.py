"""Joints with contact (issue 27 item 3): the two bodies of a joint do not collide unless the joint says
`collide: true`; other pairs still do; the brute-force reference applies the same exclusion."""

from __future__ import annotations

import numpy as np
import pytest

import rbcli
from rbcli.physics.contact.force import accumulate_contact, hold_static_bodies
from rbcli.physics.contact.reference import contact_wrench_numpy
from rbcli.physics.contact.tables import STAT_CONTACTS, make_contact_work
from rbcli.scene.load import load_scene_text


def _overlapping(collide: str, cloud: bool) -> str:
    """Balls a and b (r = 0.1 m) 0.15 m apart, ball-jointed at their midpoint, and ball c overlapping b
    (0.15 m apart too), not jointed; no gravity. cloud: each ball a 3-sphere cloud (the body level on)."""

    def body(name: str, x: float) -> str:
        if cloud:
            geometry = "positions: [[0, 0, 0], [0, 0.01, 0], [0, 0, 0.01]], masses: [0.3, 0.3, 0.3], radius: 0.1"
        else:
            geometry = "positions: [[0, 0, 0]], masses: [1.0], radius: [0.1]"
        return f"  - {{name: {name}, particles: {{{geometry}}}, position: [{x}, 0, 0]}}\n"

    return ("simulation: {dt: 0.0001, steps: 10, integrator: split2}\ngravity: [0, 0, 0]\n"
            "contact: {material: {restitution: 0.5, friction: 0.3}}\nbodies:\n"
            + body("a", 0.0) + body("b", 0.15) + body("c", 0.3)
            + f"joints:\n  - {{type: ball, bodies: [a, b], anchor: [0.075, 0, 0]{collide}}}\n")  # fmt: skip


@pytest.mark.parametrize("cloud", [False, True], ids=["spheres", "clouds"])
@pytest.mark.parametrize("collide", ["", ", collide: false", ", collide: true"])
def test_jointed_bodies_do_not_collide_unless_asked_and_others_still_do(collide, cloud):
    """The force stage's contacts and wrench equal the brute-force reference's; the jointed pair (a, b)
    feels no contact force (a's wrench is zero) unless collide: true, while the unjointed pair (b, c)
    always does."""
    sim = rbcli.Simulation(load_scene_text(_overlapping(collide, cloud)))
    contact = sim.model.contact
    work = make_contact_work(contact, sim.model.body_count)
    s = sim.data.state
    F, tau = np.zeros_like(s.x), np.zeros_like(s.x)
    accumulate_contact(sim.model.kernel_bodies(), contact, work, 0.0, s.x, s.q, s.P, s.L, F, tau)
    hold_static_bodies(contact, F, tau)
    F_ref, tau_ref, found = contact_wrench_numpy(sim.model, contact, s.x, s.q, s.P, s.L)
    spheres = 3 if cloud else 1
    pairs = 2 if collide.endswith("true") else 1
    assert work.stats[STAT_CONTACTS] == found == pairs * spheres * spheres
    scale = np.abs(F_ref).max()
    assert scale > 0.0
    np.testing.assert_allclose(F, F_ref, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(tau, tau_ref, rtol=0, atol=1e-12 * scale)
    if collide.endswith("true"):
        assert F[0, 0] < -0.1 * scale  # a is pushed away from b
    else:
        assert np.all(F[0] == 0.0) and np.all(tau[0] == 0.0)
    assert F[2, 0] > 0.1 * scale  # c is pushed away from b


def test_the_reference_without_the_exclusion_would_see_the_jointed_pair():
    """The test above can fail: the same scene with the exclusion list emptied finds the jointed pair."""
    sim = rbcli.Simulation(load_scene_text(_overlapping("", False)))
    contact = sim.model.contact._replace(excluded_pair=np.zeros(0, dtype=np.int64))
    s = sim.data.state
    assert contact_wrench_numpy(sim.model, contact, s.x, s.q, s.P, s.L)[2] == 2


def test_a_scene_without_joints_excludes_nothing():
    sim = rbcli.Simulation(load_scene_text(_overlapping("", False).split("joints:")[0]))
    assert sim.model.contact.excluded_pair.shape == (0,)
