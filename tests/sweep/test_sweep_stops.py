"""A stop at the worst moment: Ctrl-C (SIGINT to the whole process group, as a terminal sends it) while
`rbsim sweep`'s local cluster is starting and its worker processes are still importing. It ends with
one line, exit status 130, no traceback from rbsim, Dask or the workers, and no process left behind.
(Before: the workers printed KeyboardInterrupt tracebacks from their imports and Dask's atexit close
another.)"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[2]


def test_ctrl_c_while_the_cluster_starts_is_one_line_and_exit_130(tmp_path):
    scene = (ROOT / "scenes" / "verification" / "intermediate_axis.yaml").resolve()
    sweep = tmp_path / "flip.sweep.yaml"
    sweep.write_text(f"scene: {scene}\naxes:\n  - path: simulation.dt\n    values: [0.001, 0.0005]\n")
    command = [sys.executable, "-m", "rbcli", "sweep", str(sweep), "--workers", "2", "-o", str(tmp_path / "out")]
    proc = subprocess.Popen(
        command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )
    try:
        me = psutil.Process(proc.pid)
        deadline = time.monotonic() + 120
        starting: list[psutil.Process] = []
        while not starting and proc.poll() is None and time.monotonic() < deadline:
            starting = [p for p in me.children(recursive=True) if "spawn_main" in " ".join(p.cmdline())]
            time.sleep(0.005)
        assert starting, "no worker process was started"
        time.sleep(0.5)  # into the workers' imports (a second or more), before the cluster is up
        os.killpg(proc.pid, signal.SIGINT)  # the terminal's Ctrl-C: this process and every worker
        output, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130, output
    lines = [line for line in output.splitlines() if line.strip()]
    assert lines[0].startswith("sweep flip: 2 variants of") and len(lines) == 2, output
    assert lines[1].startswith("interrupted: ") and "run the same command again to resume" in lines[1]
    time.sleep(1.0)  # the workers' exit is noticed by their parents, which are gone: init reaps them
    left = [p for p in psutil.process_iter(["pid"]) if _session(p) == proc.pid and p.status() != "zombie"]
    assert not left, left


def _session(process: psutil.Process) -> int | None:
    try:
        return os.getsid(process.pid)
    except OSError:
        return None


def test_the_python_example_of_the_docs_runs_as_a_script(tmp_path):
    """docs/sweeps.md's `rbcli.sweep` block, run as a file: its local cluster's workers import the file
    again, which only the `__main__` guard makes harmless (without it: Nanny failed to start)."""
    docs = (ROOT / "docs" / "sweeps.md").read_text(encoding="utf-8")
    section = docs[docs.index("## Python") :]
    block = section[section.index("```python\n") + len("```python\n") : section.index("\n```\n")]
    assert "rbcli.sweep(" in block and 'if __name__ == "__main__":' in block
    script = tmp_path / "sweep_example.py"
    script.write_text(block + "\n")
    out = subprocess.run([sys.executable, str(script)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip() == "8 variants: {'completed'}", out.stdout
