"""The local cluster `rbsim sweep` starts itself (no other Client in this module, so `Client.current()`
is the sweep's). A stop at the worst moment: Ctrl-C (SIGINT to the whole process group, as a terminal sends it) while
`rbsim sweep`'s local cluster is starting and its worker processes are still importing. It ends with
one line, exit status 130, no traceback from rbsim, Dask or the workers, and no process left behind.
(Before: the workers printed KeyboardInterrupt tracebacks from their imports and Dask's atexit close
another.) Every endpoint on 127.0.0.1; a worker that joins is counted in; the docs' Python example runs
as a script."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
import urllib.parse
import urllib.request
from pathlib import Path

import distributed
import psutil
from sweep_cases import rows_without_wall_time

from rbcli.sweeps import dask_runner
from rbcli.sweeps.load import load_sweep
from rbcli.sweeps.run import run_sweep

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


def _listening_addresses() -> set[str]:
    """The addresses this process and its children listen on (TCP)."""
    me = psutil.Process()
    found = set()
    for process in (me, *me.children(recursive=True)):
        with contextlib.suppress(psutil.Error):
            found |= {c.laddr.ip for c in process.net_connections(kind="tcp") if c.status == psutil.CONN_LISTEN}
    return found


def test_the_local_cluster_listens_on_loopback_and_takes_in_workers_that_join(tmp_path):
    """The sweep's own LocalCluster: every endpoint (scheduler, its HTTP server, nannies, workers) on
    127.0.0.1, where Dask's dashboard default listened on every interface. A worker added while the
    sweep runs is counted in: the slots the batches are sized for become 2, and the rows stay the
    serial run's. bokeh is installed with the test extras, so the sweep reports its dashboard's link, which
    answers on 127.0.0.1 while the sweep runs."""
    scene = (ROOT / "scenes" / "verification" / "intermediate_axis.yaml").resolve()
    sweep = tmp_path / "flip.sweep.yaml"
    # 16 variants of 100,000 split2 steps
    sweep.write_text(
        f"scene: {scene}\nsamples: 16\nseed: 6\naxes:\n  - path: bodies[0].angular_momentum\n"
        "    random: {distribution: normal, mean: [0.01, 10.0, 0.0], std: [0.01, 0.0, 0.01]}\n"
        "  - path: simulation.dt\n    values: [0.0002]\n"
    )
    spec = load_sweep(sweep)
    seen: dict[str, set[str]] = {}

    def ready(total: int, done: int, cluster) -> None:  # noqa: ANN001 - ClusterInfo
        seen["listening"] = _listening_addresses()
        seen["dashboard"] = cluster.dashboard
        with urllib.request.urlopen(cluster.dashboard, timeout=30) as page:  # the status page, from bokeh
            seen["dashboard_status"] = page.status
        client = distributed.Client.current()  # the sweep's own: this module makes no other
        client.cluster.scale(2)  # a second worker joins, after the sweep counted its slots
        client.wait_for_workers(2, timeout=60)

    on_dask = run_sweep(spec, workers=1, use_folder=False, on_start=ready)
    assert seen["listening"] and seen["listening"] <= {"127.0.0.1"}, seen
    assert urllib.parse.urlsplit(seen["dashboard"]).hostname == "127.0.0.1" and seen["dashboard_status"] == 200
    assert on_dask.cluster.workers == 2 and on_dask.cluster.slots == 2 and on_dask.cluster.joined == 1
    serial = run_sweep(spec, scheduler="serial", use_folder=False)
    assert rows_without_wall_time(on_dask.table) == rows_without_wall_time(serial.table)


def test_without_bokeh_there_is_no_dashboard_link(monkeypatch):
    """Dask serves its dashboard only with bokeh: without it the sweep names none (no dead link)."""

    class Client:
        dashboard_link = "http://127.0.0.1:8787/status"

    real = dask_runner.importlib.util.find_spec
    monkeypatch.setattr(dask_runner.importlib.util, "find_spec", lambda n, *a: None if n == "bokeh" else real(n, *a))
    assert dask_runner._dashboard(Client()) is None
    monkeypatch.undo()
    assert dask_runner._dashboard(Client()) == Client.dashboard_link
