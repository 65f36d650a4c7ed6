"""Recordings carry rbsim's version and the recording format version (MCAP metadata, .rrd properties), and
a file in a newer format than this rbsim reads is refused with a clear error by every reader: the public
`read_recording`, `rbsim info`, and the MCAP-to-RRD conversion of `rbsim replay --save`."""

from __future__ import annotations

import subprocess
import sys

import pytest
from record_synthetic import make_blocks, make_header, write_run

import rbcli
from rbcli.record import frame
from rbcli.record.convert import mcap_to_rrd
from rbcli.record.mcap_layout import METADATA_RUN
from rbcli.record.mcap_read import read_mcap_contents
from rbcli.record.mcap_sink import SinkMcap
from rbcli.record.read import RecordingTooNew, read_rrd, refuse_newer_recording, summarize
from rbcli.record.rerun_sink import SinkRerun

SINKS = {"mcap": SinkMcap, "rrd": SinkRerun}


def write(path, version: int = frame.RECORDING_FORMAT_VERSION) -> None:
    """A three-frame run written as if by an rbsim whose recording format is `version`."""
    header = make_header()
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(frame, "RECORDING_FORMAT_VERSION", version)
        write_run(SINKS[path.suffix[1:]](path), header, make_blocks(header, sizes=(3,), diverge=False), "completed")


def test_mcap_metadata_carries_both_versions(tmp_path):
    path = tmp_path / "run.mcap"
    write(path)
    meta = read_mcap_contents(path).metadata[METADATA_RUN]
    assert meta["format_version"] == str(frame.RECORDING_FORMAT_VERSION)
    assert meta["rbsim_version"] == make_header().rbsim_version


def test_rrd_properties_carry_both_versions(tmp_path):
    path = tmp_path / "run.rrd"
    write(path)
    meta = read_rrd(path).metadata
    assert meta["format_version"] == str(frame.RECORDING_FORMAT_VERSION)
    assert meta["rbsim_version"] == make_header().rbsim_version


@pytest.mark.parametrize("suffix", ["mcap", "rrd"])
def test_current_format_reads(tmp_path, suffix):
    path = tmp_path / f"run.{suffix}"
    write(path)
    assert rbcli.read_recording(path).t.shape == (3,)
    assert summarize(path).frames == 3
    refuse_newer_recording(path)  # passes


@pytest.mark.parametrize("suffix", ["mcap", "rrd"])
def test_newer_format_is_refused_clearly(tmp_path, suffix):
    path = tmp_path / f"new.{suffix}"
    newer = frame.RECORDING_FORMAT_VERSION + 1
    write(path, newer)
    for read in (rbcli.read_recording, summarize):
        with pytest.raises(RecordingTooNew) as caught:
            read(path)
        message = str(caught.value)
        assert f"recording format version {newer}" in message and "newer than this rbsim" in message
        assert f"up to version {frame.RECORDING_FORMAT_VERSION}" in message and "upgrade rbsim" in message
        assert "not a readable" not in message  # not mistaken for a damaged file
    if suffix == "mcap":
        with pytest.raises(RecordingTooNew):
            mcap_to_rrd(path, tmp_path / "converted.rrd")


def test_resume_refuses_a_newer_log(tmp_path):
    """`rbsim run --resume`: a newer layout's checkpoint could be misread, so the log is refused first."""
    from rbcli.runner.resume import ResumeError, plan_resume

    path = tmp_path / "new.mcap"
    write(path, frame.RECORDING_FORMAT_VERSION + 1)
    with pytest.raises(ResumeError, match=f"recording format version {frame.RECORDING_FORMAT_VERSION + 1}"):
        plan_resume(path)


def test_the_cli_refuses_a_newer_recording_before_any_work(tmp_path):
    """`rbsim info` and `rbsim replay` (before any viewer starts; with --save, before converting): exit 1
    and the reason, one subprocess per command and format pair that matters."""
    newer = frame.RECORDING_FORMAT_VERSION + 1
    for suffix in ("mcap", "rrd"):
        write(tmp_path / f"new.{suffix}", newer)
    out = tmp_path / "out.rrd"
    for args in (["info", "new.mcap"], ["replay", "new.rrd"], ["replay", "new.mcap", "--save", str(out)]):
        command = [sys.executable, "-m", "rbcli", args[0], str(tmp_path / args[1]), *args[2:]]
        done = subprocess.run(command, capture_output=True, text=True, timeout=120)
        assert done.returncode == 1 and f"recording format version {newer}" in done.stderr, (args, done.stderr)
        assert "Traceback" not in done.stderr and not out.exists()
