"""A run's options as one object (RunOptions) from `rbsim run` to `run_settings`, and one build of the
run (issue 44): the Simulation whose kernels `rbsim run` loads is the one that runs, and loading them
changes nothing a run depends on."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import rbcli
from rbcli.cli.app import app
from rbcli.record.read import read_mcap
from rbcli.runner import simulation as simulation_module
from rbcli.scene import compile as compile_module
from rbcli.scene.compile import RunOptions, RunOverrides

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"  # split2, four bodies of four particles


def test_the_keyword_form_has_exactly_the_options_fields():
    """RunOverrides (the keywords of prepare, simulate, Simulation, compile_scene) is RunOptions spelt as
    keywords: a field added to one and not the other would be refused, or silently dropped."""
    assert set(RunOverrides.__annotations__) == {field.name for field in dataclasses.fields(RunOptions)}


def test_options_and_keywords_give_the_same_settings_and_keywords_win():
    options = RunOptions(dt=2e-3, duration=0.5, integrator="rk4", record_every=5, compression="lz4")
    by_object = rbcli.prepare(TUTORIAL, options).settings
    by_keywords = rbcli.prepare(TUTORIAL, dt=2e-3, duration=0.5, integrator="rk4", record_every=5,
                                compression="lz4").settings  # fmt: skip
    assert by_object == by_keywords
    assert (by_object.dt, by_object.steps, by_object.integrator, by_object.record_every) == (2e-3, 250, "rk4", 5)
    assert rbcli.prepare(TUTORIAL, options, dt=1e-3, integrator=None).settings == dataclasses.replace(
        by_object, dt=1e-3, steps=500
    )  # keywords win, and one given as None is not given: the object's integrator stays
    assert RunOptions(dt=1e-3, tolerance=None).given() == {"dt": 1e-3}


def test_a_refused_option_is_named_as_the_option_given():
    with pytest.raises(ValueError, match=r"^dt=-1\.0: must be a positive"):
        rbcli.prepare(TUTORIAL, RunOptions(dt=-1.0))
    result = CliRunner().invoke(app, ["run", str(TUTORIAL), "--dt", "-1", "-o", "/nonexistent/never.mcap"])
    assert result.exit_code == 1 and "--dt -1: must be a positive" in result.output


def test_a_compiled_scene_takes_no_options():
    compiled = rbcli.prepare(TUTORIAL)
    for given in ({"options": RunOptions(dt=1e-3)}, {"dt": 1e-3}):
        with pytest.raises(ValueError, match="overrides apply when compiling"):
            rbcli.Simulation(compiled, **given)
    rbcli.Simulation(compiled, RunOptions())  # nothing given: nothing to refuse


def test_rbsim_run_compiles_the_model_once_and_runs_the_simulation_whose_kernels_it_loaded(tmp_path, monkeypatch):
    """Before, `rbsim run` built a Simulation to load the kernels, dropped it, and built another to run."""
    compiled, made, loaded, ran = [], [], [], []
    compile_model = compile_module.compile_model
    monkeypatch.setattr(compile_module, "compile_model", lambda spec: compiled.append(spec) or compile_model(spec))
    Simulation = simulation_module.Simulation
    init, load_kernels, run = Simulation.__init__, Simulation.load_kernels, Simulation.run
    monkeypatch.setattr(Simulation, "__init__", lambda self, *a, **k: made.append(self) or init(self, *a, **k))
    monkeypatch.setattr(Simulation, "load_kernels", lambda self: loaded.append(self) or load_kernels(self))
    monkeypatch.setattr(Simulation, "run", lambda self, *a, **k: ran.append(self) or run(self, *a, **k))
    out = tmp_path / "t.mcap"
    result = CliRunner().invoke(app, ["run", str(TUTORIAL), "-o", str(out), "--duration", "0.05", "-q"])
    assert result.exit_code == 0, result.output
    assert len(compiled) == 1 and len(made) == 1 and loaded == ran == made
    expected = rbcli.simulate(TUTORIAL, duration=0.05)
    for name in ("x", "q", "P", "L"):  # the kernels' load left nothing behind: bit for bit a fresh run's
        assert np.array_equal(getattr(read_mcap(out), name), getattr(expected, name)), name


@pytest.mark.parametrize("scene", ["tutorial.yaml", "tumbling_plate.yaml"])
def test_loading_the_kernels_changes_no_carried_array(scene):
    sim = rbcli.Simulation(ROOT / "scenes" / scene)
    sim.step(3)  # carried work that is not zero
    before = {name: array.copy() for name, array in sim.data.carried().items()}
    sim.load_kernels()
    after = sim.data.carried()
    assert sim.step_index == 3 and set(after) == set(before)
    for name, array in before.items():
        assert array.tobytes() == after[name].tobytes(), name
