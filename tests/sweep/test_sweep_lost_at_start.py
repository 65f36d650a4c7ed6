"""Workers lost while `rbsim sweep` starts are lost workers like any other: the sweep goes on with the
workers that live (the local cluster's nannies start new ones), every variant gets its row, bitwise the
serial run's, exit status 0, and one line says what happened. Each test kills a real worker process of
the sweep's own LocalCluster at one moment of the start:

- while the cluster starts (the worker processes SIGKILLed as they appear, before they joined): before,
  a traceback ending "RuntimeError: Nanny failed to start." and exit 1;
- while its kernels warm up (the worker kills itself in its warm-up task): before, the sweep hung for
  good, its client waiting on a task pinned to the dead worker;
- as its versions are checked (the worker kills itself in that check): before, exit 1 with "worker ...
  cannot run rbsim" (the broken comm read as a bad worker) and no rows.

The last two run `rbsim sweep` from a small script that wraps one function of dask_runner (pickled by
value into the workers) so that the first worker process to run it SIGKILLs itself: the moment is then
exact, and the rest is the real CLI, Dask and worker processes."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pyarrow.parquet as pq
import pytest
from sweep_cases import rows_without_wall_time

from rbcli.sweeps.load import load_sweep
from rbcli.sweeps.run import run_sweep

ROOT = Path(__file__).resolve().parents[2]
VARIANTS = 8
# A start takes ~3 s here and a retried one twice that; a sweep that has not ended in this long hangs.
SWEEP_TIMEOUT_SECONDS = 120


def _flip_sweep(folder: Path) -> Path:
    """VARIANTS torque-free flip variants of 2,000 split2 steps: short, so the start is most of the test."""
    scene = (ROOT / "scenes" / "verification" / "intermediate_axis.yaml").resolve()
    sweep = folder / "flip.sweep.yaml"
    sweep.write_text(
        f"scene: {scene}\nsamples: {VARIANTS}\nseed: 3\naxes:\n  - path: bodies[0].angular_momentum\n"
        "    random: {distribution: normal, mean: [0.01, 10.0, 0.0], std: [0.01, 0.0, 0.01]}\n"
        "  - path: simulation.dt\n    values: [0.001]\n"
    )
    return sweep


# Runs `rbsim sweep ARGS...` with dask_runner.<NAME> wrapped: the first worker process to call it (a marker
# file, created atomically, picks one) SIGKILLs itself there. The client process runs the real one.
KILLER_SCRIPT = """\
import multiprocessing, os, signal, sys


def main():
    name, marker = sys.argv[1], sys.argv[2]
    from rbcli.sweeps import dask_runner

    real = getattr(dask_runner, name)

    def dies_once_in_a_worker(*args):
        if multiprocessing.current_process().name != "MainProcess":
            try:
                os.close(os.open(marker, os.O_CREAT | os.O_EXCL))
            except FileExistsError:
                pass
            else:
                os.kill(os.getpid(), signal.SIGKILL)
        return real(*args)

    setattr(dask_runner, name, dies_once_in_a_worker)
    from rbcli.cli.app import app

    app(sys.argv[3:], prog_name="rbsim")


if __name__ == "__main__":  # the local cluster's workers import this file again
    main()
"""


@pytest.fixture(scope="module")
def serial_rows(tmp_path_factory) -> list[dict]:
    """The rows of the flip sweep run serially in this process: what every test's sweep must give."""
    sweep = _flip_sweep(tmp_path_factory.mktemp("serial"))
    return rows_without_wall_time(run_sweep(load_sweep(sweep), scheduler="serial", use_folder=False).table)


def _run_until_done(proc: subprocess.Popen) -> str:
    """The sweep's output once it ends; a sweep still running after SWEEP_TIMEOUT_SECONDS is killed
    (with its workers) and fails the test as hung."""
    try:
        output, _ = proc.communicate(timeout=SWEEP_TIMEOUT_SECONDS)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        output, _ = proc.communicate()
        pytest.fail(f"the sweep hung (killed after {SWEEP_TIMEOUT_SECONDS} s):\n{output}")
    return output


def _check_finished_with_one_line(output: str, returncode: int, out: Path, incident: str, serial: list[dict]) -> None:
    """Exit 0, every variant's row bitwise the serial run's, and the output: the sweep's line, the cluster's,
    one line naming the loss, the result's; no traceback."""
    assert returncode == 0, output
    lines = [line for line in output.splitlines() if line.strip()]
    assert "Traceback" not in output and len(lines) == 4, output
    assert lines[1].startswith("Dask: ") and "ready in" in lines[1], output
    assert lines[2].startswith("Dask: ") and incident in lines[2], output
    assert lines[3].startswith(f"{VARIANTS} variants: {VARIANTS} completed"), output
    table = pq.read_table(out / "results.parquet")
    assert table.column("variant").to_pylist() == list(range(VARIANTS))
    assert rows_without_wall_time(table) == serial


def _killer_sweep(tmp_path: Path, function: str) -> tuple[subprocess.Popen, Path, Path]:
    sweep, out, marker = _flip_sweep(tmp_path), tmp_path / "out", tmp_path / "killed"
    script = tmp_path / "sweep_with_a_death.py"
    script.write_text(KILLER_SCRIPT)
    args = [str(script), function, str(marker), "sweep", str(sweep), "--workers", "2", "-o", str(out)]
    proc = subprocess.Popen(
        [sys.executable, *args],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,  # its own process group: a hung sweep is killed with its workers
    )
    return proc, out, marker


def test_a_worker_killed_while_the_kernels_warm_up_costs_no_variant(tmp_path, serial_rows):
    proc, out, marker = _killer_sweep(tmp_path, "warm_up")
    output = _run_until_done(proc)
    assert marker.exists(), "no worker was killed"
    _check_finished_with_one_line(output, proc.returncode, out, "was lost while its kernels warmed up", serial_rows)


def test_a_worker_killed_as_its_versions_are_checked_is_not_refused(tmp_path, serial_rows):
    proc, out, marker = _killer_sweep(tmp_path, "runtime_versions")
    output = _run_until_done(proc)
    assert marker.exists(), "no worker was killed"
    assert "cannot run rbsim" not in output
    _check_finished_with_one_line(output, proc.returncode, out, "was lost as its versions were checked", serial_rows)


def test_workers_killed_while_the_local_cluster_starts_cost_no_variant(tmp_path, serial_rows):
    """Both worker processes SIGKILLed the moment they appear (still importing, not yet joined): the
    LocalCluster fails to start, and the sweep starts it again."""
    sweep, out = _flip_sweep(tmp_path), tmp_path / "out"
    command = [sys.executable, "-m", "rbcli", "sweep", str(sweep), "--workers", "2", "-o", str(out)]
    proc = subprocess.Popen(
        command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True
    )
    killed: set[int] = set()
    try:
        me = psutil.Process(proc.pid)
        deadline = time.monotonic() + 60
        while len(killed) < 2 and proc.poll() is None and time.monotonic() < deadline:
            for process in me.children(recursive=True):
                try:
                    if process.pid not in killed and "spawn_main" in " ".join(process.cmdline()):
                        process.kill()
                        killed.add(process.pid)
                except psutil.Error:  # gone meanwhile
                    pass
            time.sleep(0.005)
    finally:
        output = _run_until_done(proc)
    assert len(killed) == 2, f"the workers were not killed as they started:\n{output}"
    _check_finished_with_one_line(output, proc.returncode, out, "the local cluster failed to start", serial_rows)


def test_a_worker_that_dies_as_it_joins_mid_sweep_is_lost_not_refused(monkeypatch):
    """Workers that join while the sweep runs are asked for their versions with client.run (a task would
    wait behind the batch the scheduler may already have given them): one that dies as it is asked answers
    with the broken comm, which is the worker lost, returned for the sweep to go on without it, not a worker
    that "cannot run rbsim" (before: ClusterRefused, exit 1). A real worker of a real LocalCluster dies in
    the call; its nanny's replacement is asked next and passes."""
    import distributed

    from rbcli.sweeps import dask_runner

    real = dask_runner.runtime_versions

    def dies_in_a_worker() -> tuple[str, str]:  # defined here: pickled by value into the worker
        import multiprocessing

        if multiprocessing.current_process().name != "MainProcess":
            os.kill(os.getpid(), signal.SIGKILL)
        return real()

    cluster = distributed.LocalCluster(
        n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    )
    try:
        with distributed.Client(cluster) as client:
            (joined,) = client.nthreads()
            monkeypatch.setattr(dask_runner, "runtime_versions", dies_in_a_worker)
            assert dask_runner._check_joined_versions(client, [joined]) == [joined]
            monkeypatch.undo()
            deadline = time.monotonic() + 60
            while not (replacements := [a for a in client.nthreads() if a != joined]):
                assert time.monotonic() < deadline, "the nanny started no replacement"
                time.sleep(0.05)
            assert dask_runner._check_joined_versions(client, replacements) == []
    finally:
        cluster.close()
