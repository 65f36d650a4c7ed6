"""`rbsim study` of a jointed scene: only the integrators that hold joints, against the pendulum's exact
motion theta(t) = 2 arcsin(k sn(K - omega0 t | k^2)) when the scene is one (else split2 at a fine step),
with the fitted order of split2 2."""

from __future__ import annotations

import math

import numpy as np
from joint_scenes import exact_period, pendulum_text

from rbcli.analysis.errors import pendulum_of, pendulum_reference
from rbcli.runner.simulation import Simulation
from rbcli.runner.study import study
from rbcli.scene.compile import compile_scene
from rbcli.scene.load import load_scene_text


def test_the_exact_pendulum_is_the_pendulum_scenes_motion():
    """The reference's period is the compound pendulum's 4 K(m) sqrt(l_eff / g) (computed independently
    from the rod's particles in joint_scenes), and split2 at dt = 1e-3 follows it to 1e-6 m over 2 s."""
    theta0 = math.radians(170)
    compiled = compile_scene(load_scene_text(pendulum_text(theta0, 1e-3)))
    pendulum = pendulum_of(compiled)
    assert pendulum is not None and abs(pendulum.theta0 - theta0) < 1e-14
    assert abs(pendulum.period - exact_period(theta0)) <= 1e-12 * exact_period(theta0)
    times = np.arange(2001) * 1e-3
    reference = pendulum_reference(compiled, pendulum, times)
    sim = Simulation(compiled)
    x = [sim.state.x[0].copy()]
    for _ in range(2000):
        sim.step(1)
        x.append(sim.state.x[0].copy())
    assert np.abs(np.array(x) - reference.x[:, 0]).max() < 1e-5  # measured 4.3e-6 m (3.5e-7 at 10 degrees)


def test_a_study_of_a_pendulum_uses_its_exact_motion_and_fits_each_family_s_orders():
    """The two families side by side: split2 with RATTLE (maximal coordinates) and the integrators in
    joint coordinates (the pendulum is a tree), each at its order against the exact motion."""
    result = study(load_scene_text(pendulum_text(math.radians(170), 1e-3)), dts=[4e-3, 2e-3, 1e-3], duration=2.0,
                   min_time=0)  # fmt: skip
    assert result.reference.kind == "exact" and "pendulum" in result.reference.description
    # the ones that hold joints: RATTLE, and the two in joint coordinates
    assert {run.integrator for run in result.runs} == {"split2", "reduced-euler", "reduced-rk4"}
    assert result.primary_error == "rotation"
    for name, order in (("split2", 2), ("reduced-euler", 1), ("reduced-rk4", 4)):
        fitted = result.fits[name].rotation.order
        assert fitted is not None and abs(fitted - order) < 0.3, (name, fitted)  # measured 2.01, ...


def test_a_study_of_a_chain_with_a_loop_keeps_to_maximal_coordinates():
    text = pendulum_text(math.radians(30), 1e-3)
    text += "  - {name: again, type: ball, bodies: [rod, world], anchor: [0, 0, 1]}\n"  # a second joint: a loop
    result = study(load_scene_text(text), dts=[2e-3, 1e-3], duration=0.2, min_time=0)
    assert {run.integrator for run in result.runs} == {"split2"}
