"""Divergence is explained (issue 17, item 3): the message names the body, the quantity, the time and a
likely cause; nothing but rbsim's own lines reaches stderr; the log ends at the last good step."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

import rbcli
from rbcli.runner.divergence import FLOOR_PER_KG, JUMP_FACTOR, EnergyGuard, explain, likely_cause
from rbcli.scene.load import load_scene_text

SPRING = """name: spring-div
simulation: {dt: 0.05, duration: 20, integrator: split2}
gravity: [0, 0, -9.81]
bodies:
  - {name: anchor_free, particles: {positions: [[0, 0, 0]], masses: [1.0], radius: [0.05]}, position: [5, 0, 0]}
  - name: bob
    particles: {positions: [[0, 0, 0]], masses: [0.1], radius: [0.05]}
    position: [0.1, 0, -1]
forces:
  - {type: spring, body: bob, anchor: [0, 0, 0], stiffness: 5000, rest_length: 1.0, damping: 0}
"""

CONTACT = """name: contact-div
simulation: {dt: 0.05, duration: 5, integrator: split2}
gravity: [0, 0, -9.81]
contact: {ground: 0, material: {restitution: 0.9, friction: 0.0}}
bodies:
  - {name: ball, particles: {positions: [[0, 0, 0]], masses: [0.5], radius: [0.05]}, position: [0, 0, 0.06]}
"""


def test_cli_names_body_quantity_time_and_cause_and_prints_nothing_else(tmp_path):
    scene = tmp_path / "spring.yaml"
    scene.write_text(SPRING)
    out = tmp_path / "s.mcap"
    run = subprocess.run([sys.executable, "-m", "rbcli", "run", str(scene), "-o", str(out)],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert run.returncode == 3, run.stderr
    error = [line for line in run.stderr.splitlines() if line.startswith("error:")]
    assert len(error) == 1
    assert "body 'bob'" in error[0] and "speed" in error[0] and "t = " in error[0]
    assert "spring's stability limit" in error[0] and "spring.yaml:10:5" in error[0]
    assert "Warning" not in run.stderr and "Traceback" not in run.stderr
    recorded = rbcli.read_recording(out)
    step = int(error[0].split("diverged at step ")[1].split(":")[0])
    assert recorded.step[-1] == step - 1  # every step up to the bad one, which is not recorded
    assert np.isfinite(recorded.x).all()


def test_contact_divergence_names_the_contact_stable_step():
    sim = rbcli.Simulation(load_scene_text(CONTACT))
    assert "contacts' stable step" in likely_cause(sim.compiled, 0)


def test_explicit_euler_on_fast_spin_is_named():
    text = """name: spin
simulation: {dt: 0.1, duration: 1, integrator: euler-matrix}
bodies:
  - name: top
    particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 3]], masses: 1}
    angular_velocity: [0, 20, 1]
"""
    compiled = rbcli.prepare(load_scene_text(text))
    assert "explicit Euler" in likely_cause(compiled, 0)


def test_explain_finds_the_first_body_out_of_range():
    compiled = rbcli.prepare(load_scene_text(SPRING))
    s = compiled.initial_state.copy()
    s.L[1] = [np.inf, 0.0, 0.0]
    text = explain(compiled, s.x, s.q, s.P, s.L, 1.25)
    assert text.startswith("body 'bob': angular speed not finite at t = 1.25 s")


def test_energy_guard_trips_on_a_jump_above_the_floor_only():
    compiled = rbcli.prepare(load_scene_text(SPRING))
    guard = EnergyGuard(compiled)
    s = compiled.initial_state.copy()
    mass = compiled.model.body_mass
    assert guard.check(s.q, s.P, s.L) is None  # first check: nothing to compare
    s.P[1] = [0.0, 0.0, mass[1] * 50.0]  # a kick from rest to 50 m/s: a huge ratio, far below the floor
    assert guard.check(s.q, s.P, s.L) is None
    speed = 1e5  # 5e9 J/kg: above the floor, and more than JUMP_FACTOR x the last check
    assert 0.5 * speed**2 > max(JUMP_FACTOR * 0.5 * 50.0**2, FLOOR_PER_KG)
    s.P[1] = [0.0, 0.0, mass[1] * speed]
    assert guard.check(s.q, s.P, s.L) == 1


RUNAWAY = """name: runaway
simulation: {dt: 0.001, duration: 10, integrator: split2}
bodies:
  - {name: ball, particles: {positions: [[0, 0, 0]], masses: [1.0], radius: [0.05]}, position: [1, 0, 0]}
forces:
  - {type: field, per: mass, bodies: all, value: [0, 0, 0], gradient: [[100, 0, 0], [0, 0, 0], [0, 0, 0]]}
"""


def test_energy_guard_stops_at_the_same_step_however_the_chunks_fall(monkeypatch):
    """x'' = 100 x grows as e^{10 t}: far from overflow (1e100 at t = 23 s) the guard stops it when its
    kinetic energy has grown 1e6-fold above 1e6 J/kg; the step is on the guard's fixed grid, whatever the
    (wall-clock-sized) chunks, and the log ends just before it."""
    import rbcli.runner.loop as loop
    import rbcli.runner.simulation as simulation
    from rbcli.record.memory_sink import SinkMemory

    results = []
    for chunk_seconds in (3e-4, 10.0):  # chunks of a few hundred steps vs everything in a few chunks
        monkeypatch.setattr(loop, "CHUNK_SECONDS", chunk_seconds)
        sink = SinkMemory()
        summary = simulation.run(rbcli.prepare(load_scene_text(RUNAWAY)), [sink])
        trajectory = sink.trajectory()
        results.append((summary.status, summary.steps, trajectory.step[-1], summary.message))
    assert results[0] == results[1], results
    status, steps, last, message = results[0]
    assert status == "diverged" and steps % 1000 == 0 and last == steps - 1
    assert "body 'ball': kinetic energy grew" in message


def test_a_division_by_zero_in_a_kernel_is_a_divergence_not_a_traceback(tmp_path):
    """rk4 on a stiff spring overflows within a few steps and divides by a zero norm: the kernels follow
    IEEE arithmetic (numba error_model numpy), so the run ends with the divergence message, exit 3."""
    scene = tmp_path / "stiff.yaml"
    text = SPRING.replace("integrator: split2", "integrator: rk4").replace("dt: 0.05", "dt: 0.01")
    scene.write_text(text.replace("stiffness: 5000", "stiffness: 1000000"))
    run = subprocess.run([sys.executable, "-m", "rbcli", "run", str(scene), "-o", str(tmp_path / "s.mcap")],
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert run.returncode == 3, run.stderr
    assert "Traceback" not in run.stderr and "body 'bob'" in run.stderr
