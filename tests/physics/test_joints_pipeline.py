"""Joints through the whole pipeline: `rbsim run` of scenes/joints/pendulum.yaml writes an .mcap and an
.rrd that read back with the hinge held in every recorded frame and the joint violations as per-frame
invariants; a checkpoint continues bitwise; a
scene without joints compiles no joint kernel (a fresh process with an empty cache, numba's own
compile events), and its split2 loop's joint stages compile to nothing."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from rbcli.cli.app import app
from rbcli.physics.data import make_data
from rbcli.physics.rotation import quat_rotate
from rbcli.record.read import read_trajectory
from rbcli.runner.simulation import Simulation
from rbcli.scene.load import load_scene, load_scene_text

ROOT = Path(__file__).resolve().parents[2]
PENDULUM = ROOT / "scenes" / "joints" / "pendulum.yaml"
PIVOT = np.array([0.0, 0.0, 1.0])
TOP_FROM_CENTRE = np.array([0.0, 0.0, 0.6])  # the rod's top particle from its centre of mass, user frame


@pytest.mark.parametrize("extension", ["mcap", "rrd"])
def test_rbsim_run_of_a_pendulum_writes_a_recording_that_reads_back(tmp_path, extension):
    out = tmp_path / f"pendulum.{extension}"
    result = CliRunner().invoke(app, ["run", str(PENDULUM), "--duration", "0.5", "-o", str(out)])
    assert result.exit_code == 0, result.output
    trajectory = read_trajectory(out)
    assert trajectory.x.shape == (51, 1, 3)  # frames every 10 steps of 1 ms, and the initial one
    top = trajectory.x[:, 0] + np.array([quat_rotate(q, TOP_FROM_CENTRE) for q in trajectory.q[:, 0]])
    # .mcap: float64 as simulated; .rrd: x and q stored as float32 (relative 6e-8)
    tolerance = 1e-12 if extension == "mcap" else 1e-6
    assert np.abs(top - PIVOT).max() <= tolerance
    assert trajectory.x[-1, 0, 0] > trajectory.x[0, 0, 0] + 0.05  # it swung: from x = -0.104 towards 0
    # the joints' violation per frame, evaluated afresh from each recorded (float64) state
    for name in ("joint_position_violation", "joint_velocity_violation"):
        values = trajectory.invariants[name]
        assert values.shape == (51,) and np.all(values <= 1e-12), (name, values.max())


def test_joint_violations_are_drifts_a_grounded_joint_changes_momentum_and_drives_change_energy():
    from rbcli.analysis.errors import admits_exact_solution
    from rbcli.physics.conservation import conserved_invariants
    from rbcli.scene.compile import compile_scene
    from rbcli.scene.load import load_scene_text

    names = ["joint_position_violation", "momentum_x", "angular_momentum_z", "energy_total"]
    spec = load_scene(PENDULUM)
    kept = conserved_invariants(spec.compiled_model.model, spec.compiled_model.forces, names)
    assert kept == {"joint_position_violation": True, "momentum_x": False, "angular_momentum_z": False,
                    "energy_total": True}  # fmt: skip
    damped = load_scene_text(PENDULUM.read_text().replace("axis: [0, 1, 0]}", "axis: [0, 1, 0], damping: 0.1}"))
    assert not conserved_invariants(damped.compiled_model.model, damped.compiled_model.forces, names)["energy_total"]
    # gravity alone, but the hinge holds the rod: free flight and torque-free rotation are not its motion
    # (a sweep or study of a pendulum compared against them reported 4.9 m "errors")
    assert not admits_exact_solution(compile_scene(spec))


def test_a_checkpoint_of_a_jointed_scene_continues_bitwise():
    sim = Simulation(PENDULUM)
    sim.step(300)
    saved = sim.checkpoint()
    sim.step(300)
    first = [a.copy() for a in (sim.data.state.x, sim.data.state.q, sim.data.state.P, sim.data.state.L)]
    again = Simulation(PENDULUM)
    again.restore(saved)
    again.step(300)
    for a, b in zip(first, (again.data.state.x, again.data.state.q, again.data.state.P, again.data.state.L),
                    strict=True):  # fmt: skip
        assert np.array_equal(a, b)


def test_the_kernel_model_and_data_of_a_scene_without_joints_have_no_joint_part():
    spec = load_scene(ROOT / "scenes" / "forces" / "spring_pendulum.yaml")
    model, state = spec.compiled_model.model, spec.compiled_model.initial_state
    assert model.joint is None and model.kernel().joint is None and make_data(state, model.kernel(), 1).joint is None
    jointed = load_scene(PENDULUM).compiled_model
    assert jointed.model.kernel().joint is jointed.model.joint
    assert make_data(jointed.initial_state, jointed.model.kernel(), 1).joint is not None
    assert "joint" not in spec.compiled_model.forces._fields  # joints are the model's, not force terms


SCRIPT = """
import json, sys
import numba.core.event as ev

compiled = []


class Recorder(ev.Listener):
    def on_start(self, event):
        f = event.data["dispatcher"].py_func
        compiled.append(f"{f.__module__}.{f.__qualname__}")

    def on_end(self, event):
        pass


ev.register("numba:compile", Recorder())
from rbcli.runner.simulation import Simulation

sim = Simulation(sys.argv[1], integrator="split2")
sim.step(3)
print(json.dumps(compiled))
"""


def test_a_scene_without_joints_compiles_no_joint_kernel(tmp_path):
    """The split2 loop of a jointless scene calls the joint stages (and the RATTLE update, joints/rattle.py)
    with None for the joint table and work, and numba prunes each one's body on `table is None`
    (joints/stages.py): they compile to empty functions and none of the rows, solver, drive or impulse
    kernels is compiled. (This test fails when
    the stages test the tables at run time, `if table.rows:`: numba then compiles both sides.)"""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    scene = tmp_path / "ball.yaml"  # gravity only: the cheapest split2 loop to compile
    scene.write_text(
        "simulation: {dt: 0.001, steps: 3, integrator: split2}\ngravity: [0, 0, -9.81]\nbodies:\n"
        "  - {name: ball, particles: {positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0]], masses: 1.0}}\n"
    )
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(scene)], env=env, cwd=ROOT, capture_output=True,
                         text=True, timeout=600)  # fmt: skip
    assert out.returncode == 0, out.stderr
    compiled = set(json.loads(out.stdout.strip().splitlines()[-1]))
    assert "rbcli.physics.chunk_loop.run_chunk[split2]" in compiled, sorted(compiled)  # it really compiled
    joint_kernels = {name for name in compiled if name.startswith("rbcli.physics.joints.")}
    # only the three stages, pruned to nothing, and the update's dispatcher answering False; not RATTLE's
    # update itself, nor any of the rows, solver, drive or impulse kernels
    stages = {f"rbcli.physics.joints.stages.joint_{stage}" for stage in ("begin", "velocity", "record")}
    update = "rbcli.physics.joints.rattle._joint_update_stage.<locals>.no_joints"
    assert joint_kernels == {*stages, update}, sorted(joint_kernels)


def test_the_joint_stages_do_not_allocate_per_step():
    """numba's allocation counters (NRT statistics, on in a fresh process) grow by the same amount over
    10 and 10,000 steps of jointed scenes (the motor-driven four-bar with its dropped rows, and with a
    second motor and a damper): the joint stages' work lives in Data."""
    code = (
        "import rbcli\n"
        "from numba.core.runtime import rtsys\n"
        "from rbcli.scene.load import load_scene_text\n"
        f"four_bar = {str(ROOT / 'scenes' / 'joints' / 'four_bar.yaml')!r}\n"
        "driven = open(four_bar).read().replace('axis: [0, 1, 0]}', 'axis: [0, 1, 0], damping: 0.01, '\n"
        "    'motor: {speed: 1.0, max_torque: 0.2}}', 1)\n"
        "for name, scene in (('four_bar', rbcli.load_scene(four_bar)), ('driven', load_scene_text(driven))):\n"
        "    sim = rbcli.Simulation(scene)\n"
        "    sim.step(1)\n"
        "    counts = []\n"
        "    for n in (10, 10_000):\n"
        "        before = rtsys.get_allocation_stats().alloc\n"
        "        sim.step(n)\n"
        "        counts.append(rtsys.get_allocation_stats().alloc - before)\n"
        "    print(name, counts[0], counts[1], sim.model.joint.damping.max())\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         env={**os.environ, "NUMBA_NRT_STATS": "1"}, timeout=600)  # fmt: skip
    assert out.returncode == 0, out.stderr
    rows = [line.split() for line in out.stdout.splitlines()]
    assert [row[0] for row in rows] == ["four_bar", "driven"] and float(rows[1][3]) == 0.01
    for name, short, long, _ in rows:
        assert int(short) == int(long), (name, short, long)


def test_a_sweep_takes_a_joints_parameter_as_an_axis(tmp_path):
    """`rbsim sweep` over joints[0].damping of the pendulum: each variant runs its own damper (the energy
    lost grows with it), and no free-body "exact" errors are reported for a jointed scene."""
    import rbcli

    table = rbcli.sweep(PENDULUM, {"joints[0].damping": [0.0, 0.05], "simulation.duration": [0.5]},
                        scheduler="serial", output=tmp_path / "out")  # fmt: skip
    rows = table.to_pylist()
    assert [row["status"] for row in rows] == ["completed", "completed"]
    lost = [row["energy_initial"] - row["energy_final"] for row in rows]
    assert abs(lost[0]) < 1e-6 < lost[1]
    assert all(row["position_error_max"] is None or np.isnan(row["position_error_max"]) for row in rows)


def test_a_resumed_jointed_run_is_bitwise_the_run_never_stopped(tmp_path, monkeypatch):
    """`rbsim run --resume` of the motor-driven four-bar (dropped rows, a motor) stopped like Ctrl-C mid
    run: the resumed log's states and invariants (joint violations included) are the whole run's bits."""
    import signal

    import rbcli.runner.loop as loop
    from rbcli.record.mcap_sink import SinkMcap
    from rbcli.runner.resume import plan_resume, resume_run

    monkeypatch.setattr(loop, "CHUNK_SECONDS", 0.002)  # many chunks, so the stop falls mid-run
    scene, overrides = ROOT / "scenes" / "joints" / "four_bar.yaml", {"duration": 0.6, "record_every": 7}
    Simulation(scene, **overrides).run(sinks=[SinkMcap(tmp_path / "whole.mcap")])
    calls = []

    def progress(done: int, total: int) -> None:
        calls.append(done)
        if len(calls) == 4:
            os.kill(os.getpid(), signal.SIGINT)

    summary = Simulation(scene, **overrides).run(sinks=[SinkMcap(tmp_path / "cut.mcap")], progress=progress)
    assert summary.status == "interrupted" and 0 < summary.steps < 600
    resume_run(plan_resume(tmp_path / "cut.mcap"), [SinkMcap(tmp_path / "resumed.mcap")])
    a, b = read_trajectory(tmp_path / "resumed.mcap"), read_trajectory(tmp_path / "whole.mcap")
    assert a.step.tolist() == b.step.tolist()
    for name in ("x", "q", "P", "L"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
    assert "joint_position_violation" in a.invariants
    for name in a.invariants:
        assert a.invariants[name].tobytes() == b.invariants[name].tobytes(), name


KICKED = """
simulation: {{dt: 0.001, steps: 10, integrator: split2}}
gravity: [0, 0, -9.81]
bodies:
  - name: bob
    particles:
      positions: [[0.1, 0, 0], [-0.1, 0, 0], [0, 0.1, 0], [0, -0.1, 0], [0, 0, 0.1], [0, 0, -0.1]]
      masses: 0.25
    position: [0, 0, 0]
    velocity: {velocity}
{forces}joints:
  - {{type: distance, bodies: [bob, world], anchors: [[0, 0, 0], [0, 0, 1]]}}
"""


def test_a_kick_on_a_jointed_body_is_taken_as_the_joint_takes_it():
    """A bob hanging on a 1 m rod kicked by J = (0.6, 0, 0.9) N s at t = 0: the rod takes the radial
    part (ideal joints: the velocity is projected W-orthogonally onto G V = 0, the exact impulsive
    reaction), so the run equals one started at v = (0.6, 0, 0) / 1.5 kg, to round-off; and a velocity
    given against the rod (v = (0.4, 0, 0.5)) is projected the same way before the first step. Without
    the joint_begin stage the first step drifts along the kick and the runs part by 1.1e-9 m after 500
    steps (checked with an empty numba cache)."""
    kick = "forces:\n  - {type: impulse, body: bob, time: 0.0, vector: [0.6, 0, 0.9]}\n"
    runs = {}
    for name, velocity, forces in (("kicked", "[0, 0, 0]", kick), ("started", "[0.4, 0, 0]", ""),
                                   ("against", "[0.4, 0, 0.5]", "")):  # fmt: skip
        sim = Simulation(load_scene_text(KICKED.format(velocity=velocity, forces=forces)))
        sim.step(500)
        runs[name] = sim.data.state.x[0].copy()
    np.testing.assert_allclose(runs["kicked"], runs["started"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(runs["against"], runs["started"], rtol=0, atol=1e-12)
    assert abs(runs["started"][0]) > 0.1  # it swung
