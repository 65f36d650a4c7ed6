"""Sweeps for the tests: a small spring scene (a plate hung from a spring, under gravity; torques, so the
orientation matters) whose stiffness and integrator the sweeps vary, and helpers to run one variant the
long way: its scene edited by hand and run by `rbcli.Simulation`, without the sweep code."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

import rbcli
from rbcli.record.memory_sink import SinkMemory
from rbcli.scene.load import load_scene_text

# 200 steps. k = 1e6 N/m on 3 kg at dt = 0.01 s: omega dt = 5.8, far past split2's and rk4's stability
# limits (2 and 2.8), so the state grows ~30-fold a step and passes 1e100 well before the end.
SPRING_SCENE = """\
name: spring-plate
simulation: {dt: 0.01, duration: 2.0, integrator: split2}
gravity: [0, 0, -9.81]
bodies:
  - name: plate
    particles:
      positions: [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]
      masses: [1.0, 1.0, 0.5, 0.5]
    position: [0.0, -0.5, 0.7]
    velocity: [0.5, 0.0, 0.0]
    angular_momentum: [0.5, 0.6, 12.0]
forces:
  - {type: spring, body: plate, point: [0, 0.5, 0], anchor: [0, 0, 2], stiffness: 100, rest_length: 1.0, damping: 0}
"""
DIVERGING_STIFFNESS = 1.0e6

SPRING_SWEEP = """\
name: spring-sweep
scene: spring.yaml
axes:
  - path: forces[0].stiffness
    values: [50, 100.0, 1.0e6]
  - path: simulation.integrator
    values: [split2, rk4]
"""

STATE_COLUMNS = ("x_final", "q_final", "v_final", "omega_final", "L_final")


def reference_state(stiffness: float, integrator: str) -> dict[str, np.ndarray]:
    """The final state of one (non-diverging) variant, built by editing the scene's YAML by hand and
    running a Simulation into a memory recording: the sweep's path setting, batching and metrics play no
    part. The recording's last frame is the final state (x, q and L bitwise `Simulation.state`'s; v and
    omega are the recorder's compiled outputs, which a row must match)."""
    data = yaml.safe_load(SPRING_SCENE)
    data["forces"][0]["stiffness"] = stiffness
    data["simulation"]["integrator"] = integrator
    sim = rbcli.Simulation(load_scene_text(yaml.safe_dump(data)))
    memory = SinkMemory()
    sim.run(sinks=[memory])
    last = memory.trajectory()
    state = sim.state
    for name in ("x", "q", "L"):
        assert getattr(last, name)[-1].tobytes() == getattr(state, name).tobytes(), name
    return {"x_final": last.x[-1], "q_final": last.q[-1], "v_final": last.v[-1], "omega_final": last.omega[-1],
                         "L_final": last.L[-1]}  # fmt: skip


def rows_without_wall_time(table) -> list[dict]:  # noqa: ANN001 - a pyarrow Table
    """The rows of a results table, minus the one column that differs between runs of a variant (wall_s).
    Failed rows too: the run loop's energy guard looks at a fixed grid of steps, so a diverging variant
    stops at the same step however the wall-clock-sized chunks fall."""
    return [nan_as_text(row) for row in table.drop_columns(["wall_s"]).to_pylist()]


def nan_as_text(value):  # noqa: ANN001, ANN202
    """NaN as the text 'nan' (NaN != NaN would make equal rows of a diverged variant compare unequal)."""
    if isinstance(value, float) and value != value:
        return "nan"
    if isinstance(value, dict):
        return {k: nan_as_text(v) for k, v in value.items()}
    if isinstance(value, list):
        return [nan_as_text(v) for v in value]
    return value


# the fixture tests/sweep/conftest.py used to hold: a conftest.py here would be registered as the module
# `conftest` too, shadowing tests/conftest.py for any later `from conftest import ...` in other folders
@pytest.fixture(name="spring_sweep")
def spring_sweep_fixture(tmp_path: Path) -> Path:
    """A sweep file (and its scene) in a fresh folder: 3 stiffnesses x 2 integrators, one stiffness diverging."""
    (tmp_path / "spring.yaml").write_text(SPRING_SCENE)
    path = tmp_path / "spring.sweep.yaml"
    path.write_text(SPRING_SWEEP)
    return path
