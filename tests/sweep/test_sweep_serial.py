"""A sweep run in one process: a row per variant whose final state is bitwise the state of the same
scene edited by hand and stepped by `rbcli.Simulation`; a variant built to diverge is a failed row and the
others complete; the Python API and the table's parameters; `rbsim info` on the table."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest
from sweep_cases import (  # noqa: F401 - a fixture
    DIVERGING_STIFFNESS,
    SPRING_SCENE,
    STATE_COLUMNS,
    nan_as_text,
    reference_state,
    rows_without_wall_time,
    spring_sweep_fixture,  # noqa: F401 - a fixture
)
from typer.testing import CliRunner

import rbcli
from rbcli.cli.app import app
from rbcli.scene.spec import SceneError
from rbcli.sweeps.load import load_sweep
from rbcli.sweeps.run import run_sweep

runner = CliRunner()


def test_rows_are_the_variants_run_one_by_one_and_the_diverging_one_fails(spring_sweep, tmp_path):
    result = run_sweep(load_sweep(spring_sweep), scheduler="serial", output=tmp_path / "out")
    rows = result.table.to_pylist()
    # product order: the last axis varies fastest
    expected = [(k, i) for k in (50, 100.0, DIVERGING_STIFFNESS) for i in ("split2", "rk4")]
    assert [(r["forces[0].stiffness"], r["simulation.integrator"]) for r in rows] == expected
    assert [r["variant"] for r in rows] == list(range(6))
    for row in rows:
        if row["forces[0].stiffness"] == DIVERGING_STIFFNESS:
            # split2 reports the divergence; rk4's kernel (in this working tree) raises ZeroDivisionError on
            # the overflowed state first: a failed row with that message either way, and the sweep goes on
            assert row["status"] in ("diverged", "error") and row["message"], row
            if row["simulation.integrator"] == "split2":
                assert row["status"] == "diverged" and "diverged at step" in row["message"] and row["steps"] < 200
                # the spring's place is given in the base scene file, not in the variant's generated YAML
                line = next(n for n, s in enumerate(SPRING_SCENE.splitlines(), 1) if "type: spring" in s)
                assert f"spring.yaml:{line}:" in row["message"], row["message"]
            continue
        assert row["status"] == "completed", row["message"]
        state = reference_state(row["forces[0].stiffness"], row["simulation.integrator"])
        assert row["steps"] == 200 and row["integrator"] == row["simulation.integrator"] and row["body_count"] == 1
        for column in STATE_COLUMNS:
            got = np.array(row[column], dtype=np.float64)
            assert got.shape == state[column].shape
            assert got.tobytes() == state[column].tobytes(), column  # bitwise, not approximately
    assert result.failed == 2 and result.ran == 6 and result.complete
    on_disk = pq.read_table(tmp_path / "out" / "results.parquet")
    assert nan_as_text(on_disk.to_pylist()) == nan_as_text(result.table.to_pylist())  # NaN != NaN in equals


def test_energy_drift_is_measured_where_energy_is_conserved(spring_sweep, tmp_path):
    table = run_sweep(load_sweep(spring_sweep), scheduler="serial", output=tmp_path / "out").table
    row = table.to_pylist()[2]  # k = 100, split2: undamped spring + gravity conserve energy
    traj = rbcli.simulate(rbcli.load_scene(spring_sweep.parent / "spring.yaml"), record_every=2)
    energy = traj.invariants["energy_total"]
    scale = max(abs(energy[0]), abs(traj.invariants["energy_kinetic"][0]))
    # the sweep records 101 frames (every 2nd of 200 steps): the same frames as this run
    assert row["energy_drift"] == pytest.approx(np.max(np.abs(energy - energy[0])) / scale, rel=1e-12)
    assert row["energy_initial"] == energy[0] and row["momentum_drift"] is None  # the spring anchor is external


def test_exact_solution_errors_where_there_is_one(tmp_path):
    (tmp_path / "free.yaml").write_text(SPRING_SCENE.split("forces:")[0])  # gravity only: exact motion known
    table = rbcli.sweep(tmp_path / "free.yaml", {"simulation.dt": [0.02, 0.01]}, scheduler="serial")
    errors = table.column("rotation_error_max").to_pylist()
    assert all(e is not None and e > 0 for e in errors)
    assert errors[1] < errors[0] / 3  # split2 is second order: halving dt quarters the error
    assert table.column("position_error_max").to_pylist()[0] < 1e-9  # free flight: exact for split2 up to round-off


def test_python_api_grid_and_random_axes_with_seed(tmp_path):
    (tmp_path / "spring.yaml").write_text(SPRING_SCENE)
    axes = {
        "forces[0].stiffness": {"grid": {"start": 50, "stop": 150, "num": 3}},
        "bodies[0].angular_momentum[2]": {"random": {"distribution": "normal", "mean": 12.0, "std": 0.5}},
    }
    table = rbcli.sweep(tmp_path / "spring.yaml", axes, samples=2, seed=3, scheduler="serial")
    assert table.num_rows == 6
    assert table.column("forces[0].stiffness").to_pylist() == [50, 50, 100, 100, 150, 150]  # whole: integers
    draws = table.column("bodies[0].angular_momentum[2]").to_pylist()
    assert draws[0:2] == draws[2:4] == draws[4:6] and draws[0] != draws[1]  # the samples vary fastest
    again = rbcli.sweep(tmp_path / "spring.yaml", axes, samples=2, seed=3, scheduler="serial")
    assert again.column("bodies[0].angular_momentum[2]").to_pylist() == draws
    other = rbcli.sweep(tmp_path / "spring.yaml", axes, samples=2, seed=4, scheduler="serial")
    assert other.column("bodies[0].angular_momentum[2]").to_pylist() != draws
    meta = rbcli.sweeps.table.sweep_metadata(table)
    assert meta["seed"] == 3 and meta["samples"] == 2 and meta["variants"] == 6
    # the draws are what the row ran: the final angular momentum about the centre of mass changes with
    # the spring's torque, but its initial value is the draw (checked through the scene itself)
    with pytest.raises(SceneError) as bad:
        rbcli.sweep(tmp_path / "spring.yaml", {"simulation.dt": ["fast"]}, scheduler="serial")
    assert "'fast' at simulation.dt gives an invalid scene" in str(bad.value)


def test_a_combination_the_loader_rejects_is_a_failed_row(tmp_path):
    (tmp_path / "free.yaml").write_text(SPRING_SCENE.split("forces:")[0])
    # each axis alone is valid with the scene's dt = 0.01 s and duration = 2 s; dt = 1 s with duration
    # 0.5 s is not (a step longer than the run)
    axes = {"simulation.dt": [0.01, 1.0], "simulation.duration": [2.0, 0.5]}
    table = rbcli.sweep(tmp_path / "free.yaml", axes, scheduler="serial")
    status = table.column("status").to_pylist()
    assert status == ["completed", "completed", "completed", "invalid"]
    message = table.column("message").to_pylist()[3]
    line = SPRING_SCENE.splitlines()[1]
    assert "dt = 1 s is longer than duration = 0.5 s" in message
    assert f"free.yaml:2:{line.index('0.01') + 1}: error" in message, message  # at dt in the base scene


def test_logs_are_each_variants_recording_and_change_no_row(spring_sweep, tmp_path):
    spec = load_sweep(spring_sweep)
    plain = run_sweep(spec, scheduler="serial", output=tmp_path / "plain")
    logged = run_sweep(spec, scheduler="serial", output=tmp_path / "logged", logs=True)
    without_log = [rows_without_wall_time(run.table.drop_columns(["log"])) for run in (plain, logged)]
    assert without_log[0] == without_log[1]
    row = logged.table.to_pylist()[2]
    assert row["log"] == str((tmp_path / "logged" / "logs" / "variant-000002.mcap").resolve())
    recorded = rbcli.read_recording(row["log"])
    assert recorded.t.size == 101 and recorded.status == "completed"
    for column in STATE_COLUMNS:  # the last-frame columns are the recording's last frame, bitwise
        frame = getattr(recorded, column.removesuffix("_final"))[-1]
        assert frame.tobytes() == np.array(row[column], dtype=np.float64).tobytes(), column
    assert plain.table.column("log").null_count == 6


def test_sweep_command_and_info_on_the_table(spring_sweep, tmp_path):
    out = tmp_path / "out"
    run = runner.invoke(app, ["sweep", str(spring_sweep), "--serial", "-o", str(out)])
    assert run.exit_code == 0, run.output
    assert "6 variants: 4 completed, " in run.output  # and the two of k = 1e6, failed (see the first test)
    assert "warning: axes[0].values[2]: 1000000.0 at forces[0].stiffness:" in run.output  # above the stable step
    info = runner.invoke(app, ["info", str(out / "results.parquet")])
    assert info.exit_code == 0, info.output
    assert "variants:   6 of 6 finished" in info.output
    assert "status:     4 completed, " in info.output
    assert "completed variants (min, median, max):" in info.output and "  energy drift: " in info.output
    assert "variant 4 (forces[0].stiffness = 1e+06, simulation.integrator = split2): diverged" in info.output
    broken = tmp_path / "broken.parquet"
    broken.write_bytes(b"not parquet")
    assert runner.invoke(app, ["info", str(broken)]).exit_code == 1
