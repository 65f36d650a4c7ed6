"""The same sweep on Dask: a 2-worker LocalCluster gives the serial rows bitwise (wall time aside), with
the work spread over both workers; a worker killed mid-sweep costs nothing (Dask runs its task again);
`rbsim sweep` starts its own cluster; nothing but `rbsim sweep` imports Dask."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from sweep_cases import rows_without_wall_time, spring_sweep_fixture  # noqa: F401 - a fixture
from typer.testing import CliRunner

from rbcli.cli.app import app
from rbcli.sweeps.load import load_sweep
from rbcli.sweeps.run import run_sweep

distributed = pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


@pytest.fixture(scope="module")
def client():
    """A LocalCluster of two single-threaded worker processes, as `rbsim sweep` starts on a 2-core machine."""
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    with distributed.Client(cluster) as c:
        yield c
    cluster.close()


def test_two_workers_give_the_serial_rows_bitwise(spring_sweep, tmp_path, client):
    spec = load_sweep(spring_sweep)
    serial = run_sweep(spec, scheduler="serial", output=tmp_path / "serial")
    with distributed.get_task_stream(client) as stream:
        on_dask = run_sweep(spec, scheduler=client, output=tmp_path / "dask", batch=1)
    assert {t["worker"] for t in stream.data if "run_batch" in str(t["key"])} == set(client.nthreads())  # both ran
    assert on_dask.table.column("variant").to_pylist() == list(range(6))
    assert rows_without_wall_time(on_dask.table) == rows_without_wall_time(serial.table)
    # and with the batches sized from the first variants' time
    sized = run_sweep(spec, scheduler=client, output=tmp_path / "sized")
    assert rows_without_wall_time(sized.table) == rows_without_wall_time(serial.table)


def test_a_worker_killed_mid_sweep_loses_nothing(tmp_path, client):
    scene = (ROOT / "scenes" / "verification" / "intermediate_axis.yaml").resolve()
    sweep = tmp_path / "flip.sweep.yaml"
    # 8 variants of 200,000 split2 steps (~0.1 s each on a quiet core), one per task
    sweep.write_text(
        f"scene: {scene}\nsamples: 8\nseed: 2\naxes:\n"
        "  - path: bodies[0].angular_momentum\n"
        "    random: {distribution: normal, mean: [0.01, 10.0, 0.0], std: [0.01, 0.0, 0.01]}\n"
        "  - path: simulation.dt\n    values: [0.0001]\n  - path: simulation.integrator\n    values: [split2]\n"
    )
    spec = load_sweep(sweep)
    killed: list[int] = []

    def kill_a_busy_worker(rows):  # noqa: ANN001 - called by the sweep after each batch, in this thread
        if killed:
            return
        busy = [address for address, keys in client.processing().items() if keys]
        if busy:
            pid = client.run(os.getpid, workers=busy[:1])[busy[0]]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    on_dask = run_sweep(spec, scheduler=client, output=tmp_path / "dask", batch=1, on_rows=kill_a_busy_worker)
    assert killed, "no worker was busy when the first batch came back"
    table = pq.read_table(tmp_path / "dask" / "results.parquet")
    assert table.column("variant").to_pylist() == list(range(8))  # complete, no duplicates
    assert set(table.column("status").to_pylist()) == {"completed"}
    serial = run_sweep(spec, scheduler="serial", use_folder=False)
    assert rows_without_wall_time(on_dask.table) == rows_without_wall_time(serial.table)


def test_sweep_command_starts_its_own_cluster(spring_sweep, tmp_path):
    out = tmp_path / "out"
    result = runner.invoke(app, ["sweep", str(spring_sweep), "--workers", "2", "-o", str(out)])
    assert result.exit_code == 0, result.output
    assert "Dask: 2 workers (2 slots) ready in" in result.output
    serial = run_sweep(load_sweep(spring_sweep), scheduler="serial", use_folder=False)
    assert rows_without_wall_time(pq.read_table(out / "results.parquet")) == rows_without_wall_time(serial.table)


def test_only_the_sweep_imports_dask():
    code = (
        "import sys, rbcli, rbcli.cli.app, rbcli.api, rbcli.sweeps.run, rbcli.sweeps.load\n"
        "from rbcli.cli import run, validate\n"
        "rbcli.sweep\n"
        "print(sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed', 'pyarrow')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"
