"""`rbsim study` timing and comparison rows: kernel timing with its spread (call overhead taken off),
costs that rise as dt halves, MuJoCo's Euler and RK4 on the same scene, and the study as an .rrd read
back with rerun's own reader."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np
import pytest
import typer
from conftest import make_body, make_scene
from typer.testing import CliRunner

from rbcli.cli.study import study as study_command
from rbcli.record.rerun_sink import read_study_rrd, verify_rrd_command
from rbcli.runner.kernel_timing import MIN_SAMPLES, time_kernel
from rbcli.runner.mujoco_twin import mujoco_version
from rbcli.runner.study import study, write_study_files

# A body whose particle frame is not its principal frame (the cloud is rotated, inertia off-diagonal in
# the user's frame), tilted, spinning and thrown under gravity: the MuJoCo twin must get the principal
# moments, the body frame and the initial state right for its errors to vanish at their orders.
_TILT = np.array([np.cos(0.3), np.sin(0.3) * 0.6, np.sin(0.3) * 0.8, 0.0])  # wxyz, about (0.6, 0.8, 0)


def _rotated_plate() -> np.ndarray:
    c, s = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.array([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 0.5], [0, 0, -0.5]]) @ R.T


def thrown_plate(dt: float = 0.02, duration: float = 2.0):
    body = make_body(
        "plate",
        particle_position=_rotated_plate(),
        particle_mass=np.array([1.0, 1.0, 0.5, 0.5, 0.25, 0.25]),
        orientation_wxyz=_TILT / np.linalg.norm(_TILT),
        velocity=np.array([0.3, -0.2, 4.0]),
        angular_momentum=np.array([0.5, 0.6, 3.0]),
    )
    return make_scene([body], dt=dt, duration=duration, gravity=np.array([0.0, 0.0, -9.81]))


# dt 0.02 2^-k over 2 s: 100 .. 800 steps, enough that each run's kernel time (~50-800 us) dwarfs the
# call overhead and the clock's resolution; 0.05 s of timing per point keeps the study near a second
# (the command's default is 0.2 s).
STEPS = [0.02 * 2.0**-k for k in range(4)]
MIN_TIME = 0.05


@pytest.fixture(scope="module")
def timed_study(tmp_path_factory):
    result = study(thrown_plate(), integrators=["split2", "rk4"], dts=STEPS, min_time=MIN_TIME)
    _, json_path = write_study_files(result, tmp_path_factory.mktemp("study"))
    return result, json.loads(json_path.read_text())


def test_costs_rise_monotonically_as_dt_halves_in_the_json(timed_study):
    """Halving dt doubles the steps over the same simulated time: each row's cost per simulated second
    must exceed the previous (coarser) one's, for every engine; the per-step cost stays within the
    spread a kernel timing allows (2x, against the 2-4x jumps of whole-run timings of 25-100 steps)."""
    _, data = timed_study
    for name in dict.fromkeys(r["integrator"] for r in data["runs"]):
        rows = [r for r in data["runs"] if r["integrator"] == name]
        assert [r["dt"] for r in rows] == pytest.approx(STEPS)
        cost = [r["cost_per_sim_second"] for r in rows]
        assert all(b > a for a, b in zip(cost, cost[1:], strict=False)), (name, cost)
        per_step = [r["seconds_per_step"] for r in rows]
        assert max(per_step) / min(per_step) < 2.0, (name, per_step)


def test_every_point_reports_its_spread(timed_study):
    """min <= median <= max over >= MIN_SAMPLES samples that together took at least min_time of CPU."""
    result, data = timed_study
    assert data["timing"]["min_time"] == MIN_TIME and data["timing"]["load_average"] >= 0.0
    for run, row in zip(result.runs, data["runs"], strict=True):
        assert 0 < row["seconds_per_step_min"] <= row["seconds_per_step"] <= row["seconds_per_step_max"]
        assert row["cost_spread"] == pytest.approx(row["seconds_per_step_max"] / row["seconds_per_step_min"])
        assert row["timing_samples"] >= MIN_SAMPLES and row["timed_runs"] >= row["timing_samples"]
        assert row["timed_runs"] * row["steps"] * row["seconds_per_step_min"] >= 0.5 * MIN_TIME, row
        assert row["wall_seconds_per_step"] > 0
        low, high = run.cost_per_sim_second_range
        assert low <= run.cost_per_sim_second <= high


def test_mujoco_rows_measure_the_same_scene(timed_study):
    """With mujoco installed: MuJoCo's Euler and RK4 rows, against the same exact reference, converge
    at orders 1 and 4 (an error of the twin's mass, inertia, body frame or initial state would leave a
    floor instead); without it, no rows and a note that says so."""
    result, data = timed_study
    rows = [r for r in data["runs"] if r["engine"] == "mujoco"]
    if mujoco_version() is None:
        assert not rows and "not installed" in data["mujoco"]["skipped"]
        assert any("not installed" in note for note in result.notes)
        return
    assert data["mujoco"] == {"version": mujoco_version(), "skipped": None}
    assert [r["integrator"] for r in rows] == ["mujoco-euler"] * 4 + ["mujoco-rk4"] * 4
    assert all(r["status"] == "completed" for r in rows)
    # rotation from the tilted spin; position: MuJoCo's semi-implicit Euler is first order in x too
    assert result.fits["mujoco-euler"].rotation.order == pytest.approx(1.0, abs=0.25)
    assert result.fits["mujoco-euler"].position.order == pytest.approx(1.0, abs=0.25)
    assert result.fits["mujoco-rk4"].rotation.order == pytest.approx(4.0, abs=0.3)


def test_time_kernel_bills_the_steps_not_the_call():
    """A fake run that spends 200 us per call plus 10 us per step (CPU spin): 20 steps take 400 us,
    of which the kernel is 200 us: time_kernel reports ~10 us per step, not 20."""

    def spin(seconds: float) -> None:
        end = time.thread_time() + seconds
        while time.thread_time() < end:
            pass

    def advance(n: int) -> int:
        spin(200e-6 + n * 10e-6)
        return n

    timing = time_kernel(lambda: None, advance, 20, min_time=0.05)
    assert timing.median == pytest.approx(10e-6, rel=0.15), timing
    assert timing.overhead == pytest.approx(200e-6, rel=0.15), timing
    assert timing.low <= timing.median <= timing.high and timing.samples >= MIN_SAMPLES


def _app() -> typer.Typer:
    app = typer.Typer()
    app.command("study")(study_command)
    app.command("other")(lambda: None)  # two commands, so "study" is a subcommand as in rbsim
    return app


SPIN_SCENE = (
    "name: spin\nsimulation: {dt: 0.01, duration: 1.0}\ngravity: [0, 0, -9.81]\nbodies:\n  - name: plate\n"
    "    particles: {positions: [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], masses: [1, 1, 0.5, 0.5]}\n"
    "    angular_momentum: [0.5, 0.6, 3.0]\n"
)


def test_rerun_output_reads_back_as_the_json(tmp_path):
    """`--rerun x.rrd`: per integrator the errors and the cost spread as scalars on the dt and cost
    timelines, the PNG byte for byte, read back with rerun's reader and verified by `rerun rrd verify`."""
    scene = tmp_path / "spin.yaml"
    scene.write_text(SPIN_SCENE)
    out, rrd = tmp_path / "out", tmp_path / "views" / "spin.rrd"
    args = ["study", str(scene), "--quick", "-i", "split2", "-i", "dopri5", "--min-time", "0.01", "--out", str(out),
            "--rerun", str(rrd)]  # fmt: skip
    result = CliRunner().invoke(_app(), args)
    assert result.exit_code == 0, result.output
    data = json.loads((out / "spin-study.json").read_text())
    back = read_study_rrd(rrd)
    assert back.images["plot"] == ((out / "spin-study.png").read_bytes(), "image/png")
    assert "split2" in back.texts["study"] and "reference: exact" in back.texts["study"].lower()
    series = {}
    for index, row in enumerate(data["runs"]):
        name = row["integrator"] + ("-adaptive" if row["tolerance"] is not None else "")
        series.setdefault(name, []).append(row | {"index": index})
    expected = {"split2", "dopri5", "dopri5-adaptive"} | ({"mujoco-euler", "mujoco-rk4"} if mujoco_version() else set())
    assert set(series) == expected
    for name, rows in series.items():
        cost = back.values[f"study/cost/{name}"]
        expect = [[r["cost_per_sim_second"] * r[k] / r["seconds_per_step"] for k in
                   ("seconds_per_step_min", "seconds_per_step", "seconds_per_step_max")] for r in rows]  # fmt: skip
        np.testing.assert_allclose(cost, expect, rtol=1e-12)
        errors = back.values[f"study/rotation_error_max/{name}"][:, 0]
        np.testing.assert_array_equal(errors, [r["rotation_error_max"] for r in rows])
        logs = back.values[f"study/log10_rotation_error_max/{name}"][:, 0]
        np.testing.assert_allclose(logs, np.log10(np.maximum(errors, 1e-300)), rtol=1e-12)
        times = back.timelines[f"study/rotation_error_max/{name}"]
        np.testing.assert_array_equal(times["run"], [r["index"] for r in rows])
        np.testing.assert_allclose(times["dt"], [r["dt"] for r in rows], rtol=0, atol=1e-9)  # ns on the timeline
        np.testing.assert_allclose(times["cost"], [r["cost_per_sim_second"] for r in rows], rtol=0, atol=1e-9)
    verify = subprocess.run(verify_rrd_command(rrd), capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stderr


def test_rerun_option_needs_an_rrd_path(tmp_path):
    scene = tmp_path / "spin.yaml"
    scene.write_text(SPIN_SCENE)
    result = CliRunner().invoke(_app(), ["study", str(scene), "--quick", "--rerun", str(tmp_path / "x.mcap")])
    assert result.exit_code == 1 and ".rrd" in result.output


def test_without_mujoco_the_study_runs_and_says_so(monkeypatch):
    """mujoco unimportable (as without the [bench] extra): no MuJoCo rows and a note by default; asking
    for them is an error that names the extra."""
    monkeypatch.setitem(sys.modules, "mujoco", None)  # `import mujoco` now raises ImportError
    assert mujoco_version() is None
    result = study(thrown_plate(duration=0.2), integrators=["split2"], dts=STEPS[:2], min_time=0.0)
    assert [r.engine for r in result.runs] == ["rbsim", "rbsim"]
    assert "not installed" in result.mujoco_skipped and any("[bench]" in note for note in result.notes)
    with pytest.raises(ValueError, match=r"\[bench\]"):
        study(thrown_plate(duration=0.2), integrators=["split2"], dts=STEPS[:2], min_time=0.0, mujoco=True)


def test_a_diverging_mujoco_run_is_reported_and_logs_nothing(tmp_path, monkeypatch):
    """The fast spin (omega0 = (60, 40, 80) rad/s) under MuJoCo's Euler at dt = 1/60 s blows up; MuJoCo
    resets a bad state and warns instead of stopping: the twin reports "diverged" from the warning
    counters, and MuJoCo's own handler (which appends to MUJOCO_LOG.TXT in the working directory) is
    kept quiet."""
    from rbcli.api import load_scene
    from rbcli.runner.mujoco_twin import MUJOCO_METHODS, MujocoTwin
    from rbcli.scene.compile import compile_scene

    compiled = compile_scene(load_scene("scenes/verification/fast_spin.yaml"))
    monkeypatch.chdir(tmp_path)
    if mujoco_version() is None:
        with pytest.raises(ImportError):
            MujocoTwin(compiled, MUJOCO_METHODS["mujoco-euler"])
        return
    twin = MujocoTwin(compiled, MUJOCO_METHODS["mujoco-euler"])
    traj = twin.trajectory(compiled.settings.steps, 1)
    assert traj.status == "diverged" and traj.summary.steps < compiled.settings.steps
    assert np.isfinite(traj.q).all()  # frames up to the blow-up only
    assert not list(tmp_path.iterdir()), list(tmp_path.iterdir())
