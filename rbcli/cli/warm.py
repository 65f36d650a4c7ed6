"""`rbsim warm`: compile the kernels of a small scene of each kind, or of the given scenes, into numba's
cache ahead of their first runs, several processes at once (rbcli/runner/warm.py)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Annotated

import typer

from rbcli.cli import messages
from rbcli.cli.exit_codes import ExitCode

POLL_SECONDS = 0.1


def warm(
    scenes: Annotated[
        list[Path] | None,
        typer.Argument(
            metavar="SCENE",
            help="Scene files whose kernels to prepare [default: a small scene of each kind]",
            show_default=False,
        ),  # fmt: skip
    ] = None,
    jobs: Annotated[
        int | None,
        typer.Option(
            "--jobs",
            "-j",
            min=1,
            metavar="N",
            help="Processes compiling at once [default: the cores]",
            show_default=False,
        ),  # fmt: skip
    ] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Print errors only")] = False,
) -> None:
    """Compile the kernels the first runs of SCENEs need (or of one small scene of each kind: free bodies,
    forces, contact, joints, joints with contact) into numba's cache, several at once, so that those runs
    load them instead of compiling; exits 1 when a scene is invalid or a compile fails."""
    from rbcli.runner.threads import available_cores
    from rbcli.scene.load import analyse_scene

    with tempfile.TemporaryDirectory(prefix="rbsim-warm-") as folder:
        if scenes:
            labels = [(str(path), path) for path in scenes]
            invalid = 0
            for _, path in labels:
                if not path.is_file():
                    messages.error("scene file not found", expected="a path to a YAML scene file", where=path)
                    invalid += 1
                    continue
                spec, issues = analyse_scene(path)
                messages.issues(issues, path)
                invalid += spec is None
            if invalid:
                raise typer.Exit(ExitCode.INVALID)
        else:
            from rbcli.runner.warm import KIND_ORDER, kind_scene

            labels = []
            for kind in KIND_ORDER:
                path = Path(folder) / f"{kind.replace('+', '_')}.yaml"
                path.write_text(kind_scene(kind))
                labels.append((kind, path))
        failed = _warm_all(labels, jobs or available_cores(), quiet)
    if failed:
        raise typer.Exit(ExitCode.INVALID)


def _warm_all(labels: list[tuple[str, Path]], jobs: int, quiet: bool) -> int:
    """Each scene in a process of its own (python -m rbcli.runner.warm), `jobs` at a time; a line per
    scene as it ends. Returns how many failed; a stop signal stops every process (what finished stays
    cached) and exits 128 + the signal."""
    pending, failed, started = list(labels), 0, time.perf_counter()
    running: list[tuple[str, subprocess.Popen[str]]] = []
    stops: list[int] = []
    previous = {
        s: signal.signal(s, lambda received, frame: stops.append(received)) for s in (signal.SIGINT, signal.SIGTERM)
    }
    try:
        while (pending or running) and not stops:
            while pending and len(running) < jobs:
                label, path = pending.pop(0)
                command = [sys.executable, "-m", "rbcli.runner.warm", str(path)]
                running.append(
                    (label, subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
                )
            time.sleep(POLL_SECONDS)
            for label, process in [item for item in running if item[1].poll() is not None]:
                running.remove((label, process))
                out, err = process.communicate()
                if process.returncode != 0:
                    failed += 1
                    messages.error(f"warm {label}: the compile failed (exit {process.returncode})",
                                   expected=err.strip().splitlines()[-1] if err.strip() else "")  # fmt: skip
                elif not quiet:
                    done = json.loads(out.strip().splitlines()[-1])
                    what = (f"compiled {done['functions']} functions" if done["functions"] else
                            "nothing to compile (in the cache)")  # fmt: skip
                    messages.status(f"warm {label}: {what} in {done['seconds']:.1f} s")
    finally:
        for _, process in running:  # a stop: each ends its compile at a safe point (runner/warm.py)
            process.send_signal(signal.SIGTERM)
        for _, process in running:
            process.wait()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    if stops:
        messages.status(f"stopped by {signal.Signals(stops[0]).name} (what finished compiling is cached)")
        raise typer.Exit(128 + stops[0])
    if not quiet:
        messages.status(f"warm: {len(labels) - failed} of {len(labels)} ready in {time.perf_counter() - started:.1f} s "
                        f"({jobs} at a time)")  # fmt: skip
    return failed
