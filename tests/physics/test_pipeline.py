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

from rbcli.physics.forces.stage_list import FORCE_STAGES, ForceStage, wrench_source
from rbcli.physics.integrators import INTEGRATORS
from rbcli.physics.pipeline import ADAPTIVE, BOTH, FIXED, STEP_STAGES, Stage, adaptive_source, chunk_source

CHUNKS = Path(__file__).resolve().parents[2] / "rbcli" / "physics" / "chunks"
WRENCH_PASS = CHUNKS.parent / "forces" / "wrench_pass.py"


def _short(name: str) -> str:
    return INTEGRATORS[name].module.rsplit(".", 1)[1]


ADAPTIVE_NAMES = [name for name, info in INTEGRATORS.items() if info.adaptive]
PARALLEL_NAMES = [name for name, info in INTEGRATORS.items() if info.parallel]


def regenerate() -> None:
    for name in INTEGRATORS:
        path = CHUNKS / f"{_short(name)}.py"
        path.write_text(chunk_source(_short(name), name))
        print("wrote", path)
    for name in PARALLEL_NAMES:
        path = CHUNKS / f"{_short(name)}_parallel.py"
        path.write_text(chunk_source(_short(name), name, parallel=True))
        print("wrote", path)
    for name in ADAPTIVE_NAMES:
        path = CHUNKS / f"{_short(name)}_adaptive.py"
        path.write_text(adaptive_source(_short(name), name))
        print("wrote", path)
    WRENCH_PASS.write_text(wrench_source())
    print("wrote", WRENCH_PASS)


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_committed_chunk_loops_are_generated_from_the_stage_list(name):
    path = CHUNKS / f"{_short(name)}.py"
    assert path.read_text() == chunk_source(_short(name), name), f"{path} is stale: run this file with --regenerate"
    assert INTEGRATORS[name].chunk().run_chunk is not None


@pytest.mark.parametrize("name", PARALLEL_NAMES)
def test_committed_parallel_loops_are_generated_from_the_stage_list(name):
    """The threaded loop is the serial one but for the step it calls (docs/performance.md, "Threads")."""
    path = CHUNKS / f"{_short(name)}_parallel.py"
    source = chunk_source(_short(name), name, parallel=True)
    assert path.read_text() == source, f"{path} is stale: run this file with --regenerate"
    serial = chunk_source(_short(name), name)
    assert "import step_parallel as integrator_step" in source and "import step as integrator_step" in serial
    body = source.split("def run_chunk", 1)[1]
    assert body == serial.split("def run_chunk", 1)[1], "the threaded loop must run the serial loop's stages"


@pytest.mark.parametrize("name", ADAPTIVE_NAMES)
def test_committed_adaptive_loops_are_generated_from_the_stage_list(name):
    path = CHUNKS / f"{_short(name)}_adaptive.py"
    assert path.read_text() == adaptive_source(_short(name), name), f"{path} is stale: run this file with --regenerate"
    assert INTEGRATORS[name].adaptive_chunk().run_chunk is not None


def test_stage_list_is_impulses_contact_update_record():
    names = ["impulses", "joint_begin", "contact_begin", "kinematic_begin", "update", "kinematic_end",
             "joint_velocity", "contact_commit", "materialise", "contact_record", "joint_record", "record"]  # fmt: skip
    assert [stage.name for stage in STEP_STAGES] == names
    # materialise belongs to exact's loop alone (it writes the states exact defers), the joint stages to
    # split2's (the one integrator that holds joints: integrators.check_integrator)
    owned = {stage.name: stage.integrators for stage in STEP_STAGES if stage.integrators}
    joint_stages = {name: ("split2",) for name in ("joint_begin", "joint_velocity", "joint_record")}
    assert owned == {"materialise": ("exact",), **joint_stages}
    assert "materialise(" in chunk_source("exact", "exact") and "materialise(" not in chunk_source("split2", "split2")
    # split2's update is the RATTLE step in a scene with joints (joints/rattle.py), its own step otherwise
    assert "if not joint_update(" in chunk_source("split2", "split2")
    assert "joint_update(" in chunk_source("split2", "split2", parallel=True)
    assert "joint_" not in chunk_source("split4", "split4")
    assert [stage.name for stage in STEP_STAGES if stage.substep] == names[2:8]
    # which loops have which stage: one field per stage; materialise (exact's) and the joint stages
    # (split2's: joints refuse a tolerance) are fixed-step only
    fixed_only = ("materialise", "joint_begin", "joint_velocity", "joint_record")
    assert {stage.name: stage.loops for stage in STEP_STAGES} == {
        **dict.fromkeys(names, BOTH),
        **dict.fromkeys(fixed_only, (FIXED,)),
    }
    adaptive = adaptive_source("dopri5", "dopri5")
    in_adaptive = [stage.name for stage in STEP_STAGES if ADAPTIVE in stage.loops and stage.name != "update"]
    assert all(f"# {name}: " in adaptive for name in in_adaptive), in_adaptive
    assert "materialise" not in adaptive and "integrator_step" not in adaptive and "joint_" not in adaptive


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


def _load_generated(tmp_path: Path, name: str, stages: tuple[Stage, ...], source=chunk_source):  # noqa: ANN001, ANN202
    path = tmp_path / f"chunk_{_short(name)}.py"
    path.write_text(source(_short(name), name, stages))
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
    data = make_data(compiled.initial_state, compiled.model, pushed.SCRATCH_WIDTH)
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


def test_a_step_start_stage_added_to_the_list_runs_at_every_grid_step_of_the_adaptive_loop(tmp_path):
    """The same push as a step-start stage (before the impulses), with no `lands_at`: the adaptive loop
    must land on every grid index and run it there, as the fixed-step loop does, so after n grid steps
    P_x is P0 + n pushes exactly (no forces: dopri5 leaves P as it is, exactly; with `lands_at="end"`
    the stage runs at the chunk's start only: one push, checked by hand) and the frame at grid step 5
    holds five pushes."""
    from conftest import make_scene, random_bodies

    from rbcli.api import prepare
    from rbcli.physics.data import make_data
    from rbcli.physics.step import empty_buffers

    pushed = _load_generated(tmp_path, "dopri5", (PUSH_STAGE, *STEP_STAGES), adaptive_source)
    assert "land = min(land, index + 1)" in adaptive_source("dopri5", "dopri5", (PUSH_STAGE, *STEP_STAGES))
    compiled = prepare(make_scene(random_bodies(3, seed=2), integrator="dopri5"))
    steps, every = 12, 5
    data = make_data(compiled.initial_state, compiled.model, 0, adaptive=True, tolerance=1e-6, duration=0.012)
    P0 = data.state.P.copy()
    frames = empty_buffers(4, 3)
    done, filled, status = pushed.run_chunk(
        compiled.model.kernel(), compiled.forces.kernel(), data.kernel(), 1e-3, 0, steps, every, frames, 0
    )
    assert (done, filled, status) == (steps, 2, 0)
    assert np.array_equal(frames.P[0][:, 0], P0[:, 0] + every * PUSH)
    assert np.array_equal(data.state.P[:, 0], P0[:, 0] + steps * PUSH) and np.array_equal(
        data.state.P[:, 1:], P0[:, 1:]
    )


def test_committed_force_pass_is_generated_from_the_force_stage_list():
    assert WRENCH_PASS.read_text() == wrench_source(), f"{WRENCH_PASS} is stale: run this file with --regenerate"
    names = ["gravity", "field", "point_force", "torque", "spring", "drag", "contact"]
    assert [stage.name for stage in FORCE_STAGES] == names
    assert [stage.name for stage in FORCE_STAGES if stage.dissipative] == ["drag"]
    assert [stage.name for stage in FORCE_STAGES if not stage.tables] == ["gravity"]  # a flag, no table


# A force stage as a new force type would add one: a constant world force on every body that has a field
# row, dispatched on the field table (so it compiles away where fields do), added after the list's own.
KICK = 1.5  # [N], world y
KICK_STAGE = ForceStage(
    "kick",
    "kick: a constant force on the bodies of the field rows (test stage)",
    (),
    f"for row in range(forces.field.body.shape[0]):\n    F[forces.field.body[row], 1] += {KICK!r}",
    tables=("forces.field",),
)


def test_a_force_stage_added_to_the_list_runs_in_the_generated_pass(tmp_path):
    """Gravity only: F = M g exactly. With the kick stage: the same plus KICK in y on the body that has
    the field row, exactly (no other stage touches F_y here), and the stage compiled away when the
    field table is None (KernelForceTables of a scene without fields): F = M g again. The force table
    is built by hand: a zero field on body 1 (it adds exactly 0.0), whose row names the kicked body."""
    from conftest import make_scene, random_bodies

    from rbcli.api import prepare
    from rbcli.physics.forces import NO_SCHEDULE, make_force_data
    from rbcli.physics.forces.tables import field_table

    path = tmp_path / "kicked_pass.py"
    path.write_text(wrench_source((*FORCE_STAGES, KICK_STAGE)))
    spec = importlib.util.spec_from_file_location("_test_kicked_pass", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    compiled = prepare(make_scene(random_bodies(3, seed=4), gravity=np.array([0.0, 0.0, -9.81])))
    model, s = compiled.model.kernel(), compiled.initial_state
    bodies, force_data = compiled.model.kernel_bodies(), make_force_data(model)  # as a chunk loop passes them
    field = field_table(body=[1], per_mass=[False], value=[[0.0, 0.0, 0.0]], gradient=[np.zeros((3, 3))],
                        schedule=[NO_SCHEDULE])  # fmt: skip
    with_field = compiled.forces._replace(field=field)
    expected = compiled.model.body_mass[:, None] * np.array([0.0, 0.0, -9.81])
    for forces, kick in ((with_field.kernel(), KICK), (compiled.forces.kernel(), 0.0)):  # only what each has
        F, tau = np.zeros((3, 3)), np.zeros((3, 3))
        module.accumulate_wrench(bodies, forces, model.contact, force_data, 0.0, s.x, s.q, s.P, s.L, F, tau)
        assert np.array_equal(F[:, 0::2], expected[:, 0::2])
        assert np.array_equal(F[:, 1], np.array([0.0, kick, 0.0]))


if __name__ == "__main__":
    if "--regenerate" in sys.argv:
        regenerate()
    else:
        print(__doc__)
