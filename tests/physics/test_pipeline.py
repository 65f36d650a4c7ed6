"""The step pipeline: the stage list of physics/pipeline.py is what the chunk loops run, in its order,
and each integrator's loop is compiled with its own step and only the stages its integrator has; the
force pass (forces/wrench_pass.py) calls the stages of forces/stage_list.py FORCE_STAGES in its order."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import numpy as np
import pytest
from conftest import as_runner_passes

from rbcli.physics import adaptive_loop, chunk_loop
from rbcli.physics.forces import wrench_pass
from rbcli.physics.forces.stage_list import FORCE_STAGES
from rbcli.physics.integrators import INTEGRATORS, get_integrator
from rbcli.physics.joints import rattle
from rbcli.physics.pipeline import STEP_STAGES

PHYSICS = Path(__file__).resolve().parents[2] / "rbcli" / "physics"
STAGE_CALLS = {stage.fixed for stage in STEP_STAGES} | {stage.adaptive for stage in STEP_STAGES}


def _loop(module) -> ast.FunctionDef:  # noqa: ANN001
    """The AST of `module`'s run_chunk, as written in its file."""
    tree = ast.parse(inspect.getsource(module))
    return next(node for node in tree.body if isinstance(node, ast.FunctionDef) and node.name == "run_chunk")


def _stage_calls(node: ast.AST) -> list[ast.Call]:
    """The calls of a stage's function under `node`, in source order."""
    calls = [n for n in ast.walk(node) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    calls = [call for call in calls if call.func.id in STAGE_CALLS]  # type: ignore[union-attr]
    return sorted(calls, key=lambda call: (call.lineno, call.col_offset))


def _comment_above(lines: list[str], lineno: int) -> str:
    """The comment block nearest above source line `lineno` (1-based), at most 3 code lines up (a stage's
    call may sit under its test, `if contact_commit_due(...):`, or after a line preparing it)."""
    index = lineno - 2
    for _ in range(3):
        if lines[index].strip().startswith("#"):
            break
        index -= 1
    while lines[index - 1].strip().startswith("#"):
        index -= 1
    return lines[index].strip()


def _names(calls: list[ast.Call]) -> list[str]:
    return [call.func.id for call in calls]  # type: ignore[union-attr]


def test_stage_list_is_impulses_contact_update_record():
    names = ["impulses", "tree_kick", "joint_begin", "contact_begin", "kinematic_begin", "joint_update",
             "tree_update", "update", "kinematic_end", "joint_velocity", "contact_commit", "materialise",
             "contact_record", "joint_record", "tree_record", "record"]  # fmt: skip
    assert [stage.name for stage in STEP_STAGES] == names
    assert [stage.name for stage in STEP_STAGES if stage.substep] == names[3:11]
    # materialise belongs to exact's loop alone (it writes the states exact defers), the joint stages to
    # split2's (the one integrator that holds joints: integrators.check_integrator); neither to the
    # adaptive loop (joints refuse a tolerance, dopri5 defers nothing)
    joint_stages = ["joint_begin", "joint_update", "joint_velocity", "joint_record"]
    assert {stage.name: stage.only for stage in STEP_STAGES if stage.only} == {
        **dict.fromkeys(joint_stages, "joints"),
        "materialise": "defers",
        "tree_kick": "tree",
        "tree_update": "tree",
        "tree_record": "tree",
    }
    fixed_only = [
        "tree_kick",
        *joint_stages[:2],
        "tree_update",
        joint_stages[2],
        "materialise",
        "joint_record",
        "tree_record",
    ]
    assert [stage.name for stage in STEP_STAGES if stage.adaptive is None] == fixed_only
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
    constants = {"joints": "HOLDS_JOINTS", "defers": "DEFERS", "tree": "HOLDS_TREE"}
    for flag, constant in constants.items():
        gates = [n for n in ast.walk(loop) if isinstance(n, ast.If) and ast.unparse(n.test) == constant]
        gated = ast.Module([statement for n in gates for statement in n.body], [])  # the If's body, not its else
        inside = _names(_stage_calls(gated))
        assert inside == [stage.fixed for stage in STEP_STAGES if stage.only == flag], flag
    lines = inspect.getsource(chunk_loop).splitlines()
    for call, stage in zip(_stage_calls(loop), STEP_STAGES, strict=True):
        above = _comment_above(lines, call.lineno)
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
        assert (bound["joint_update"] is rattle.joint_update_stage) == info.joints
        assert loop.SCRATCH_WIDTH == module.SCRATCH_WIDTH
        assert info.chunk() is info.chunk()  # one dispatcher per integrator: compiled or loaded once
    names = {get_integrator(n).chunk().run_chunk.py_func.__qualname__ for n in INTEGRATORS}
    assert len(names) == len(INTEGRATORS)  # each loop has cache files of its own
    # the module's own names stand for no integrator: its function runs only as bound
    assert chunk_loop.integrator_step is chunk_loop._unbound and not chunk_loop.HOLDS_JOINTS
    assert chunk_loop.joint_update is chunk_loop._unbound


def test_a_loop_runs_the_joint_stages_only_where_its_integrator_holds_joints():
    """The hinged pendulum (scenes/joints/pendulum.yaml: centre of mass d = 0.6 m from the pivot, at rest)
    through two loops for 0.2 s. split2's runs the joint stages: the hinge holds, |x - pivot| = d to
    round-off (1e-12 m; docs/joints.md). rk4's has none (joints refuse rk4 when a scene is loaded; its
    loop is called directly here): the rod falls freely, x_z = x_z(0) - g t^2 / 2, which rk4 integrates
    exactly under constant gravity (to round-off, 1e-12 m). So the flags reach the compiled loops."""
    from rbcli.api import prepare
    from rbcli.physics.data import make_data
    from rbcli.physics.step import empty_buffers

    compiled = prepare(Path(__file__).resolve().parents[2] / "scenes" / "joints" / "pendulum.yaml", integrator="split2")
    pivot, d, g, steps, dt = np.array([0.0, 0.0, 1.0]), 0.6, 9.81, 200, 1e-3
    x0 = compiled.initial_state.x[0].copy()
    assert abs(np.linalg.norm(x0 - pivot) - d) < 1e-12
    for name in ("split2", "rk4"):
        chunk = get_integrator(name).chunk()
        data = make_data(compiled.initial_state, compiled.model, chunk.SCRATCH_WIDTH, forces=compiled.forces)
        frames = empty_buffers(1, 1, 1)
        handles = as_runner_passes(compiled.model.kernel(), compiled.forces.kernel(), data.kernel(), frames)
        done, _, status = chunk.run_chunk(*handles[:3], dt, 0, steps, 10**9, handles[3], 0)
        assert (done, status) == (steps, 0)
        x = data.state.x[0]
        if name == "split2":
            assert abs(np.linalg.norm(x - pivot) - d) < 1e-12, name
        else:
            free_fall = x0 + np.array([0.0, 0.0, -0.5 * g * (steps * dt) ** 2])
            assert np.max(np.abs(x - free_fall)) < 1e-12, name


def _force_pass_calls() -> list[tuple[str, bool, str]]:
    """(stage, called only under `if dissipative:`, the comment line above the call) of every stage call
    in accumulate_wrench, in source order; gravity's stage is its inline accumulate_gravity call."""
    source = inspect.getsource(wrench_pass)
    lines = source.splitlines()
    function = next(
        node
        for node in ast.parse(source).body
        if isinstance(node, ast.FunctionDef) and node.name == "accumulate_wrench"
    )
    found = []

    def visit(node: ast.AST, dissipative: bool) -> None:
        for child in ast.iter_child_nodes(node):
            gated = dissipative or (
                isinstance(child, ast.If) and isinstance(child.test, ast.Name) and child.test.id == "dissipative"
            )
            if isinstance(child, ast.Call) and isinstance(child.func, ast.Name):
                name = child.func.id
                stage = "gravity" if name == "accumulate_gravity" else name.removesuffix("_stage")
                if name == "accumulate_gravity" or name.endswith("_stage"):
                    statement = child.lineno - 1
                    while not lines[statement - 1].strip().startswith("#"):  # up to the comment above
                        statement -= 1
                    found.append((stage, dissipative, lines[statement - 1].strip().removeprefix("# ")))
            visit(child, gated)

    visit(function, False)
    return found


def test_the_force_pass_calls_the_force_stages_in_the_list_order():
    names = ["gravity", "field", "point_force", "torque", "spring", "drag", "contact"]
    assert [stage.name for stage in FORCE_STAGES] == names
    assert [stage.name for stage in FORCE_STAGES if stage.dissipative] == ["drag"]
    assert [stage.name for stage in FORCE_STAGES if not stage.tables] == ["gravity"]  # a flag, no table
    calls = _force_pass_calls()
    assert [name for name, _, _ in calls] == names
    for stage, (_, dissipative, comment) in zip(FORCE_STAGES, calls, strict=True):
        assert dissipative == stage.dissipative, stage.name
        assert comment == stage.why, stage.name


def test_each_force_stage_is_dispatched_on_its_tables():
    """`<name>_stage = force_stage(_<name>, *tables)` in wrench_pass.py, with FORCE_STAGES' tables: the
    dispatcher compiles the stage to nothing where one of them is None."""
    tree = ast.parse(inspect.getsource(wrench_pass))
    dispatched = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Call):
            call = node.value
            if isinstance(call.func, ast.Name) and call.func.id == "force_stage":
                target = node.targets[0].id  # type: ignore[attr-defined]
                assert call.args[0].id == "_" + target.removesuffix("_stage")  # type: ignore[attr-defined]
                dispatched[target.removesuffix("_stage")] = tuple(arg.value for arg in call.args[1:])  # type: ignore[attr-defined]
    assert dispatched == {stage.name: stage.tables for stage in FORCE_STAGES if stage.tables}


def test_the_contact_stage_is_called_only_where_contact_is_needed():
    """accumulate_wrench calls contact_stage inside `if contact_needed(...)`, the quiet skin's test outside
    the stage: as a call the stage passes the contact table and work by value, ~300 ns an evaluation,
    and a scene of far-apart bodies stepped at 2.4x the same scene without `contact:` (docs/contact.md,
    "Idle contact, a third time")."""
    function = next(
        node
        for node in ast.parse(inspect.getsource(wrench_pass)).body
        if isinstance(node, ast.FunctionDef) and node.name == "accumulate_wrench"
    )
    guards = [
        node
        for node in ast.walk(function)
        if isinstance(node, ast.If)
        and isinstance(node.test, ast.Call)
        and getattr(node.test.func, "id", None) == "contact_needed"
    ]
    assert len(guards) == 1
    inside = [n.func.id for n in ast.walk(guards[0]) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    assert "contact_stage" in inside
    everywhere = [n.func.id for n in ast.walk(function) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    assert everywhere.count("contact_stage") == 1
