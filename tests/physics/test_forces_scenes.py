"""The example scenes in scenes/forces/ load, compile to the tables they describe, and behave as their
comments say (short runs with euler-matrix at a small dt, so only this repository's baseline is needed)."""

from pathlib import Path

import numpy as np
import pytest

from rbcli.api import load_scene, prepare, simulate
from rbcli.physics.forces import force_terms_present
from rbcli.physics.rotation import quat_to_matrix

SCENES = Path(__file__).resolve().parents[2] / "scenes" / "forces"

EXPECTED_TERMS = {
    "spring_pendulum.yaml": ("gravity", "spring"),
    "spring_chain.yaml": ("gravity", "spring", "drag"),
    "spinning_top.yaml": ("gravity", "spring"),
    "pushed_box.yaml": ("point_force", "torque"),
    "projectile_drag.yaml": ("gravity", "drag"),
    "impulse_kick.yaml": ("impulse",),
}


def test_every_example_is_listed():
    assert sorted(p.name for p in SCENES.glob("*.yaml")) == sorted(EXPECTED_TERMS)


@pytest.mark.parametrize("name", sorted(EXPECTED_TERMS))
def test_example_loads_and_compiles_to_its_terms(name):
    path = SCENES / name
    assert path.read_text().startswith("# yaml-language-server: $schema=../../schemas/scene.schema.json\n")
    compiled = prepare(load_scene(path))
    assert force_terms_present(compiled.forces, compiled.model.contact) == EXPECTED_TERMS[name]


def test_spinning_top_precesses_at_the_gyroscopic_rate():
    """Mean azimuth rate of the symmetry axis ~ M g d / (I3 w3) = 1.51 rad/s, in the sense of the
    gravity torque; the released top's nutation raises the mean by O(M g d I_tip / (I3 w3)^2) ~ 8%,
    so 15%. The stiff pivot keeps the tip within 1 mm of the anchor (static sag M g / k = 0.1 mm)."""
    traj = simulate(SCENES / "spinning_top.yaml", integrator="euler-matrix", dt=2e-5, duration=1.0, record_every=50)
    axis = quat_to_matrix(traj.q[:, 0])[..., :, 2]
    azimuth = np.unwrap(np.arctan2(axis[:, 1], axis[:, 0]))
    rate = np.polyfit(traj.t, azimuth, 1)[0]
    assert rate == pytest.approx(9.81 * 0.2775 / (0.018 * 100), rel=0.15)
    tip = traj.x[:, 0] - 0.2775 * axis
    assert np.abs(tip).max() < 1e-3


def test_pushed_box_gets_the_pulse_impulse():
    """Momentum after the triangular pulse = 10 N x 0.5 s in +y. Euler's left Riemann sum of a
    piecewise-linear s(t) with knots on the step grid is exact up to dt/2 (s(end) - s(start)) = 0."""
    traj = simulate(SCENES / "pushed_box.yaml", integrator="euler-matrix", duration=2.0)
    np.testing.assert_allclose(traj.P[-1, 0], [0.0, 5.0, 0.0], rtol=0, atol=1e-12)
    assert traj.omega[-1, 0, 2] > 0.0  # pushed +y at the +x end: spins counter-clockwise about z


def test_drag_shortens_the_projectile():
    traj = simulate(SCENES / "projectile_drag.yaml", integrator="euler-matrix")
    peak = traj.x[:, :, 2].max(axis=0)
    assert peak[0] == pytest.approx(30.0**2 / (4 * 9.81), rel=1e-3)  # (v0 sin 45)^2 / (2 g)
    assert peak[1] < 0.9 * peak[0] and traj.x[-1, 1, 0] < 0.8 * traj.x[-1, 0, 0]
