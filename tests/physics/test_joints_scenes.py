"""The example scenes of scenes/joints/: each holds its joints to round-off; the four-bar (a loop of four
spatial hinges, 3 redundant rows, driven by a motor) warns which rows, still runs and closes to
round-off; the double
pendulum's energy error stays bounded through its chaotic motion."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rbcli.physics.joints.reference import joint_rows_numpy
from rbcli.runner.simulation import Simulation
from rbcli.scene.load import check_scene

SCENES = Path(__file__).resolve().parents[2] / "scenes" / "joints"


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENES.glob("*.yaml")))
def test_every_joint_scene_holds_its_joints_to_round_off(name):
    """200 steps, then every row's residual from the state (numpy twin) <= 1e-12 m or rad. On one thread,
    as jointed scenes run by default since the serial-loop rule (runner/threads.py chunk_threads): the
    threaded loop with joint stages is ~80 s of numba that no other test compiles."""
    sim = Simulation(SCENES / f"{name}.yaml", threads=1)
    sim.step(200)
    s = sim.data.state
    residual = joint_rows_numpy(sim.model.joint, s.x, s.q)[0]
    assert np.abs(residual).max() <= 1e-12, np.abs(residual).max()


def test_the_four_bar_loop_warns_of_its_redundant_rows_and_still_closes_to_round_off():
    """Four hinges about y on a planar loop constrain the out-of-plane motion twice: the last hinge's
    out-of-plane anchor row (1) and both axis rows (3, 4) repeat the others. validate warns naming them;
    the run drops redundant rows every step, never more than those 3 (stats; how many of the 3 fall under
    the pivot tolerance varies from step to step: 1, 2 or 3 of 3,000 steps measured), and the loop closes
    to round-off while the motor at A turns the crank at its 2 rad/s (its 3 N m cap is enough against
    gravity, so the speed is held exactly)."""
    issues = check_scene(SCENES / "four_bar.yaml")
    assert [i.severity for i in issues] == ["warning"]
    assert "joint 'D': 3 of its 5 rows (rows 1, 3, 4) repeat constraints of earlier joints" in issues[0].message
    sim = Simulation(SCENES / "four_bar.yaml")
    start = sim.data.state.x.copy()
    worst = 0.0
    dropped = []
    for _ in range(30):
        sim.step(100)
        s = sim.data.state
        worst = max(worst, float(np.abs(joint_rows_numpy(sim.model.joint, s.x, s.q)[0]).max()))
        dropped.append(int(sim.data.joint.stats[3]))  # rows dropped by the solver in the last step
    assert worst <= 1e-12, worst
    assert 1 <= min(dropped) and max(dropped) <= 3, dropped
    assert np.abs(sim.data.state.x - start).max() > 0.05  # it moved
    np.testing.assert_allclose(sim.state.omega[0], [0.0, 2.0, 0.0], rtol=0, atol=1e-12)  # the crank


@pytest.mark.parametrize("integrator", ["split2", None])
def test_the_double_pendulum_energy_error_stays_bounded(integrator):
    """Chaotic, so no trajectory reference; but split2 with the joint stages keeps E(t) - E(0) small
    and without drift: over 10 s its largest value in the last 2 s is within twice that of the first 2 s
    (measured ratio below 1), and below 1e-4 of the energy scale M g l. The scene names no integrator, so
    it runs reduced-rk4 in joint coordinates (docs/trees.md): not symplectic, its error grows (measured
    1.6e-9 J in the first 2 s, 2.4e-8 J in the last), but at its fourth order it stays far below the same
    bound."""
    sim = Simulation(SCENES / "double_pendulum.yaml", integrator=integrator)
    assert sim.compiled.settings.integrator == (integrator or "reduced-rk4")
    mass = sim.model.body_mass

    def energy() -> float:
        s = sim.state
        kinetic = 0.5 * float(np.sum(s.P * s.v) + np.sum(s.L * s.omega))
        return kinetic + float(np.sum(mass * 9.81 * s.x[:, 2]))

    start = energy()
    errors = []
    for _ in range(100):
        sim.step(100)
        errors.append(abs(energy() - start))
    errors = np.array(errors)
    if integrator == "split2":
        assert errors[-20:].max() <= 2.0 * errors[:20].max(), (errors[:20].max(), errors[-20:].max())
    assert errors.max() < 1e-4 * float(mass.sum()) * 9.81, errors.max()
