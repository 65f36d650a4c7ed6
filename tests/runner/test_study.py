"""Work-precision study: exact reference and fitted orders, numerical reference with its error
estimate, files that match the table, the plot, and `rbsim study --quick`. Timing, MuJoCo rows and the
.rrd output: tests/runner/test_study_timing.py."""

from __future__ import annotations

import csv
import dataclasses
import json
import struct

import numpy as np
import pytest
import typer
from conftest import make_body, make_scene
from typer.testing import CliRunner

from rbcli.analysis.errors import fit_order, rotation_error
from rbcli.cli.study import PLOT_DPI, PLOT_SIZE_INCHES, plot_work_precision, table_rows
from rbcli.cli.study import study as study_command
from rbcli.physics.integrators import INTEGRATORS
from rbcli.runner.mujoco_twin import refusal
from rbcli.runner.study import admits_exact_solution, output_grid, study, write_study_files
from rbcli.scene.compile import compile_scene
from rbcli.scene.force_specs import BodyPoint, ForceSpring

# I = diag(1, 2, 3) kg m^2 (principal axes = the user's axes): +-1 m on x (1 kg), +-1 m on y (0.5 kg)
PLATE = dict(
    particle_position=np.array([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]),
    particle_mass=np.array([1.0, 1.0, 0.5, 0.5]),
)
# omega0 = (0.5, 0.3, 1.0) rad/s body frame, near the stable major axis: L = I omega0
TUMBLE_L = np.array([0.5, 0.6, 3.0])
# Step sizes 0.05 2^-k: coarse enough that 4th-order errors (~1e-4 .. 1e-9 rad over 2 s) stay far above
# round-off (~1e-12), fine enough that 1st-order ones (~1e-2 .. 1e-3 rad) are in the asymptotic range.
ORDER_DTS = [0.05 * 2.0**-k for k in range(5)]
FIXED_STEP = [n for n, i in INTEGRATORS.items() if not i.adaptive and not i.demonstration]


def tumbling_scene(**kw):
    body = make_body("plate", angular_momentum=TUMBLE_L, velocity=np.array([0.3, 0.0, 1.0]), **PLATE)
    return make_scene([body], dt=0.05, duration=2.0, **kw)


@pytest.fixture(scope="module")
def torque_free_study():
    return study(tumbling_scene(), integrators=FIXED_STEP, dts=ORDER_DTS, min_time=0.0, mujoco=False)


def test_torque_free_scene_uses_the_exact_reference(torque_free_study):
    assert admits_exact_solution(compile_scene(tumbling_scene(gravity=np.array([0, 0, -9.81]))))
    assert torque_free_study.reference.kind == "exact"
    assert torque_free_study.primary_error == "rotation"
    assert set(torque_free_study.conserved) == {"energy", "momentum", "angular_momentum"}


@pytest.mark.parametrize("name", FIXED_STEP)
def test_fitted_slope_recovers_the_nominal_order(torque_free_study, name):
    """log(error) against log(dt) has slope p for a method of order p (asymptotic range); 0.2 allows
    for the leading error term's coefficient drifting a little over a 16x range of dt."""
    runs = [r for r in torque_free_study.runs if r.integrator == name]
    assert [r.status for r in runs] == ["completed"] * len(ORDER_DTS)
    fit = torque_free_study.fits[name].rotation
    if name.startswith("exact"):  # the exact free-body flow: round-off only, nothing to fit
        assert max(r.rotation_error_max for r in runs) < 1e-10
        return
    assert fit.order is not None and fit.points >= 3, fit
    assert abs(fit.order - INTEGRATORS[name].order) < 0.2, (name, fit)


def test_adaptive_method_fits_its_fixed_step_order_and_follows_its_tolerance():
    """dopri5 at fixed steps is order 5 (steps 0.1 2^-k: errors 1e-9 .. 1e-12 rad, above round-off);
    with a tolerance (its own rows, no fitted order) a tighter tolerance takes more steps and errs less.
    The fitted range is still pre-asymptotic: the slopes per halving are 5.30, 5.15, 5.03 (5.18, 5.08,
    4.96 when dopri5 rebuilt m = R^T L at each step, which also rescaled |m| to |L|), so the fit over
    0.1 .. 0.025 is 5.23 and the finest pair's slope is held to 5 more tightly."""
    result = study(tumbling_scene(), integrators=["dopri5"], dts=[0.1 * 2.0**-k for k in range(4)],
                   tolerances=[1e-4, 1e-8], min_time=0.0, mujoco=False)  # fmt: skip
    fit = result.fits["dopri5"].rotation
    assert fit.order is not None and abs(fit.order - 5) < 0.3, fit
    fixed = {r.dt: r.rotation_error_max for r in result.runs if r.tolerance is None}
    assert abs(np.log2(fixed[0.05] / fixed[0.025]) - 5) < 0.2, fixed
    loose, tight = [r for r in result.runs if r.tolerance is not None]
    assert (loose.tolerance, tight.tolerance) == (1e-4, 1e-8)
    assert tight.steps > loose.steps and tight.rotation_error_max < loose.rotation_error_max
    assert tight.force_evals == (tight.steps + tight.rejected_steps) * INTEGRATORS["dopri5"].force_evals
    assert result.run_fitted_order(tight) is None
    assert table_rows(result)[-1][0] == "dopri5 tol=1e-08" and table_rows(result)[-1][7] == "adaptive"


def test_errors_and_drift_are_measured_against_the_exact_motion(torque_free_study):
    """Centre of mass: x0 + v0 t exactly for every method (P is constant, x += dt P / M is exact),
    so position errors are round-off; rotation errors shrink with dt; energy drift is reported."""
    for run in torque_free_study.runs:
        assert run.position_error_max < 1e-12
        assert run.energy_drift is not None and run.energy_drift >= 0.0
        assert run.ns_per_body_step > 0 and run.force_evals == run.steps * INTEGRATORS[run.integrator].force_evals
    euler = [r.rotation_error_max for r in torque_free_study.runs if r.integrator == "euler-matrix"]
    assert euler == sorted(euler, reverse=True)


def test_forced_scene_reports_a_reference_error_below_the_errors_it_ranks():
    """A spring tether off the centre of mass under gravity: torque, so no closed form. The reference
    (best method at dt_min / 16) differs from itself at 2 dt_ref by less than any studied run's error."""
    spring = ForceSpring(end_a=BodyPoint(body="plate", point=np.array([1.0, 0, 0])), anchor=np.array([0, 0, 2.0]),
                         stiffness=20.0, rest_length=1.0)  # fmt: skip
    body = make_body("plate", angular_momentum=TUMBLE_L, **PLATE)
    sim = make_scene([body], dt=0.02, duration=1.0, gravity=np.array([0, 0, -9.81]))
    scene = type(sim)(**{**sim.__dict__, "forces": (spring,)})
    assert not admits_exact_solution(compile_scene(scene))
    names = [n for n in ("euler-matrix", "split2") if n in INTEGRATORS]
    result = study(scene, integrators=names, dts=[0.02, 0.01, 0.005], min_time=0.0)
    ref = result.reference
    assert ref.kind == "numerical" and ref.dt == pytest.approx(0.005 / 16)
    assert result.conserved == ("energy",)
    assert ref.rotation_error_estimate < min(r.rotation_error_max for r in result.runs)
    assert ref.position_error_estimate < min(r.position_error_max for r in result.runs)
    assert result.fits["euler-matrix"].position.order == pytest.approx(1.0, abs=0.3)
    # MuJoCo's twin would be a different problem (its tendons are not rbsim's springs): no rows, and why
    assert "spring" in refusal(compile_scene(scene))
    assert not [r for r in result.runs if r.engine == "mujoco"]
    assert result.mujoco_skipped and f"no MuJoCo rows: {result.mujoco_skipped}" in result.notes


def test_files_match_the_table(tmp_path, torque_free_study):
    csv_path, json_path = write_study_files(torque_free_study, tmp_path)
    rows = list(csv.DictReader(csv_path.open()))
    data = json.loads(json_path.read_text())
    table = table_rows(torque_free_study)
    assert len(rows) == len(table) == len(data["runs"]) == len(torque_free_study.runs)
    for row, cells, run in zip(rows, table, data["runs"], strict=True):
        assert cells[0] == row["integrator"] == run["integrator"]
        assert int(cells[2]) == int(row["steps"]) == run["steps"]
        # the table rounds to 3-4 significant digits; CSV and JSON carry the full value
        for cell, key in ((1, "dt"), (3, "rotation_error_max"), (4, "position_error_max"), (5, "energy_drift"),
                          (6, "ns_per_body_step")):  # fmt: skip
            assert float(row[key]) == run[key]
            assert float(cells[cell]) == pytest.approx(run[key], rel=5e-3, abs=0.5 if key.startswith("ns") else 0)
        fitted = run["fitted_order"]
        assert cells[7].startswith("—" if fitted is None else f"{fitted:.2f}")


def test_png_is_a_valid_image_of_the_expected_size(tmp_path, torque_free_study):
    png, svg = plot_work_precision(torque_free_study, tmp_path / "plot")
    head = png.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR"
    width, height = struct.unpack(">II", head[16:24])
    assert (width, height) == (round(PLOT_SIZE_INCHES[0] * PLOT_DPI), round(PLOT_SIZE_INCHES[1] * PLOT_DPI))
    assert svg.read_text().lstrip().startswith("<?xml")


def test_the_cost_range_holds_the_cost_and_plots_where_a_sample_is_the_median(tmp_path, torque_free_study):
    """The range is the samples rescaled by cost / median: a fastest sample equal to the median rounds
    past the cost for some values (a negative error bar, refused by matplotlib); the range holds it."""
    rng = np.random.default_rng(3)
    seconds, cost = next(
        (s, c) for s, c in zip(rng.uniform(1e-7, 1e-4, 10_000), rng.uniform(1e-6, 1e-3, 10_000), strict=True)
        if s * (c / s) > c
    )  # fmt: skip
    runs = [dataclasses.replace(run, seconds_per_step=seconds, seconds_per_step_min=seconds,
                                seconds_per_step_max=seconds, cost_per_sim_second=cost)
            for run in torque_free_study.runs]  # fmt: skip
    low, high = runs[0].cost_per_sim_second_range
    assert low <= cost <= high
    plot_work_precision(dataclasses.replace(torque_free_study, runs=runs), tmp_path / "plot")


def test_quick_cli_run_writes_table_files_and_plot(tmp_path):
    scene = tmp_path / "spin.yaml"
    scene.write_text(
        "name: spin\nsimulation: {dt: 0.01, duration: 5.0}\nbodies:\n  - name: plate\n"
        "    particles: {positions: [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]], masses: [1, 1, 0.5, 0.5]}\n"
        "    angular_momentum: [0.5, 0.6, 3.0]\n"
    )
    app = typer.Typer()
    app.command("study")(study_command)
    app.command("other")(lambda: None)  # two commands, so "study" is a subcommand as in rbsim
    out = tmp_path / "out"
    args = ["study", str(scene), "--quick", "-i", "euler-matrix", "-i", "split2", "--no-mujoco", "--out", str(out)]
    result = CliRunner().invoke(app, args)
    assert result.exit_code == 0, result.output
    assert "euler-matrix" in result.output and "split2" in result.output
    rows = list(csv.DictReader((out / "spin-study.csv").open()))
    assert [r["integrator"] for r in rows] == ["euler-matrix"] * 3 + ["split2"] * 3
    assert (out / "spin-study.json").is_file() and (out / "spin-study.svg").is_file()
    assert (out / "spin-study.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_rotation_error_is_the_geodesic_angle():
    """angle(R_a^T R_b) for a rotation by theta about any axis is theta, down to 1e-12 rad."""
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    for theta in (1e-12, 1e-6, 0.5, 3.0):
        q = np.concatenate([[np.cos(theta / 2)], np.sin(theta / 2) * axis])
        assert rotation_error(np.array([1.0, 0, 0, 0]), q) == pytest.approx(theta, rel=1e-12)
        assert rotation_error(q, -q) < 1e-15  # q and -q are the same rotation


def test_fit_order_skips_saturated_and_round_off_points():
    """error = dt^2, saturated at the two coarsest dts and flattened by round-off at 1e-8 (above the
    stated floor 1e-9): the fit keeps the 12 points in between and finds the slope 2 exactly."""
    dt = 2.0 ** -np.arange(20)
    error = np.maximum(dt**2, 1e-8)
    error[:2] = 3.1
    fit = fit_order(dt, error, floor=1e-9, ceiling=0.3)
    assert fit.order == pytest.approx(2.0, abs=1e-9) and fit.points == 12


def test_output_grid_aligns_recorded_times():
    grid = output_grid([0.04, 0.01, 0.02], duration=1.0)
    assert grid.base == pytest.approx(0.04) and grid.times[-1] == pytest.approx(1.0)
    assert grid.steps_per_base(0.01) == 4
    with pytest.raises(ValueError, match="common multiple"):
        output_grid([0.01, 0.003], duration=0.02)
