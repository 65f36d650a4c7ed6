"""Regression tests of what the fuzzers (tests/*fuzz*.py, benchmarks/fuzz_long.py) found: each case used
to escape as a traceback (or a numpy warning) and is now a located error or the run's own report."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

import rbcli
from rbcli.cli.app import app
from rbcli.record.memory_sink import SinkMemory
from rbcli.runner.simulation import run, warm_up
from rbcli.scene.load import analyse_scene_text

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")
BODY = "  - name: b\n    particles: {{positions: [[0, 0, 0], [{s}, 0, 0], [0, {s}, 0], [0, 0, {s}]], masses: {m}}}\n"


def errors(text: str) -> list:
    spec, issues = analyse_scene_text(text, "s.yaml")
    assert spec is None
    return [i for i in issues if i.severity == "error"]


def test_a_tolerance_with_contact_loads_and_compiles():
    """Found by fuzzing: run_settings refused adaptive stepping with contact by a ValueError that escaped
    `rbcli.load_scene` and `rbsim validate` as a traceback. Adaptive dopri5 now runs contact
    (tests/physics/test_adaptive_contact.py): the scene loads and compiles with its tolerance."""
    from rbcli.scene.compile import compile_scene

    text = (
        "simulation: {dt: 0.001, steps: 5, integrator: dopri5, tolerance: 1.0e-6}\n"
        "contact: {ground: 0.0}\n"
        "bodies:\n"
        "  - {name: b, shape: {type: sphere, radius: 0.1}, spacing: 0.05, density: 100, position: [0, 0, 1]}\n"
    )
    spec, issues = analyse_scene_text(text, "s.yaml")
    assert spec is not None and not [i for i in issues if i.severity == "error"], issues
    assert compile_scene(spec).settings.tolerance == 1e-6


@pytest.mark.parametrize(
    ("motion", "quantity"),
    [("velocity: [1.0e+300, 0, 0]", "momentum"), ("angular_momentum: [0, 1.0e+300, 0]", "angular momentum"),
     ("angular_velocity: [0, 0, 1.0e+200]", "angular momentum"), ("momentum: [0, 0, -2.0e+100]", "momentum")],
)  # fmt: skip
def test_an_initial_state_beyond_the_divergence_bound_is_a_located_error(motion, quantity, tmp_path):
    """A body starting with |P| or |L| > 1e100 (the bound beyond which a run counts the state as diverged)
    loaded, and `rbsim run` then died in the kernel warm-up with a SimulationDiverged traceback."""
    text = "simulation: {dt: 0.001, steps: 5}\nbodies:\n" + BODY.format(s=1, m=1) + f"    {motion}\n"
    [error] = errors(text)
    assert (error.location.line, error.location.column) == (3, 5)  # the body
    assert error.message.startswith(f"body 'b': initial {quantity} [")
    assert "is beyond 1e+100, where a run counts the state as diverged" in error.message
    (tmp_path / "s.yaml").write_text(text)
    result = CliRunner().invoke(app, ["run", str(tmp_path / "s.yaml"), "-o", str(tmp_path / "o.mcap")])
    assert result.exit_code == 1 and result.exception.__class__ is SystemExit
    assert result.stderr.startswith(f"{tmp_path / 's.yaml'}:3:5: error: body 'b': initial {quantity}")


def test_the_bound_is_the_one_the_run_checks():
    from rbcli.physics.state import STATE_LIMIT
    from rbcli.physics.step import BLOWUP_LIMIT

    assert STATE_LIMIT == BLOWUP_LIMIT


def test_an_inertia_whose_inverse_overflows_is_a_located_error():
    """Principal moments ~1e-310 kg m^2 (masses 1e-300 kg 10 um apart) passed the singularity check (it is
    relative), and 1 / I overflowed: a numpy RuntimeWarning on the terminal, then 'spinning at inf rad/s'."""
    text = "simulation: {dt: 0.001, steps: 5}\nbodies:\n" + BODY.format(s=1e-5, m=1e-300)
    [error] = errors(text)
    assert (error.location.line, error.location.column) == (3, 5)
    assert "are so small that 1 / I overflows float64" in error.message
    # the smallest moments that invert stay accepted: 1e-300 kg at 1e-4 m gives I ~ 1e-308
    assert analyse_scene_text(text.replace("1e-05", "1e-4"), "s.yaml")[0] is not None


def test_warm_up_leaves_an_out_of_bounds_state_to_the_run(tmp_path):
    """A compiled scene whose state is out of bounds (changed in code): warm_up raised SimulationDiverged,
    a traceback out of `rbsim run`; now it compiles only, and the run stops at step 0 as diverged."""
    scene = tmp_path / "s.yaml"
    scene.write_text("simulation: {dt: 0.001, steps: 5, integrator: split2}\nbodies:\n" + BODY.format(s=1, m=1))
    compiled = rbcli.prepare(scene)
    compiled.initial_state.L[0] = [0.0, 1e300, 0.0]
    warm_up(compiled)
    memory = SinkMemory()
    summary = run(compiled, [memory])
    assert summary.status == "diverged" and "angular" in summary.message
    assert np.array_equal(memory.trajectory().step, [0])


def test_a_contact_stiffness_that_overflows_is_a_located_error():
    """gravity 9.81e300 m/s^2 with contact: the stiffness derived from it (k ~ M g / overlap) was inf, numpy
    overflow and invalid-value warnings reached the terminal and the run diverged on NaN forces."""
    text = (
        "simulation: {dt: 0.001, steps: 5, integrator: split2}\ngravity: [0, 0, -9.81e+300]\ncontact: {ground: 0}\n"
        "bodies:\n  - {name: ball, shape: {type: sphere, radius: 0.1}, spacing: 0.05, density: 100}\n"
    )
    [error] = errors(text)
    assert (error.location.line, error.location.column) == (5, 5)
    assert error.message.startswith("body 'ball': its contact stiffness, from its mass")
    assert "gravity inf m/s^2, is inf N/m, not a positive finite number" in error.message


def test_a_duration_beyond_what_a_recording_holds_is_refused(tmp_path):
    """`rbsim run --dt 4.6e16 --duration 4.6e16` ended in a struct.error traceback in the MCAP writer: the
    step's time in nanoseconds did not fit 64 bits. The bound is 2^63 - 1 ns (.rrd's signed int64)."""
    scene = tmp_path / "s.yaml"
    scene.write_text("simulation: {dt: 0.001, steps: 5}\nbodies:\n" + BODY.format(s=1, m=1))
    result = CliRunner().invoke(app, ["run", str(scene), "--dt", "4.6e16", "--duration", "4.6e16", "-o", "x.mcap"])
    assert result.exit_code == 1 and result.exception.__class__ is SystemExit
    assert result.stderr.startswith("error: --duration 4.6e+16: longer than 9.223e+09 s (292 years)")
    assert not (tmp_path / "x.mcap").exists()
    with pytest.raises(ValueError, match=r"^duration=10000000000.0: longer than"):
        rbcli.prepare(scene, dt=1e9, duration=1e10)
    rbcli.prepare(scene, dt=1e9, duration=9e9)  # 9e9 s fits
    text = "simulation: {dt: 1.0e+16, duration: 1.0e+17}\nbodies:\n" + BODY.format(s=1, m=1)
    [error] = errors(text)
    assert (error.location.line, error.location.column) == (1, 1)
    assert error.message.startswith("simulation: simulation.duration=1e+17: longer than 9.223e+09 s")


def test_a_record_every_beyond_int64_is_refused_naming_the_option(tmp_path):
    """`--record-every 1180591620717411303424` (2^70) passed the checks and the run loop raised an
    OverflowError traceback handing it to the compiled kernel (an int64)."""
    scene = tmp_path / "s.yaml"
    scene.write_text("simulation: {dt: 0.001, steps: 5}\nbodies:\n" + BODY.format(s=1, m=1))
    out = str(tmp_path / "x.mcap")
    result = CliRunner().invoke(app, ["run", str(scene), "--record-every", str(2**70), "-o", out])
    assert result.exit_code == 1 and result.exception.__class__ is SystemExit
    assert result.stderr.startswith(f"error: --record-every {2**70}: must be a whole number of steps, at least 1")
    result = CliRunner().invoke(app, ["run", str(scene), "--record-every", str(2**63 - 1), "-o", out, "-q"])
    assert result.exit_code == 0, result.stderr  # the largest int64 runs: it records the first and last step
    assert list(rbcli.read_recording(out).step) == [0, 5]


@pytest.mark.parametrize("defaults", ["[{spacing: 0.1}]", "[]"])
def test_a_body_without_a_source_after_malformed_defaults_is_a_located_error(defaults):
    """Found by fuzzing (test_mutated_data_never_crashes_the_loader): `defaults` given as a list stopped the
    schema before the bodies, and a body with none of particles, shape, mesh or compound reached the
    lattice's spacing rule, which raised StopIteration. It is the schema's own error, located at the body."""
    text = f"simulation: {{steps: 10, dt: 0.01}}\ndefaults: {defaults}\nbodies:\n  - {{name: c, mass: 2.0}}\n"
    found = [(i.location.line, i.message) for i in errors(text)]
    assert (4, "bodies[0]: missing one of 'particles', 'shape', 'mesh', 'compound'") in found, found
    # and the list is one wrong type, not also "velocity and momentum both" (a `not: {required}` rule holds
    # vacuously on a list)
    assert not [message for _, message in found if "give either" in message], found
