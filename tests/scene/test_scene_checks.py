"""The dt-stability warning for stiff springs: given exactly where leapfrog/split2 stops being stable."""

import numpy as np
import pytest

from rbcli.api import simulate
from rbcli.scene.load import check_scene, load_scene_text

SCENE = """\
name: stiff
simulation: {{dt: {dt}, duration: 2.0, integrator: split2}}
bodies:
  - name: bob
    particles: {{positions: [[0.1, 0, 0], [-0.1, 0, 0], [0, 0.1, 0], [0, -0.1, 0]], masses: 0.25}}
    position: [0, 0, -1.01]
forces:
  - {{type: spring, body: bob, anchor: [0, 0, 0], stiffness: 1.0e5, rest_length: 1.0}}
"""
# a 1 kg bob at its centre of mass: omega = sqrt(k / M) = 316.2 rad/s, stability limit 2 / omega = 6.32 ms
LIMIT = 2.0 / np.sqrt(1.0e5)


def test_warning_names_the_spring_and_the_limit(tmp_path):
    path = tmp_path / "stiff.yaml"
    path.write_text(SCENE.format(dt=0.01))
    (issue,) = check_scene(path)
    assert issue.severity == "warning" and issue.location.line == 8
    assert f"{LIMIT:.3g} s" in issue.message
    path.write_text(SCENE.format(dt=0.005))
    assert check_scene(path) == []


@pytest.mark.parametrize("factor, stable", [(0.95, True), (1.05, False)])
def test_the_limit_is_where_split2_loses_stability(factor, stable):
    """The warning is honest: just below 2/omega the oscillation stays bounded, just above it grows."""
    traj = simulate(load_scene_text(SCENE.format(dt=factor * LIMIT)), on_diverge="return", duration=2.0)
    stretch = np.abs(traj.x[:, 0, 2] + 1.0)  # distance from the rest position
    if stable:
        assert traj.status == "completed" and stretch.max() < 0.1
    else:
        assert traj.status == "diverged" or stretch.max() > 1e3
