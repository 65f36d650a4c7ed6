"""`rbsim info` and `rbsim replay` through Typer's CliRunner, and the import rules of the record package."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import typer
from record_synthetic import (  # noqa: F401 - pytest fixtures
    BODY_NAMES,
    INVARIANT_NAMES,
    concat,
    mcap_path_fixture,
    rrd_path_fixture,
    synthetic_fixture,
)
from typer.testing import CliRunner

from rbcli.cli.info import info
from rbcli.cli.replay import replay
from rbcli.record.read import read_mcap, read_rrd, summarize
from rbcli.record.rerun_sink import verify_rrd_command

ROOT = Path(__file__).resolve().parents[2]

# the lead's app.py registers these the same way; a private app keeps these tests independent of it
app = typer.Typer()
app.command("info")(info)
app.command("replay")(replay)
runner = CliRunner()


def test_info_on_both_formats(mcap_path, rrd_path):
    for path in (mcap_path, rrd_path):
        result = runner.invoke(app, ["info", str(path)])
        assert result.exit_code == 0, result.output
        out = result.output
        assert "synthetic" in out and "euler-matrix" in out and "dt = 0.1 s" in out and "diverged" in out
        assert f"bodies       {len(BODY_NAMES)}" in out and all(n in out for n in INVARIANT_NAMES)


@pytest.mark.parametrize("fmt", ["mcap", "rrd"])
def test_summary_drift_is_max_deviation_from_the_start(fmt, mcap_path, rrd_path, synthetic):
    """drift = max_t |f(t) - f(0)|, relative = drift / |f(0)|; none for a series that starts at 0."""
    _, blocks = synthetic
    summary = summarize(mcap_path if fmt == "mcap" else rrd_path)
    assert summary.frames == sum(len(b) for b in blocks) and summary.status == "diverged"
    drifts = {d.name: d for d in summary.drifts}
    for name in INVARIANT_NAMES:
        f = np.concatenate([b.invariants[name] for b in blocks])
        assert drifts[name].max_abs == np.max(np.abs(f - f[0]))
    assert drifts["energy_total"].relative == drifts["energy_total"].max_abs / abs(drifts["energy_total"].initial)
    assert drifts["momentum_x"].relative is None  # starts at exactly 0


def test_replay_save_converts_mcap_to_a_verified_rrd(tmp_path, mcap_path, synthetic):
    out = tmp_path / "converted.rrd"
    result = runner.invoke(app, ["replay", str(mcap_path), "--save", str(out)])
    assert result.exit_code == 0, result.output
    check = subprocess.run(verify_rrd_command(out), capture_output=True, text=True, timeout=60)
    assert check.returncode == 0, check.stderr
    converted, original = read_rrd(out), read_mcap(mcap_path)
    assert converted.body_names == original.body_names and converted.scene_text == original.scene_text
    assert converted.summary["status"] == "diverged"
    np.testing.assert_array_equal(converted.step, original.step)
    np.testing.assert_allclose(converted.x, original.x, rtol=1e-7, atol=0)  # float32 in Rerun
    np.testing.assert_allclose(converted.q, original.q, rtol=1e-7, atol=0)
    for name in INVARIANT_NAMES:
        np.testing.assert_array_equal(converted.invariants[name], original.invariants[name])


def test_replay_without_a_display_explains_and_exits_1(monkeypatch, mcap_path, rrd_path):
    monkeypatch.setattr(sys, "platform", "linux")
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    for path in (mcap_path, rrd_path):
        result = runner.invoke(app, ["replay", str(path)])
        assert result.exit_code == 1
        assert "no display" in result.output and "--web" in result.output and "--save" in result.output
        assert result.exception is None or isinstance(result.exception, SystemExit)  # no traceback


@pytest.mark.parametrize("command", ["info", "replay"])
def test_missing_or_foreign_files_exit_1_with_a_message(command, tmp_path):
    result = runner.invoke(app, [command, str(tmp_path / "nope.mcap")])
    assert result.exit_code == 1 and "not found" in result.output
    other = tmp_path / "scene.yaml"
    other.write_text("name: x\n")
    result = runner.invoke(app, [command, str(other)])
    assert result.exit_code == 1 and "expected a .mcap or .rrd" in result.output


def test_corrupt_files_exit_1_without_a_traceback(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n this is not a recording")
    for args in (["info", str(bad)], ["replay", str(bad), "--save", str(tmp_path / "out.rrd")]):
        result = runner.invoke(app, args)
        assert result.exit_code == 1 and "cannot" in result.output, result.output
        assert "Traceback" not in result.output


def test_replay_save_must_be_an_rrd(tmp_path, mcap_path):
    result = runner.invoke(app, ["replay", str(mcap_path), "--save", str(tmp_path / "out.mcap")])
    assert result.exit_code == 1 and ".rrd" in result.output


# --- import rules ----------------------------------------------------------------------------------

WRITER_OWNERS = {
    "mcap": ("rbcli/record/mcap_writer.py", "rbcli/record/mcap_read.py", "rbcli/record/mcap_recovery.py"),
    "mcap_protobuf": ("rbcli/record/mcap_messages.py",),
    "google.protobuf": ("rbcli/record/mcap_messages.py",),
    "foxglove_schemas_protobuf": ("rbcli/record/mcap_messages.py",),
    "zstandard": ("rbcli/record/mcap_writer.py",),
    "lz4": ("rbcli/record/mcap_writer.py",),
    "rerun": ("rbcli/record/rerun_sink.py",),
}


def test_each_writer_library_is_imported_by_one_module():
    """Static check over rbcli/: mcap (the file writer, the indexed reader and crash recovery),
    mcap_protobuf, protobuf, foxglove, the compressors and rerun each appear only in their owning modules."""
    for path in sorted((ROOT / "rbcli").rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        for node in ast.walk(ast.parse(path.read_text(), filename=rel)):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            for name in names:
                for library, owners in WRITER_OWNERS.items():
                    if name == library or name.startswith(f"{library}."):
                        assert rel in owners, f"{rel} imports {name}; only {owners} may"


def test_readers_and_commands_import_writers_lazily():
    """Importing the readers, the converter and the two commands loads no writer library."""
    code = (
        "import sys, rbcli.record.read, rbcli.record.convert, rbcli.cli.info, rbcli.cli.replay\n"
        "print(' '.join(m for m in ('mcap', 'rerun', 'foxglove_schemas_protobuf', 'google.protobuf') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == ""
