"""`rbsim replay --web` prints (and opens, where a browser exists) the address that loads the recording:
the viewer's page with the served recording as its data source (before, the bare server address opened
rerun's welcome page with nothing loaded). Stopped by SIGTERM (or Ctrl-C, SIGHUP) it leaves no process
and no bound port behind: the Rerun viewer runs in a process group of its own, which rbsim stops and
waits for (before, SIGTERM killed rbsim alone and the rerun server kept both ports and a core)."""

from __future__ import annotations

import os
import re
import signal
import socket
import subprocess
import sys
import time
import urllib.parse
import urllib.request
import warnings
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import rbcli
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


@pytest.fixture(scope="module")
def mcap_recording(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("rec") / "t.mcap"
    run_to_file(prepare(TUTORIAL, duration=0.05), out)
    return out


def browser_env(folder: Path) -> dict[str, str]:
    """rbsim's environment with no display and $BROWSER a script that writes the address it is asked to open
    into folder/opened.txt: no real browser opens, and the test sees what would have."""
    script = folder / "browser.sh"
    script.write_text(f'#!/bin/sh\nprintf "%s" "$1" > {folder / "opened.txt"}\n')
    script.chmod(0o755)
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    return {**env, "BROWSER": str(script)}


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


def _kill_all(pids: list[int] | set[int]) -> None:
    """SIGKILL to each of pids still there (what a failed test leaves of the viewer's processes)."""
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def alive(pid: int) -> bool:
    fields = _stat(pid)
    return fields is not None and fields[0] != "Z"  # a zombie holds no port and runs nothing


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process tree from /proc (Linux)")
@pytest.mark.parametrize(("signum", "status"), [(signal.SIGTERM, 143), (signal.SIGINT, 130), (signal.SIGHUP, 129)])
def test_a_stop_signal_leaves_no_process_and_no_bound_port(tmp_path, recording, signum, status):
    web, grpc = free_port(), free_port()
    log = tmp_path / "replay.log"
    args = [sys.executable, "-m", "rbcli", "replay", str(recording), "--web", "--port", str(web)]
    env = browser_env(tmp_path)
    with open(log, "w") as out:
        proc = subprocess.Popen(
            [*args, "--grpc-port", str(grpc)], cwd=ROOT, stdout=out, stderr=subprocess.STDOUT, env=env
        )
    below: list[int] = []
    try:
        deadline = time.monotonic() + 60.0
        while not (listening(web) and listening(grpc)):
            if proc.poll() is not None:
                text = log.read_text()
                if "the Rerun web viewer exited" in text:  # rbsim ran it; the viewer could not start here
                    pytest.skip(f"rerun's web viewer did not start here (exit {proc.returncode}): {text[-500:]}")
                raise AssertionError(text)
            assert time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)
        # python -m rerun and the rerun binary (a helper the viewer starts may come and go meanwhile)
        below = [p for p in descendants(proc.pid) if alive(p)]
        assert len(below) >= 2, below
        proc.send_signal(signum)
        try:
            proc.wait(timeout=30)
        except subprocess.TimeoutExpired:  # say where it hangs: rbsim's log and what is left below it
            left = {p: _stat(p) for p in descendants(proc.pid)}
            raise AssertionError(f"rbsim still running 30 s after {signum!r}: {left}\n{log.read_text()}") from None
    finally:
        if proc.poll() is None:  # the test failed: leave nothing either (rbsim killed cannot stop its
            proc.kill()  # viewer: a server left behind kept a core busy for the rest of the suite)
            proc.wait()
            _kill_all(below)
    text = log.read_text()
    assert proc.returncode == status, text
    assert f"stopped the web viewer ({signal.Signals(signum).name}); ports {web} and {grpc} are free" in text
    assert [p for p in below if alive(p)] == []  # no child, no grandchild left running
    assert "\x1b[" not in text and " INFO " not in text  # rerun's coloured log is not forwarded
    assert can_bind(web) and can_bind(grpc) and not listening(web) and not listening(grpc)


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process tree from /proc (Linux)")
def test_a_stop_signal_while_the_viewer_starts_stops_it_too(tmp_path, recording):
    """SIGTERM as soon as the viewer's process exists, before its ports answer: rbsim stops waiting for
    them, stops the viewer's group and exits 143 with both ports free (the signal is noted by the handler
    and acted on by the waiting loop, which polls for it)."""
    web, grpc = free_port(), free_port()
    log = tmp_path / "replay.log"
    args = [sys.executable, "-m", "rbcli", "replay", str(recording), "--web", "--port", str(web)]
    with open(log, "w") as out:
        proc = subprocess.Popen(
            [*args, "--grpc-port", str(grpc)], cwd=ROOT, stdout=out, stderr=subprocess.STDOUT, env=browser_env(tmp_path)
        )
    below: set[int] = set()
    try:
        deadline = time.monotonic() + 60.0
        while not (below := {p for p in descendants(proc.pid) if alive(p)}):
            assert proc.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.005)
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=30)
    finally:
        below |= descendants(proc.pid)  # the viewer's binary too, started after `below` was first taken
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        _kill_all(below)
    text = log.read_text()
    assert proc.returncode == 143, text
    assert f"stopped the web viewer (SIGTERM); ports {web} and {grpc} are free" in text
    assert [p for p in below if alive(p)] == []
    assert can_bind(web) and can_bind(grpc)


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


RERUN = [sys.executable, "-m", "rerun"]


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process tree from /proc (Linux)")
@pytest.mark.parametrize("kind", ["rrd", "mcap"])
def test_the_printed_address_loads_the_recording(tmp_path, recording, mcap_recording, kind):
    """The one address rbsim prints is the viewer's page (HTTP 200, rerun's viewer and its script) whose
    `url` parameter names a data source on the recording port; what that source serves, read back with
    rerun's own client into an .rrd, is the recording: `rerun rrd compare` finds it equal to the .rrd
    (to rerun's own conversion of the .mcap), and rbsim's reader gets the .rrd's frames bitwise. The
    browser ($BROWSER) was asked to open that same address. Before, `http://127.0.0.1:9090` carried no
    data source and the viewer showed its welcome page."""
    source_file = recording if kind == "rrd" else mcap_recording
    if kind == "rrd":
        expected = source_file
    else:  # the recording rerun's viewer shows for an .mcap: rerun's own import of it
        expected = tmp_path / "expected.rrd"
        app_id = ["--application-id", source_file.stem]  # as the viewer names a file's recording
        subprocess.run([*RERUN, "mcap", "convert", str(source_file), "-o", str(expected), *app_id], check=True)
    web, grpc = free_port(), free_port()
    log = tmp_path / "replay.log"
    args = [sys.executable, "-m", "rbcli", "replay", str(source_file), "--web", "--port", str(web)]
    with open(log, "w") as out:
        proc = subprocess.Popen(
            [*args, "--grpc-port", str(grpc)],
            cwd=ROOT,
            stdout=out,
            stderr=subprocess.STDOUT,
            env=browser_env(tmp_path),
        )
    saver = None
    try:
        deadline = time.monotonic() + 60.0
        while "serving" not in log.read_text():
            assert proc.poll() is None and time.monotonic() < deadline, log.read_text()
            time.sleep(0.05)
        addresses = re.findall(r"http://\S+", log.read_text())
        assert len(addresses) == 1, log.read_text()
        address = addresses[0]
        parts = urllib.parse.urlsplit(address)
        assert (parts.hostname, parts.port) == ("127.0.0.1", web)
        with urllib.request.urlopen(address, timeout=30) as page:
            assert page.status == 200 and page.headers.get_content_type() == "text/html"
            html = page.read().decode()
        assert "<title>Rerun Viewer</title>" in html and 'src="re_viewer.js"' in html
        with urllib.request.urlopen(urllib.parse.urljoin(address, "re_viewer.js"), timeout=30) as script:
            assert script.status == 200 and b"wasm_bindgen" in script.read()
        (data_source,) = urllib.parse.parse_qs(parts.query)["url"]
        assert data_source == f"rerun+http://127.0.0.1:{grpc}/proxy"

        served = tmp_path / "served.rrd"  # what a viewer receives from the data source, saved by rerun
        saver_port = ["--bind", "127.0.0.1", "--port", str(free_port())]  # its own server: no clash with rbsim's
        env = {**os.environ, "RUST_LOG": "error"}
        saver = subprocess.Popen([*RERUN, data_source, "--save", str(served), *saver_port], env=env)
        compare = [*RERUN, "rrd", "compare", "--unordered", str(expected), str(served)]
        while subprocess.run(compare, capture_output=True, env=env).returncode != 0:  # until all of it came
            assert saver.poll() is None and time.monotonic() < deadline, "the data source never gave the recording"
            time.sleep(0.2)
        assert (tmp_path / "opened.txt").read_text() == address  # opened, once it loads (no display here)
    finally:
        below = descendants(proc.pid)
        for process in (saver, proc):
            if process is not None and process.poll() is None:
                process.send_signal(signal.SIGINT)
                try:
                    process.wait(timeout=30)
                except subprocess.TimeoutExpired:  # leave no server running on the suite's cores
                    process.kill()
                    process.wait()
                    _kill_all(below)
    if kind == "rrd":  # and it reads back as the recording, frame for frame
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # a streamed .rrd has no footer: rerun's reader says so
            back, original = rbcli.read_recording(served), rbcli.read_recording(source_file)
        assert back.x.shape == original.x.shape and back.x.shape[0] > 1
        for name in ("t", "step", "x", "q"):  # what an .rrd holds of the state (v, omega, P, L: NaN)
            assert np.array_equal(getattr(back, name), getattr(original, name)), name


def test_no_browser_is_opened_without_a_display_or_browser(monkeypatch):
    """Without a display and without $BROWSER no browser is opened: Python's webbrowser would pick a
    console browser (lynx, w3m) there, which would take over the terminal. (With $BROWSER, the test above
    sees the address opened.)"""
    from rbcli.cli import replay

    for name in ("DISPLAY", "WAYLAND_DISPLAY", "BROWSER"):
        monkeypatch.delenv(name, raising=False)
    assert not replay.browser_available()
