"""The same sweep on Dask: a 2-worker LocalCluster gives the serial rows bitwise (wall time aside), with
the work spread over both workers; every worker killed mid-sweep costs nothing (the job and the lost
tasks run again); a variant that exhausts its worker's memory is a "crashed" row after a bounded number
of tries while the rest complete; `rbsim sweep` starts its own cluster; nothing but `rbsim sweep`
imports Dask."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import dask
import distributed
import pyarrow.parquet as pq
import pytest
from sweep_cases import rows_without_wall_time, spring_sweep_fixture  # noqa: F401 - a fixture
from typer.testing import CliRunner

from rbcli.cli.app import app
from rbcli.sweeps import table as tables
from rbcli.sweeps.dask_runner import run_on_dask
from rbcli.sweeps.load import load_sweep
from rbcli.sweeps.run import run_sweep, sweep_job

ROOT = Path(__file__).resolve().parents[2]
runner = CliRunner()


# The memory test's workers: 600 MiB each, checked every 50 ms (a worker past 95 % of it is killed by its
# nanny and restarted), and a task given up after killing its workers twice (allowed-failures 1), so
# the memory-exhausting variant below costs two short tries instead of Dask's four.
WORKER_MEMORY = 600 * 2**20
MEMORY_CONFIG = {
    "distributed.worker.memory.monitor-interval": "50ms",
    "distributed.worker.memory.terminate": 0.95,
    "distributed.scheduler.allowed-failures": 1,
}


def _cluster(**options) -> distributed.LocalCluster:  # noqa: ANN003 - LocalCluster's
    """Two single-threaded worker processes, as `rbsim sweep` starts on a 2-core machine, on 127.0.0.1."""
    return distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address="127.0.0.1:0", **options
    )


@pytest.fixture(scope="module")
def client():
    cluster = _cluster()
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


def _flip_sweep(folder: Path, samples: int, seed: int, dt: float = 1e-4) -> Path:
    """`samples` torque-free flip variants (intermediate_axis.yaml: 2 s; 20,000 split2 steps at 1e-4 s)."""
    scene = (ROOT / "scenes" / "verification" / "intermediate_axis.yaml").resolve()
    sweep = folder / "flip.sweep.yaml"
    sweep.write_text(
        f"scene: {scene}\nsamples: {samples}\nseed: {seed}\naxes:\n"
        "  - path: bodies[0].angular_momentum\n"
        "    random: {distribution: normal, mean: [0.01, 10.0, 0.0], std: [0.01, 0.0, 0.01]}\n"
        f"  - path: simulation.dt\n    values: [{dt}]\n  - path: simulation.integrator\n    values: [split2]\n"
    )
    return sweep


def _worker_pids(client) -> dict[str, int]:  # noqa: ANN001 - a distributed.Client
    return client.run(os.getpid)


def test_every_worker_killed_mid_sweep_loses_nothing(tmp_path, client):
    """Both workers of the cluster SIGKILLed after the first part: their nannies start new ones, the job
    (a task, not scattered data) is computed again there and every lost task runs again; the sweep
    ends with every row, bitwise the serial run's, and exit status 0. (With the scattered job the
    pending variants came back as "error" rows, lost dependencies, and the exit status was 0.)"""
    sweep = _flip_sweep(tmp_path, samples=16, seed=4, dt=1e-3)
    out = tmp_path / "out"
    address = client.cluster.scheduler_address
    command = [
        sys.executable,
        "-m",
        "rbcli",
        "sweep",
        str(sweep),
        "--scheduler",
        address,
        "--batch",
        "1",
        "-o",
        str(out),
    ]
    proc = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 120
        while not list((out / "parts").glob("part-*.parquet")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        before = _worker_pids(client)
        for pid in before.values():
            os.kill(pid, signal.SIGKILL)
        finished_at_kill = len(list((out / "parts").glob("part-*.parquet")))
        output, _ = proc.communicate(timeout=180)
    finally:
        proc.kill()
    assert 0 < finished_at_kill < 16 and len(before) == 2, "the kill did not land mid-sweep"
    assert proc.returncode == 0, output
    table = pq.read_table(out / "results.parquet")
    assert table.column("variant").to_pylist() == list(range(16))
    assert set(table.column("status").to_pylist()) == {"completed"}
    serial = run_sweep(load_sweep(sweep), scheduler="serial", use_folder=False)
    assert rows_without_wall_time(table) == rows_without_wall_time(serial.table)
    client.wait_for_workers(2, timeout=60)
    assert not set(_worker_pids(client).values()) & set(before.values())  # both were new workers


HERD_SCENE = """\
name: herd
simulation: {dt: 0.001, steps: 200, integrator: split2}
bodies:
  - grid:
      name: plate
      count: [4, 4, 4]
      spacing: 3.0
      template:
        particles:
          positions: [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]
          masses: [1.0, 1.0, 0.5, 0.5]
        angular_momentum: [0.5, 0.6, 12.0]
"""


def test_a_variant_that_exhausts_its_workers_memory_is_recorded_crashed_and_the_rest_complete(tmp_path):
    """64 bodies recorded every step (`record.frames: scene`) keep ~10 kB a frame in memory: 200 steps
    are 2 MB, 150,000 steps would be 1.5 GB, past the workers' 600 MiB, so the nanny kills that variant's
    worker each time it runs it. After allowed-failures + 1 = 2 tries it is a "crashed" row saying so;
    the other variants complete; resuming leaves it alone, `retry_failed` tries it again."""
    (tmp_path / "herd.yaml").write_text(HERD_SCENE)
    sweep = tmp_path / "herd.sweep.yaml"
    sweep.write_text(
        "scene: herd.yaml\nrecord: {frames: scene}\naxes:\n"
        "  - path: simulation.steps\n    values: [100, 150000, 200, 250]\n"
    )
    out = tmp_path / "out"
    with dask.config.set(MEMORY_CONFIG):
        cluster = _cluster(memory_limit=WORKER_MEMORY)  # its own: no later test waits for its restarts
    try:
        command = ["sweep", str(sweep), "--scheduler", cluster.scheduler_address, "--batch", "1", "-o", str(out)]
        result = runner.invoke(app, command)
    finally:
        cluster.close()
    assert result.exit_code == 4, result.output  # not every variant has a result
    assert "1 of 4 variants have no result of their own" in result.output
    rows = {row["variant"]: row for row in pq.read_table(out / "results.parquet").to_pylist()}
    assert sorted(rows) == [0, 1, 2, 3]  # the crashed variant's row is recorded
    assert rows[1]["status"] == "crashed", rows[1]
    assert "took down its worker on each of its 2 tries" in rows[1]["message"]
    assert "KilledWorker" in rows[1]["message"]
    for variant, steps in ((0, 100), (2, 200), (3, 250)):
        assert rows[variant]["status"] == "completed" and rows[variant]["steps"] == steps
    again = run_sweep(load_sweep(sweep), scheduler="serial", output=out)
    assert again.ran == 0 and again.crashed == 1 and not again.all_finished  # the crash is its own result


def test_a_worker_of_another_rbsim_version_is_refused_in_one_line(spring_sweep, tmp_path, client):
    """A worker whose rbcli says another version (set in that worker's process) stops the sweep before
    anything runs: exit 1 and one error line naming both versions."""
    import numba

    import rbcli._version

    def pretend(version: str):  # noqa: ANN202 - a function for client.run, self-contained (pickled by value)
        return lambda: setattr(__import__("rbcli._version").__dict__["_version"], "__version__", version)

    worker = sorted(client.nthreads())[0]
    client.run(pretend("9.9.9"), workers=[worker])
    try:
        address = client.cluster.scheduler_address
        result = runner.invoke(app, ["sweep", str(spring_sweep), "--scheduler", address, "-o", str(tmp_path / "out")])
    finally:
        client.run(pretend(rbcli._version.__version__), workers=[worker])
    assert result.exit_code == 1, result.output
    errors = [line for line in result.output.splitlines() if "error:" in line]
    assert len(errors) == 1 and "Traceback" not in result.output, result.output
    assert f"worker {worker} runs rbsim 9.9.9 with numba {numba.__version__}" in errors[0]
    assert f"this rbsim is {rbcli._version.__version__} with numba {numba.__version__}" in errors[0]
    assert not (tmp_path / "out" / "parts").exists()  # nothing ran


MESH_SCENE = """\
name: crate
simulation: {dt: 0.001, steps: 500, integrator: split2}
bodies:
  - name: crate
    mesh: {file: meshes/cube.obj, scale: 0.5}
    spacing: 0.1
    density: 500
    angular_velocity: [0.5, 0.2, 3.0]
"""


def test_a_mesh_scene_runs_on_workers_that_cannot_see_the_mesh(tmp_path, client):
    """The job carries the mesh file's bytes: with the scene's mesh folder gone from the machine the
    workers run on (as on a cluster without a shared file system), every variant still loads the same
    mesh and its row is bitwise the serial run's (made while the folder was there). Before, every row
    was "invalid": the workers looked for the mesh at the client's absolute path."""
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "cube.obj").write_bytes((ROOT / "scenes" / "meshes" / "cube.obj").read_bytes())
    (tmp_path / "crate.yaml").write_text(MESH_SCENE)
    sweep = tmp_path / "crate.sweep.yaml"
    sweep.write_text("scene: crate.yaml\naxes:\n  - path: bodies[0].angular_velocity[2]\n    values: [3.0, -2.0]\n")
    spec = load_sweep(sweep)
    serial = run_sweep(spec, scheduler="serial", use_folder=False)
    assert set(serial.table.column("status").to_pylist()) == {"completed"}
    job = sweep_job(spec)
    (tmp_path / "meshes").rename(tmp_path / "elsewhere")  # the workers' machine has no such folder
    rows: list[dict] = []
    pending = [(i, spec.variant_values(i)) for i in range(spec.variant_count)]
    run_on_dask(job, pending, rows.extend, scheduler=client, batch=1)
    table = tables.merge(spec, tables.rows_table(rows), complete=True)
    assert rows_without_wall_time(table) == rows_without_wall_time(serial.table)
