"""Nothing lost: a sweep stopped part way (its parts are what finished) runs only the rest when started
again, and the table ends complete, one row per variant, equal to an uninterrupted run; a real Ctrl-C
of `rbsim sweep` keeps what finished; a folder of another sweep is never mixed in."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest
from sweep_cases import rows_without_wall_time, spring_sweep_fixture  # noqa: F401 - a fixture

from rbcli.sweeps.dask_runner import failed_rows
from rbcli.sweeps.load import load_sweep
from rbcli.sweeps.run import SweepOutputError, run_sweep
from rbcli.sweeps.table import write_part

ROOT = Path(__file__).resolve().parents[2]


def _part_variants(folder: Path) -> dict[Path, list[int]]:
    return {p: pq.read_table(p).column("variant").to_pylist() for p in sorted((folder / "parts").glob("*.parquet"))}


def test_resume_runs_only_the_variants_without_a_part(spring_sweep, tmp_path):
    spec = load_sweep(spring_sweep)
    whole = run_sweep(spec, scheduler="serial", output=tmp_path / "whole", batch=2)
    out = tmp_path / "stopped"
    run_sweep(spec, scheduler="serial", output=out, batch=2)
    parts = _part_variants(out)
    assert sorted(v for vs in parts.values() for v in vs) == list(range(6)) and len(parts) == 3
    # a sweep stopped after its first batch: the other batches never wrote their parts
    lost = [p for p in parts if 0 not in parts[p]]
    for p in lost:
        p.unlink()
    (out / "results.parquet").unlink()
    kept = next(p for p in parts if 0 in parts[p])
    kept_stat = kept.stat()
    again = run_sweep(spec, scheduler="serial", output=out, batch=2)
    assert again.resumed == 2 and again.ran == 4
    new_parts = _part_variants(out)
    assert kept in new_parts and kept.stat().st_mtime_ns == kept_stat.st_mtime_ns  # left as it was
    assert sorted(v for p, vs in new_parts.items() if p != kept for v in vs) == [2, 3, 4, 5]  # only the rest
    table = pq.read_table(out / "results.parquet")
    assert table.column("variant").to_pylist() == list(range(6))  # complete, no duplicates
    assert rows_without_wall_time(table) == rows_without_wall_time(whole.table)
    # and once complete, a run again has nothing left to do
    assert run_sweep(spec, scheduler="serial", output=out).ran == 0


def test_resume_runs_exactly_the_variants_the_cluster_lost_and_retry_failed_the_failed_ones(spring_sweep, tmp_path):
    """A folder where the cluster lost variants 2 and 3 (rows "lost", as dask_runner records a task lost
    more often than it retries) and an older rbsim recorded variant 0's lost task as an "error" row:
    resuming runs exactly those three, the table ends equal to an uninterrupted run; the diverged and
    failed variants 4 and 5 are their own results and run again only with retry_failed."""
    spec = load_sweep(spring_sweep)
    whole = run_sweep(spec, scheduler="serial", output=tmp_path / "whole", batch=2)
    out = tmp_path / "out"
    run_sweep(spec, scheduler="serial", output=out, batch=2)
    parts = _part_variants(out)
    for part, variants in parts.items():
        if variants == [2, 3]:
            part.unlink()
            write_part(out, failed_rows([(2, ()), (3, ())], "lost", "the cluster lost this variant's task 5 times"))
        if variants == [0, 1]:
            rows = pq.read_table(part).to_pylist()
            rows[0].update(status="error", message="the task failed on the cluster: FutureCancelledError: forgotten")
            part.unlink()
            write_part(out, rows)
    ran: list[int] = []

    def note(rows: list[dict]) -> None:
        ran.extend(row["variant"] for row in rows)

    again = run_sweep(spec, scheduler="serial", output=out, batch=1, on_rows=note)
    assert sorted(ran) == [0, 2, 3] and again.resumed == 3
    assert again.complete and again.all_finished
    table = pq.read_table(out / "results.parquet")
    assert table.column("variant").to_pylist() == list(range(6))  # one row each: the new ones won
    assert rows_without_wall_time(table) == rows_without_wall_time(whole.table)
    ran.clear()
    retried = run_sweep(spec, scheduler="serial", output=out, batch=1, retry_failed=True, on_rows=note)
    assert sorted(ran) == [4, 5] and retried.resumed == 4  # the diverged / failed k = 1e6 pair
    assert rows_without_wall_time(retried.table) == rows_without_wall_time(whole.table)


def test_a_folder_of_another_sweep_is_refused_unless_fresh(spring_sweep, tmp_path):
    out = tmp_path / "out"
    run_sweep(load_sweep(spring_sweep), scheduler="serial", output=out)
    spring_sweep.write_text(spring_sweep.read_text().replace("[split2, rk4]", "[split2]"))
    changed = load_sweep(spring_sweep)
    with pytest.raises(SweepOutputError, match="another sweep"):
        run_sweep(changed, scheduler="serial", output=out)
    result = run_sweep(changed, scheduler="serial", output=out, fresh=True)
    assert result.ran == 3 and result.table.num_rows == 3


def test_ctrl_c_keeps_the_finished_batches_and_the_same_command_resumes(tmp_path):
    scene = (ROOT / "scenes" / "verification" / "intermediate_axis.yaml").resolve()
    sweep = tmp_path / "flip.sweep.yaml"
    # 24 variants of 20,000 split2 steps (tens of ms each): long enough to stop part way
    sweep.write_text(
        f"scene: {scene}\nsamples: 24\nseed: 5\naxes:\n"
        "  - path: bodies[0].angular_momentum\n"
        "    random: {distribution: normal, mean: [0.01, 10.0, 0.0], std: [0.01, 0.0, 0.01]}\n"
        "  - path: simulation.dt\n    values: [0.001]\n  - path: simulation.integrator\n    values: [split2]\n"
    )
    out = tmp_path / "out"
    command = [sys.executable, "-m", "rbcli", "sweep", str(sweep), "--serial", "--batch", "1", "-o", str(out)]
    proc = subprocess.Popen(command, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 120
    while not list((out / "parts").glob("part-*.parquet")) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    output, _ = proc.communicate(timeout=120)
    finished = {v for vs in _part_variants(out).values() for v in vs}
    if proc.returncode == 0:  # the machine ran all 24 before the signal landed: nothing to resume
        pytest.skip("the sweep finished before Ctrl-C arrived")
    assert proc.returncode == 130, output
    assert "interrupted" in output and "run the same command again to resume" in output
    assert 0 < len(finished) < 24
    partial = pq.read_table(out / "results.parquet")
    assert sorted(partial.column("variant").to_pylist()) == sorted(finished)  # what finished, merged
    before = set(_part_variants(out))
    again = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert f"resuming: {len(finished)} of 24 variants already finished" in again.stderr
    rerun = {v for p, vs in _part_variants(out).items() if p not in before for v in vs}
    assert rerun == set(range(24)) - finished  # only the rest ran
    table = pq.read_table(out / "results.parquet")
    assert table.column("variant").to_pylist() == list(range(24))
    assert set(table.column("status").to_pylist()) == {"completed"}
    assert os.path.exists(out / "sweep.json")
