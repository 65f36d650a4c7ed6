"""`rbsim replay --web` stopped by SIGTERM (or Ctrl-C, SIGHUP) leaves no process and no bound port behind:
the Rerun viewer runs in a process group of its own, which rbsim stops and waits for (before, SIGTERM
killed rbsim alone and the rerun server kept both ports and a core)."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rbcli.api import prepare, run_to_file
from rbcli.cli.app import app

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"
runner = CliRunner()


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "t.rrd"
    run_to_file(prepare(TUTORIAL, duration=0.05), out)
    return out


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.2)
        return s.connect_ex(("127.0.0.1", port)) == 0


def can_bind(port: int) -> bool:
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _stat(pid: int) -> list[str] | None:
    """Fields of /proc/<pid>/stat after the command name (state, ppid, pgrp, ...); None when gone."""
    try:
        return (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None


def descendants(pid: int) -> set[int]:
    """Every process below `pid` (children, grandchildren, ...) from /proc."""
    parents: dict[int, int] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit() and (fields := _stat(int(entry.name))) is not None:
            parents[int(entry.name)] = int(fields[1])
    found, todo = set(), [pid]
    while todo:
        parent = todo.pop()
        children = [p for p, pp in parents.items() if pp == parent]
        found.update(children)
        todo.extend(children)
    return found


def alive(pid: int) -> bool:
    fields = _stat(pid)
    return fields is not None and fields[0] != "Z"  # a zombie holds no port and runs nothing


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process tree from /proc (Linux)")
@pytest.mark.parametrize(("signum", "status"), [(signal.SIGTERM, 143), (signal.SIGINT, 130), (signal.SIGHUP, 129)])
def test_a_stop_signal_leaves_no_process_and_no_bound_port(tmp_path, recording, signum, status):
    web, grpc = free_port(), free_port()
    log = tmp_path / "replay.log"
    args = [sys.executable, "-m", "rbcli", "replay", str(recording), "--web", "--port", str(web)]
    with open(log, "w") as out:
        proc = subprocess.Popen([*args, "--grpc-port", str(grpc)], cwd=ROOT, stdout=out, stderr=subprocess.STDOUT)
    try:
        deadline = time.monotonic() + 60.0
        while not (listening(web) and listening(grpc)):
            if proc.poll() is not None:
                text = log.read_text()
                if "serving" in text:  # rbsim ran it; the viewer itself could not start in this environment
                    pytest.skip(f"rerun's web viewer did not start here (exit {proc.returncode}): {text[-500:]}")
                raise AssertionError(text)
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)
        below = descendants(proc.pid)
        assert below and all(alive(p) for p in below)  # python -m rerun and the rerun binary
        proc.send_signal(signum)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:  # the test failed: leave nothing either
            proc.kill()
            proc.wait()
    text = log.read_text()
    assert proc.returncode == status, text
    assert f"stopped the web viewer ({signal.Signals(signum).name}); ports {web} and {grpc} are free" in text
    assert [p for p in below if alive(p)] == []  # no child, no grandchild left running
    assert "\x1b[" not in text and " INFO " not in text  # rerun's coloured log is not forwarded
    assert can_bind(web) and can_bind(grpc) and not listening(web) and not listening(grpc)


def test_a_port_in_use_is_refused_before_starting_the_viewer(recording):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = runner.invoke(app, ["replay", str(recording), "--web", "--port", str(port)])
        assert result.exit_code == 1, result.output
        assert f"port {port} on 127.0.0.1 is in use" in result.output and "--port" in result.output
        result = runner.invoke(
            app, ["replay", str(recording), "--web", "--port", str(free_port()), "--grpc-port", str(port)]
        )
        assert result.exit_code == 1 and f"port {port} on 127.0.0.1 is in use" in result.output
        assert "--grpc-port" in result.output
