"""`rbsim replay FILE`: open a recording in the Rerun viewer, serve it to a browser, or convert it."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.parse
from pathlib import Path
from typing import IO, Annotated

import typer

from rbcli.cli import messages
from rbcli.cli.exit_codes import signal_exit

WEB_PORT = 9090  # the web viewer's HTTP port (rerun's default)
GRPC_PORT = 9876  # the gRPC server the web viewer reads the recording from (rerun's default)
_STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")
STOP_GRACE_SECONDS = 5.0  # how long the viewer gets to exit after SIGTERM before SIGKILL
LOG_DRAIN_SECONDS = 1.0  # how long rbsim waits for the viewer's last log lines once its group is gone
POLL_SECONDS = 0.05  # how often the serving loop looks for a noted stop signal and the viewer's exit
# The Rerun viewer logs through Rust's `tracing` (coloured "2026-...Z  INFO target: text" lines on its
# stderr, even into a pipe): it runs with RUST_LOG=warn unless the user set RUST_LOG, and its stderr is
# read back line by line, colours stripped and INFO/DEBUG/TRACE lines dropped (_forward_viewer_log).
VIEWER_LOG_LEVEL = "warn"
_ANSI = re.compile(r"\x1b\[[0-9;?]*[ -/]*[@-~]")
_TRACING_LINE = re.compile(r"^\S+Z\s+(TRACE|DEBUG|INFO|WARN|ERROR)\s+(\S+?):\s?(.*)$")


def has_display() -> bool:
    """Whether a native viewer window can open: on Linux that needs DISPLAY or WAYLAND_DISPLAY."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def replay(
    file: Annotated[
        Path, typer.Argument(metavar="FILE", help="A recording: .rrd, or .mcap (the Rerun viewer reads both).")
    ],
    web: Annotated[
        bool,
        typer.Option(
            "--web", help="Serve a web viewer on http://127.0.0.1:PORT instead of opening a window; prints its address"
        ),
    ] = False,
    save: Annotated[
        Path | None, typer.Option("--save", metavar="FILE.rrd", help="Write the recording as an .rrd file and exit")
    ] = None,
    port: Annotated[int, typer.Option("--port", metavar="PORT", help="--web: the web viewer's HTTP port")] = WEB_PORT,
    grpc_port: Annotated[
        int, typer.Option("--grpc-port", metavar="PORT", help="--web: the port of the gRPC server the viewer reads")
    ] = GRPC_PORT,
) -> None:
    """Open FILE in the Rerun viewer shipped with rerun-sdk; --web serves it locally (until Ctrl-C, SIGTERM or
    SIGHUP: the server and its ports are then freed, exit 128 + the signal); --save converts."""
    suffix = file.suffix.lower()
    if not file.is_file():
        raise messages.fail(f"recording not found: {file}", expected="a .mcap or .rrd file")
    if suffix not in (".mcap", ".rrd"):
        raise messages.fail(f"{file}: not a recording", expected="a .mcap or .rrd file")
    from rbcli.record.read import RecordingTooNew, refuse_newer_recording

    try:
        refuse_newer_recording(file)
    except RecordingTooNew as exc:
        raise messages.fail(str(exc), expected="a newer rbsim (pip install -U rbsim)") from None

    if save is not None:
        _save(file, save)
        return

    from rbcli.record.rerun_sink import open_viewer_command

    if web:
        # --serve-web: the viewer's page and the gRPC proxy the file is fed into, both on 127.0.0.1; unlike
        # --web-viewer it opens no browser itself (rbsim opens the address it prints, where a browser exists)
        serve = ["--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(port), "--port", str(grpc_port)]
        _serve_web(file, [*open_viewer_command(file), *serve], (port, grpc_port))
        return

    if not has_display():
        raise messages.fail(
            "no display (DISPLAY and WAYLAND_DISPLAY are unset), so the Rerun viewer cannot open a window",
            expected=f"`rbsim replay {file} --web` (a web viewer on http://127.0.0.1:{WEB_PORT}) or "
            f"`rbsim replay {file} --save out.rrd` (an .rrd to open where there is a display)",
        )
    process = subprocess.Popen(open_viewer_command(file), start_new_session=True)
    messages.status(f"opened {file} in the Rerun viewer (pid {process.pid})")


def web_viewer_address(web_port: int, grpc_port: int) -> str:
    """The address that opens the web viewer on the served recording, not on its welcome page.

    The viewer takes its data source as the `url` query parameter, here the gRPC proxy that `rerun
    --serve-web FILE` feeds the file into (`rerun+http://HOST:PORT/proxy`), percent-encoded as rerun-sdk's
    own WebViewerConfig encodes it (every character but letters and digits). rerun says `localhost`;
    rbsim names 127.0.0.1, the one address both servers are bound to."""
    source = f"rerun+http://127.0.0.1:{grpc_port}/proxy"
    return f"http://127.0.0.1:{web_port}/?url={urllib.parse.quote(source, safe='')}"


def browser_available() -> bool:
    """Whether rbsim should open a browser: a display, or a browser the user named in $BROWSER, and one
    that Python's webbrowser finds. Without a display webbrowser falls back to a console browser (lynx,
    w3m), which would take over the terminal rbsim reports in."""
    import webbrowser

    if not (has_display() or os.environ.get("BROWSER")):
        return False
    try:
        webbrowser.get()
    except webbrowser.Error:
        return False
    return True


def _open_in_browser(address: str) -> None:
    """Open `address` in the browser; a browser that fails to start is no reason to stop serving."""
    import webbrowser

    with contextlib.suppress(webbrowser.Error, OSError):
        webbrowser.open(address)


def _serve_web(file: Path, command: list[str], ports: tuple[int, int]) -> None:
    """Run the Rerun web viewer until it exits or a stop signal comes, and leave nothing behind.

    The viewer (`python -m rerun`, which starts the `rerun` binary as its own child) runs in a process
    group of its own: Ctrl-C in the terminal reaches rbsim only, and rbsim stops the whole group.
    SIGINT, SIGTERM and SIGHUP end it the same way: SIGTERM to the group, SIGKILL after
    STOP_GRACE_SECONDS, and rbsim waits until no process of the group is left (so its ports are free)
    and its log forwarder has read the viewer's last words, then exits 128 + the signal. Before, SIGTERM
    killed rbsim alone and the rerun server kept running at 100 % of a core, holding both ports. (SIGKILL
    of rbsim itself cannot be handled.)

    The signal handler only notes the signal; the main thread polls for it. A handler that raised an
    exception could land in the middle of any library code the main thread was running (a thread's
    start, a lock's acquire and the `try` after it), and one CI run saw rbsim still there 30 s after
    SIGTERM; a noted signal is acted on between two polls, in this function's own code."""
    web, grpc = ports
    for number, what in ((web, "--port"), (grpc, "--grpc-port")):
        if not _port_free(number):
            raise messages.fail(
                f"port {number} on 127.0.0.1 is in use (another `rbsim replay --web`?)",
                expected=f"a free port: stop that server or choose another with {what}",
            )

    signals_seen: list[int] = []

    def note(signum: int, frame: object) -> None:
        signals_seen.append(signum)

    numbers = [getattr(signal, name) for name in _STOP_SIGNALS if hasattr(signal, name)]
    previous = {number: signal.signal(number, note) for number in numbers}
    process: subprocess.Popen | None = None
    forward: threading.Thread | None = None
    code = 0
    try:
        env = dict(os.environ)
        quiet = "RUST_LOG" not in env  # a RUST_LOG the user set is theirs: every line is forwarded
        env.setdefault("RUST_LOG", VIEWER_LOG_LEVEL)
        if not signals_seen:
            process = subprocess.Popen(command, start_new_session=True, env=env, stderr=subprocess.PIPE)
            forward = threading.Thread(target=_forward_viewer_log, args=(process.stderr, quiet), daemon=True)
            forward.start()
        if process is not None and _wait_listening(process, ports, signals_seen):
            # an address printed (or opened) before both ports answer would not load yet
            address = web_viewer_address(web, grpc)
            messages.status(
                f"serving {file} at {address} (the viewer on port {web}, the recording on port {grpc}, "
                "bound to 127.0.0.1 only); Ctrl-C to stop"
            )
            if browser_available():  # in a thread: a browser command may run until the browser closes
                threading.Thread(target=_open_in_browser, args=(address,), daemon=True).start()
        while process is not None and not signals_seen:
            with contextlib.suppress(subprocess.TimeoutExpired):
                code = process.wait(timeout=POLL_SECONDS)
                break
    finally:
        try:
            if process is not None:
                _stop_group(process)
            if forward is not None:  # the pipe ends with the group: its last lines before rbsim's own
                forward.join(timeout=LOG_DRAIN_SECONDS)
        finally:
            for number, handler in previous.items():
                signal.signal(number, handler)
    if signals_seen:
        name = signal.Signals(signals_seen[0]).name
        messages.status(f"stopped the web viewer ({name}); ports {web} and {grpc} are free again")
        raise typer.Exit(signal_exit(signals_seen[0]))
    if code:
        raise messages.fail(f"the Rerun web viewer exited with code {code}")


def _forward_viewer_log(stream: IO[bytes] | None, quiet: bool) -> None:
    """Copy the viewer's stderr to rbsim's as plain lines: ANSI colours stripped, Rust `tracing` lines
    below WARN dropped when `quiet`, WARN and ERROR lines through the shared formatter (`warning: rerun: ...`)."""
    if stream is None:
        return
    with contextlib.suppress(OSError, ValueError):  # the pipe closes when the viewer ends
        for raw in stream:
            line = _ANSI.sub("", raw.decode("utf-8", "replace")).rstrip()
            if not line:
                continue
            traced = _TRACING_LINE.match(line)
            if traced is None or (not quiet and traced[1] not in ("WARN", "ERROR")):
                messages.status(f"rerun: {line}")
            elif traced[1] in ("WARN", "ERROR"):
                messages.emit("warning" if traced[1] == "WARN" else "error", f"rerun: {traced[3]}")


def _wait_listening(process: subprocess.Popen, ports: tuple[int, ...], signals_seen: list[int]) -> bool:
    """Wait until every port accepts connections on 127.0.0.1 (True), or the viewer exits or a stop
    signal is noted (False)."""
    while process.poll() is None and not signals_seen:
        if all(_listening(port) for port in ports):
            return True
        time.sleep(POLL_SECONDS)
    return False


def _listening(port: int) -> bool:
    """Whether a server accepts connections on 127.0.0.1:port now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.settimeout(0.5)
        return probe.connect_ex(("127.0.0.1", port)) == 0


def _port_free(port: int) -> bool:
    """Whether a server could listen on 127.0.0.1:port now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as servers do: TIME_WAIT is no obstacle
        try:
            probe.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def _stop_group(process: subprocess.Popen) -> None:
    """SIGTERM to the viewer's process group, SIGKILL after STOP_GRACE_SECONDS, and wait until no
    process of the group is left (its leader reaped)."""
    group = process.pid  # start_new_session: the leader's pid is the group's id
    for sig in (signal.SIGTERM, signal.SIGKILL):
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(group, sig)
        deadline = time.monotonic() + STOP_GRACE_SECONDS
        while time.monotonic() < deadline:
            with contextlib.suppress(subprocess.TimeoutExpired):
                process.wait(timeout=0.05)
            if process.returncode is not None and not _group_alive(group):
                return


def _group_alive(group: int) -> bool:
    """Whether a live process (not a zombie: those hold no ports) is left in the process group."""
    proc = Path("/proc")
    if proc.is_dir():
        for entry in proc.iterdir():
            if not entry.name.isdigit():
                continue
            try:
                # /proc/<pid>/stat: "pid (comm) state ppid pgrp ..."; comm may hold spaces and parentheses
                fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            if len(fields) > 2 and int(fields[2]) == group and fields[0] != "Z":
                return True
        return False
    try:  # pragma: no cover - no /proc: ask the kernel (zombies count as alive there)
        os.killpg(group, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _save(file: Path, save: Path) -> None:
    """Convert (MCAP) or copy (RRD) to `save`, which must end in .rrd."""
    if save.suffix.lower() != ".rrd":
        guess = messages.suffix_guess(save, (".rrd",))
        raise messages.fail(f"--save {str(save)!r}: unknown format{guess}", expected="a file name ending in .rrd")
    if save.resolve() == file.resolve():
        raise messages.fail(f"--save {str(save)!r} is the input file", expected="another file name")
    from rbcli.record.output_file import OutputError, check_output

    try:  # before any work, as `run -o` does: a folder, a file where a folder should be, no permission
        check_output(save)
        save.parent.mkdir(parents=True, exist_ok=True)
        if file.suffix.lower() == ".rrd":
            shutil.copyfile(file, save)
            messages.status(f"{file} is already an .rrd; copied to {save}")
            return
    except OutputError as exc:
        raise messages.fail(str(exc).replace("output ", "--save ", 1)) from None
    except OSError as exc:
        raise messages.fail(f"--save {str(save)!r}: {exc.strerror or exc}") from None
    from rbcli.record.convert import mcap_to_rrd

    try:
        frames = mcap_to_rrd(file, save)
    except Exception as exc:  # a corrupt or foreign file: say so, never a traceback
        raise messages.fail(f"cannot convert {file}: {exc}") from None
    messages.status(f"wrote {save}: {frames} frames from {file}")
