"""The step pipeline: the committed chunk loops are what the stage list generates, and a stage added to
the list runs in every integrator's loop.

    python tests/physics/test_pipeline.py --regenerate    # rewrite rbcli/physics/chunks/*.py
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from rbcli.physics.integrators import INTEGRATORS
from rbcli.physics.pipeline import STEP_STAGES, Stage, chunk_source

CHUNKS = Path(__file__).resolve().parents[2] / "rbcli" / "physics" / "chunks"


def _short(name: str) -> str:
    return INTEGRATORS[name].module.rsplit(".", 1)[1]


def regenerate() -> None:
    for name in INTEGRATORS:
        path = CHUNKS / f"{_short(name)}.py"
        path.write_text(chunk_source(_short(name), name))
        print("wrote", path)


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_committed_chunk_loops_are_generated_from_the_stage_list(name):
    path = CHUNKS / f"{_short(name)}.py"
    assert path.read_text() == chunk_source(_short(name), name), f"{path} is stale: run this file with --regenerate"
    assert INTEGRATORS[name].chunk().run_chunk is not None


def test_stage_list_is_impulses_contact_update_record():
    names = ["impulses", "joint_begin", "contact_begin", "kinematic_begin", "update", "kinematic_end",
             "joint_position", "joint_velocity", "contact_commit", "materialise", "contact_record",
             "record"]  # fmt: skip
    assert [stage.name for stage in STEP_STAGES] == names
    # materialise belongs to exact's loop alone (it writes the states exact defers), the joint stages to
    # split2's (the one integrator that holds joints: integrators.check_integrator)
    owned = {stage.name: stage.integrators for stage in STEP_STAGES if stage.integrators}
    joint_stages = {name: ("split2",) for name in ("joint_begin", "joint_position", "joint_velocity")}
    assert owned == {"materialise": ("exact",), **joint_stages}
    assert "materialise(" in chunk_source("exact", "exact") and "materialise(" not in chunk_source("split2", "split2")
    assert "joint_position_stage(" in chunk_source("split2", "split2")
    assert "joint_position_stage(" not in chunk_source("split4", "split4")
    assert [stage.name for stage in STEP_STAGES if stage.substep] == names[2:9]


# A trivial stage, as a user of the pipeline would add one: a constant push on every body, applied as an
# exact momentum jump after each step. Tested through the generated source exactly as the committed
# loops are built, so what this shows holds for them.
PUSH = 0.25  # [N s] per step, world x
PUSH_STAGE = Stage(
    "push",
    "push: a constant momentum jump on every body after each update (test stage)",
    (),
    f"for b in range(P.shape[0]):\n    P[b, 0] += {PUSH!r}",
)


def _load_generated(tmp_path: Path, name: str, stages: tuple[Stage, ...]):  # noqa: ANN202
    path = tmp_path / f"chunk_{_short(name)}.py"
    path.write_text(chunk_source(_short(name), name, stages))
    spec = importlib.util.spec_from_file_location(f"_test_chunk_{_short(name)}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("name", ["split2", "rk4", "euler-matrix", "exact"])
def test_a_stage_added_to_the_list_runs_in_the_generated_loop(tmp_path, name):
    """With no forces, P only changes through the added stage: after n steps every body's P_x is its
    initial value plus n pushes (exactly: the pushes are 0.25, the sums exact in binary), while a loop
    built from the unchanged list leaves P alone. Four integrators of four different kinds stand for all
    (each generated loop compiles anew, ~2 s apiece: the stale-file test covers all ten)."""
    from conftest import make_scene, random_bodies

    from rbcli.api import prepare
    from rbcli.physics.data import make_data
    from rbcli.physics.step import empty_buffers

    stages = (*STEP_STAGES[:-1], PUSH_STAGE, STEP_STAGES[-1])
    pushed = _load_generated(tmp_path, name, stages)
    compiled = prepare(make_scene(random_bodies(3, seed=2), integrator=name))
    data = make_data(compiled.initial_state, compiled.forces, pushed.SCRATCH_WIDTH)
    P0 = data.state.P.copy()
    frames = empty_buffers(4, 3)
    steps = 12
    done, filled, status = pushed.run_chunk(
        compiled.model.kernel(), compiled.forces.kernel(), data.kernel(), 1e-3, 0, steps, 5, frames, 0
    )
    assert (done, filled, status) == (steps, 2, 0)
    assert np.array_equal(data.state.P[:, 0], P0[:, 0] + steps * PUSH)
    assert np.array_equal(data.state.P[:, 1:], P0[:, 1:])
    assert np.array_equal(frames.P[0][:, 0], P0[:, 0] + 5 * PUSH)  # the stage ran before the record stage


if __name__ == "__main__":
    if "--regenerate" in sys.argv:
        regenerate()
    else:
        print(__doc__)
