"""The step pipeline: the stage list of physics/pipeline.py is what the chunk loops run, in its order,
and each integrator's loop is compiled with its own step and only the stages its integrator has.

    python tests/physics/test_pipeline.py --regenerate    # rewrite rbcli/physics/forces/wrench_pass.py
"""

from __future__ import annotations

import ast
import importlib.util
import inspect
import sys
from pathlib import Path

import numpy as np
import pytest

from rbcli.physics import adaptive_loop, chunk_loop
from rbcli.physics.forces.stage_list import FORCE_STAGES, ForceStage, wrench_source
from rbcli.physics.integrators import INTEGRATORS, get_integrator
from rbcli.physics.joints import stages as joint_stages
from rbcli.physics.pipeline import STEP_STAGES

PHYSICS = Path(__file__).resolve().parents[2] / "rbcli" / "physics"
WRENCH_PASS = PHYSICS / "forces" / "wrench_pass.py"
STAGE_CALLS = {stage.fixed for stage in STEP_STAGES} | {stage.adaptive for stage in STEP_STAGES}


def regenerate() -> None:
    WRENCH_PASS.write_text(wrench_source())
    print("wrote", WRENCH_PASS)


def _loop(module) -> ast.FunctionDef:  # noqa: ANN001
    """The AST of `module`'s run_chunk, as written in its file."""
    tree = ast.parse(inspect.getsource(module))
    return next(node for node in tree.body if isinstance(node, ast.FunctionDef) and node.name == "run_chunk")


def _stage_calls(node: ast.AST) -> list[ast.Call]:
    """The calls of a stage's function under `node`, in source order."""
    calls = [n for n in ast.walk(node) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    calls = [call for call in calls if call.func.id in STAGE_CALLS]  # type: ignore[union-attr]
    return sorted(calls, key=lambda call: (call.lineno, call.col_offset))


def _names(calls: list[ast.Call]) -> list[str]:
    return [call.func.id for call in calls]  # type: ignore[union-attr]


def test_stage_list_is_impulses_contact_update_record():
    names = ["impulses", "joint_begin", "contact_begin", "kinematic_begin", "update", "kinematic_end",
             "joint_position", "joint_velocity", "contact_commit", "materialise", "contact_record",
             "joint_record", "record"]  # fmt: skip
    assert [stage.name for stage in STEP_STAGES] == names
    assert [stage.name for stage in STEP_STAGES if stage.substep] == names[2:9]
    # materialise belongs to exact's loop alone (it writes the states exact defers), the joint stages to
    # split2's (the one integrator that holds joints: integrators.check_integrator); neither to the
    # adaptive loop (joints refuse a tolerance, dopri5 defers nothing)
    joint_stages = ["joint_begin", "joint_position", "joint_velocity", "joint_record"]
    assert {stage.name: stage.only for stage in STEP_STAGES if stage.only} == {
        **dict.fromkeys(joint_stages, "joints"),
        "materialise": "defers",
    }
    assert [stage.name for stage in STEP_STAGES if stage.adaptive is None] == [*joint_stages[:3], "materialise",
                                                                               "joint_record"]  # fmt: skip
    assert all(stage.fixed for stage in STEP_STAGES)
    assert [name for name, info in INTEGRATORS.items() if info.joints] == ["split2"]
    assert [name for name, info in INTEGRATORS.items() if info.defers] == ["exact"]


def test_the_fixed_step_loop_calls_the_stages_in_the_list_order():
    """chunk_loop.run_chunk's source: one call per stage, in STEP_STAGES order; the sub-step stages, and
    only they, inside the loop over the sub-steps; the stages of some integrators, and only they, under
    the constant naming their flag (`if HOLDS_JOINTS:`, `if DEFERS:`), which chunk_loop binds per
    integrator; and the comment above each call is the list's `name: why`."""
    loop = _loop(chunk_loop)
    assert _names(_stage_calls(loop)) == [stage.fixed for stage in STEP_STAGES]
    substeps = [n for n in ast.walk(loop) if isinstance(n, ast.For) and "substeps" in ast.unparse(n.iter)]
    assert len(substeps) == 1
    assert _names(_stage_calls(substeps[0])) == [stage.fixed for stage in STEP_STAGES if stage.substep]
    constants = {"joints": "HOLDS_JOINTS", "defers": "DEFERS"}
    for flag, constant in constants.items():
        gated = ast.Module([n for n in ast.walk(loop) if isinstance(n, ast.If) and ast.unparse(n.test) == constant], [])
        inside = _names(_stage_calls(gated))
        assert inside == [stage.fixed for stage in STEP_STAGES if stage.only == flag], flag
    lines = inspect.getsource(chunk_loop).splitlines()
    for call, stage in zip(_stage_calls(loop), STEP_STAGES, strict=True):
        above = lines[call.lineno - 2].strip() if stage.name != "materialise" else lines[call.lineno - 4].strip()
        assert above.startswith(f"# {stage.name}: {stage.why}"), (stage.name, above)


def test_the_adaptive_loop_calls_its_stages_in_the_list_order():
    """adaptive_loop.run_chunk's source: the stages with an adaptive call, first met in STEP_STAGES order
    (the loop calls some at more than one place: Stage's docstring), and none of the others."""
    calls = _names(_stage_calls(_loop(adaptive_loop)))
    first = list(dict.fromkeys(calls))
    assert first == [stage.adaptive for stage in STEP_STAGES if stage.adaptive]
    fixed_only = {stage.fixed for stage in STEP_STAGES if stage.adaptive is None}
    assert not fixed_only & set(calls)


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_each_integrator_s_loop_is_the_one_loop_bound_to_its_step(name):
    """Every integrator's loop is chunk_loop.run_chunk's code with its own module's step (and, for
    split2, the threaded loop with step_parallel), its own flags, and its own cache name; nothing is
    compiled here (numba compiles at the first call)."""
    info = get_integrator(name)
    module = info.load()
    loops = [(info.chunk(), module.step)]
    if info.parallel:
        loops.append((info.parallel_chunk(), module.step_parallel))
    for loop, step in loops:
        function = loop.run_chunk.py_func
        assert function.__code__ is chunk_loop.run_chunk.__code__
        bound = function.__globals__
        assert bound["integrator_step"] is step
        assert (bound["HOLDS_JOINTS"], bound["DEFERS"]) == (info.joints, info.defers)
        assert (bound["integrator_materialise"] is getattr(module, "materialise", None)) == info.defers
        assert (bound["joint_position"] is joint_stages.joint_position) == info.joints
        assert loop.SCRATCH_WIDTH == module.SCRATCH_WIDTH
        assert info.chunk() is info.chunk()  # one dispatcher per integrator: compiled or loaded once
    names = {get_integrator(n).chunk().run_chunk.py_func.__qualname__ for n in INTEGRATORS}
    assert len(names) == len(INTEGRATORS)  # each loop has cache files of its own
    # the module's own names stand for no integrator: its function runs only as bound
    assert chunk_loop.integrator_step is chunk_loop._unbound and not chunk_loop.HOLDS_JOINTS
    assert chunk_loop.joint_position is chunk_loop._unbound


def test_a_loop_runs_the_joint_stages_only_where_its_integrator_holds_joints():
    """The hinged pendulum (scenes/joints/pendulum.yaml: centre of mass d = 0.6 m from the pivot, at rest)
    through two loops for 0.2 s. split2's runs the joint stages: the hinge holds, |x - pivot| = d to
    round-off (1e-12 m; docs/joints.md). rk4's has none (joints refuse rk4 when a scene is loaded; its
    loop is called directly here): the rod falls freely, x_z = x_z(0) - g t^2 / 2, which rk4 integrates
    exactly under constant gravity (to round-off, 1e-12 m). So the flags reach the compiled loops."""
    from rbcli.api import prepare
    from rbcli.physics.data import make_data
    from rbcli.physics.step import empty_buffers

    compiled = prepare(Path(__file__).resolve().parents[2] / "scenes" / "joints" / "pendulum.yaml")
    pivot, d, g, steps, dt = np.array([0.0, 0.0, 1.0]), 0.6, 9.81, 200, 1e-3
    x0 = compiled.initial_state.x[0].copy()
    assert abs(np.linalg.norm(x0 - pivot) - d) < 1e-12
    for name in ("split2", "rk4"):
        chunk = get_integrator(name).chunk()
        data = make_data(compiled.initial_state, compiled.model, chunk.SCRATCH_WIDTH)
        frames = empty_buffers(1, 1, 1)
        done, _, status = chunk.run_chunk(
            compiled.model.kernel(), compiled.forces.kernel(), data.kernel(), dt, 0, steps, 10**9, frames, 0
        )
        assert (done, status) == (steps, 0)
        x = data.state.x[0]
        if name == "split2":
            assert abs(np.linalg.norm(x - pivot) - d) < 1e-12, name
        else:
            free_fall = x0 + np.array([0.0, 0.0, -0.5 * g * (steps * dt) ** 2])
            assert np.max(np.abs(x - free_fall)) < 1e-12, name


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
