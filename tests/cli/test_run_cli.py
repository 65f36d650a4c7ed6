"""`rbsim run` end to end: the files it writes read back (with the mcap and rerun libraries) to the same
states `rbcli.simulate` returns; bad input exits 1 with a clear message and writes nothing."""

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import rbcli
from rbcli.cli.app import app
from rbcli.record.read import read_mcap, read_rrd

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"
runner = CliRunner()


@pytest.fixture(scope="module")
def reference():
    return rbcli.simulate(rbcli.load_scene(TUTORIAL), duration=0.2)


def test_run_writes_an_mcap_holding_exactly_the_trajectory(tmp_path, reference):
    out = tmp_path / "t.mcap"
    result = runner.invoke(app, ["run", str(TUTORIAL), "-o", str(out), "--duration", "0.2", "-q"])
    assert result.exit_code == 0, result.output
    recorded = read_mcap(out)
    assert recorded.frames == len(reference.t) == 201
    for name in ("t", "x", "q", "v", "omega", "P", "L"):
        np.testing.assert_array_equal(getattr(recorded, name), getattr(reference, name), err_msg=name)


def test_run_writes_an_rrd_holding_the_trajectory(tmp_path, reference):
    out = tmp_path / "t.rrd"
    result = runner.invoke(app, ["run", str(TUTORIAL), "-o", str(out), "--duration", "0.2", "-q"])
    assert result.exit_code == 0, result.output
    recorded = read_rrd(out)
    assert recorded.frames == len(reference.t)
    np.testing.assert_allclose(recorded.t, reference.t, atol=1e-9)  # nanosecond time stamps
    # transforms are stored as float32: compare within float32 resolution of the values
    np.testing.assert_allclose(recorded.x, reference.x, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(np.abs(np.sum(recorded.q * reference.q, -1)), 1.0, atol=1e-6)


def test_missing_scene_exits_1_and_writes_nothing(tmp_path):
    out = tmp_path / "never.mcap"
    result = runner.invoke(app, ["run", str(tmp_path / "nope.yaml"), "-o", str(out)])
    assert result.exit_code == 1
    assert "scene file not found" in result.output and "nope.yaml" in result.output
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_invalid_scene_exits_1_with_located_errors_and_writes_nothing(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(TUTORIAL.read_text().replace("masses: [1.0, 0.5, 0.5, 0.25]", "masses: [1.0, -0.5, 0.5, 0.25]"))
    out = tmp_path / "out" / "never.mcap"
    result = runner.invoke(app, ["run", str(bad), "-o", str(out)])
    assert result.exit_code == 1
    assert f"{bad}:" in result.output and "masses" in result.output
    assert not (tmp_path / "out").exists()


def test_unknown_integrator_and_format_are_usage_errors_that_write_nothing(tmp_path):
    result = runner.invoke(app, ["run", str(TUTORIAL), "-o", str(tmp_path / "a.mcap"), "--integrator", "eulr"])
    assert result.exit_code == 1 and "eulr" in result.output
    result = runner.invoke(app, ["run", str(TUTORIAL), "-o", str(tmp_path / "a.csv")])
    assert result.exit_code == 1 and ".mcap or .rrd" in result.output
    assert list(tmp_path.iterdir()) == []


def test_overrides_reach_the_run(tmp_path):
    out = tmp_path / "o.mcap"
    args = ["run", str(TUTORIAL), "-o", str(out), "--dt", "0.01", "--duration", "0.5", "--record-every", "10", "-q"]
    assert runner.invoke(app, args).exit_code == 0
    recorded = read_mcap(out)
    assert recorded.step.tolist() == [0, 10, 20, 30, 40, 50]
    np.testing.assert_allclose(recorded.t[-1], 0.5)


def _chunk_compressions(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return {index.compression for index in make_reader(f).get_summary().chunk_indexes}


@pytest.mark.parametrize("compression, stored", [("lz4", "lz4"), ("none", ""), ("zstd", "zstd")])
def test_compression_option_picks_the_mcap_chunk_compression(tmp_path, reference, compression, stored):
    out = tmp_path / f"c-{compression}.mcap"
    args = ["run", str(TUTORIAL), "-o", str(out), "--duration", "0.2", "--compression", compression, "-q"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert _chunk_compressions(out) == {stored}
    np.testing.assert_array_equal(read_mcap(out).x, reference.x)  # the content does not depend on it


def test_scene_record_compression_is_used_and_the_flag_overrides_it(tmp_path):
    scene = tmp_path / "lz4.yaml"
    text = TUTORIAL.read_text()
    flow = "simulation: {dt: 0.001, duration: 5.0, integrator: euler-matrix}"
    assert flow in text  # the test adds a record section to it
    scene.write_text(text.replace(flow, flow[:-1] + ", record: {compression: lz4}}"))
    out = tmp_path / "s.mcap"
    assert runner.invoke(app, ["run", str(scene), "-o", str(out), "--duration", "0.05", "-q"]).exit_code == 0
    assert _chunk_compressions(out) == {"lz4"}
    args = ["run", str(scene), "-o", str(out), "--duration", "0.05", "--compression", "none", "-q"]
    assert runner.invoke(app, args).exit_code == 0
    assert _chunk_compressions(out) == {""}


def test_an_unknown_compression_exits_1_and_writes_nothing(tmp_path):
    out = tmp_path / "x.mcap"
    result = runner.invoke(app, ["run", str(TUTORIAL), "-o", str(out), "--compression", "gzip", "-q"])
    assert result.exit_code == 1 and "gzip" in result.output and not out.exists()


def test_the_cli_compressions_are_the_schema_enum():
    import json

    from rbcli.cli.run import COMPRESSIONS

    schema = json.loads((ROOT / "schemas" / "scene.schema.json").read_text())
    assert tuple(schema["$defs"]["record"]["properties"]["compression"]["enum"]) == COMPRESSIONS


def test_the_summary_says_the_threads_and_why(tmp_path, monkeypatch):
    """One short part of the summary line: how many threads the steps used and why (issue 45)."""
    from rbcli.runner.threads import ENV

    monkeypatch.setenv(ENV, "1")  # restored after the test (the CLI writes --threads into it)
    args = ["run", str(TUTORIAL), "-o", str(tmp_path / "t.mcap"), "--duration", "0.05"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert f"threads: 1 ({ENV}=1)" in result.output
    result = runner.invoke(app, [*args, "--threads", "auto"])
    assert result.exit_code == 0, result.output
    assert "threads: 1 (" in result.output  # the tutorial is too small for the threaded loop, whatever the count
