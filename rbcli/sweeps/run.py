"""Running a sweep: its folder (parts, manifest, results), resuming, and the serial or Dask execution.

    outputs/<name>/sweep.json        the sweep's fingerprint: a folder belongs to one sweep
    outputs/<name>/parts/*.parquet   one file per finished batch (table.py), the record of what is done
    outputs/<name>/results.parquet   every part merged, one row per variant, rewritten at each end
    outputs/<name>/logs/             variant-<n>.mcap when logs are on

Starting a sweep whose folder already holds parts of the same sweep resumes it: the finished variants
are skipped and the rest run (those without a row, and those whose row says the cluster lost them;
`retry_failed` runs every variant that did not complete). A folder of another sweep (its file or scene
changed since) is refused unless `fresh` (which empties it). Each variant's row depends on nothing but
the variant: the same row (wall time aside) whether it ran alone, in a batch, on a cluster or resumed.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rbcli.scene.spec import SceneError
from rbcli.sweeps.batches import Batcher
from rbcli.sweeps.execute import STATUS_CRASHED, SweepJob, run_batch, warm_up
from rbcli.sweeps.spec import SweepSpec

if TYPE_CHECKING:
    import pyarrow as pa

    from rbcli.sweeps.dask_runner import ClusterInfo

DEFAULT_OUTPUT_DIR = Path("outputs")
SERIAL = "serial"  # scheduler value: run every variant in this process, one after the other


class SweepOutputError(ValueError):
    """The output folder cannot take this sweep (another sweep's results, or not writable)."""


@dataclass
class SweepRun:
    """How a sweep went: the merged table, its folder, variant counts and the cluster it used."""

    table: pa.Table
    output: Path | None
    variants: int
    resumed: int  # finished before this run (skipped)
    ran: int
    failed: int  # rows of this run whose status is not "completed"
    wall_s: float  # from the first variant started to the last row (cluster start-up, warm-up, shut-down excluded)
    cluster: ClusterInfo | None = None
    complete: bool = True  # every variant has its own result (a row, and not one lost to the cluster)
    unfinished: int = 0  # variants without their own result: no row, or lost to the cluster (resume runs them)
    crashed: int = 0  # variants that took their worker down on every try (`retry_failed` runs them again)

    @property
    def all_finished(self) -> bool:
        """Every variant ran to its own end (completed, diverged, invalid or its own error): the exit
        status 0 of `rbsim sweep`; otherwise 4 (cli/exit_codes.py)."""
        return self.unfinished == 0 and self.crashed == 0


def sweep(
    base_scene: str | Path,
    axes: Sequence[Mapping[str, Any]] | Mapping[str, Any],
    *,
    combine: str = "product",
    samples: int | None = None,
    seed: int = 0,
    scheduler: Any = None,
    workers: int | None = None,
    batch: int | None = None,
    frames: int | str = 101,
    output: str | Path | None = None,
    logs: bool = False,
    fresh: bool = False,
    retry_failed: bool = False,
) -> pa.Table:
    """Run a scene over a set of axis values and return the results table (pyarrow; `table.py` lists the
    columns; `.to_pandas()` when pandas is installed).

    axes: as in a sweep file (a list of {path, values | grid | random}), or a mapping path -> values
    (a list) or path -> {grid: ...} / {random: ...}, e.g. {"simulation.dt": [1e-3, 5e-4]}.
    scheduler: None (a LocalCluster sized to the machine), "serial" (this process), a Dask scheduler
    address, or a distributed.Client. output: a folder for the parts and results.parquet (a sweep
    interrupted there resumes when run again); None keeps the results in memory only. retry_failed: on
    resuming, run again every variant that did not complete (not only those the cluster lost).
    Raises SceneError (every issue, located in the YAML text of this definition) for a bad sweep.
    """
    from rbcli.sweeps.load import analyse_sweep_text, sweep_definition_text

    if isinstance(axes, Mapping):
        axes = [
            {"path": path, **(spec if isinstance(spec, Mapping) else {"values": spec})} for path, spec in axes.items()
        ]
    definition: dict[str, Any] = {
        "scene": str(Path(base_scene).resolve()),
        "axes": [dict(a) for a in axes],
        "combine": combine,
        "seed": seed,
        "record": {"frames": frames, "logs": logs},
    }
    if samples is not None:
        definition["samples"] = samples
    if batch is not None:
        definition["batch"] = batch
    spec, issues = analyse_sweep_text(sweep_definition_text(definition), "<rbcli.sweep>")
    if spec is None:
        raise SceneError(issues)
    return run_sweep(
        spec,
        scheduler=scheduler,
        workers=workers,
        output=output,
        fresh=fresh,
        use_folder=output is not None,
        retry_failed=retry_failed,
    ).table


def run_sweep(
    spec: SweepSpec,
    *,
    scheduler: Any = None,
    workers: int | None = None,
    batch: int | None = None,
    output: str | Path | None = None,
    fresh: bool = False,
    logs: bool | None = None,
    use_folder: bool = True,
    on_start: Callable[[int, int, ClusterInfo | None], None] | None = None,
    on_rows: Callable[[list[dict[str, Any]]], None] | None = None,
    retry_failed: bool = False,
    host: str | None = None,
) -> SweepRun:
    """Run the variants of `spec` not yet finished in its folder (every one without a folder).

    on_start(total, already finished, cluster or None when serial) is called once the workers are ready;
    on_rows(rows) after each batch (the CLI's progress bar). KeyboardInterrupt: the finished batches are
    kept (and merged into results.parquet, marked incomplete) and the interrupt is raised again.
    retry_failed: run again the variants whose rows did not complete, too. host: the interface a local
    cluster listens on (default 127.0.0.1)."""
    from rbcli.sweeps import table as tables

    folder = _folder(spec, output) if use_folder else None
    total = spec.variant_count
    done: set[int] = set()
    logs = spec.logs if logs is None else logs
    job = sweep_job(spec, folder / "logs" if logs and folder is not None else None)
    if folder is not None:
        _claim(folder, spec, fresh, _fingerprint(spec, job))
        done = {v for v in tables.finished_variants(folder, retry_failed=retry_failed) if 0 <= v < total}
    pending = [(i, spec.variant_values(i)) for i in range(total) if i not in done]
    batch = batch or spec.batch
    collected: list[dict[str, Any]] = []
    counts = {"ran": 0, "failed": 0}

    def keep(rows: list[dict[str, Any]]) -> None:
        if folder is not None:
            tables.write_part(folder, rows)
        else:
            collected.extend(rows)
        counts["ran"] += len(rows)
        counts["failed"] += sum(1 for r in rows if r.get("status") != "completed")
        if on_rows is not None:
            on_rows(rows)

    cluster: ClusterInfo | None = None
    started = time.perf_counter()
    try:
        if scheduler == SERIAL:
            if pending:  # as each Dask worker is warmed before the timing starts
                warm_up(job, pending[0][1])
            if on_start is not None:
                on_start(total, len(done), None)
            started = time.perf_counter()
            _run_serial(job, pending, keep, batch)
        else:
            from rbcli.sweeps.dask_runner import run_on_dask

            def ready(info: ClusterInfo) -> None:
                nonlocal started
                if on_start is not None:
                    on_start(total, len(done), info)
                started = time.perf_counter()

            cluster = run_on_dask(
                job, pending, keep, scheduler=scheduler, workers=workers, batch=batch, on_ready=ready, host=host
            )
    except BaseException:
        if folder is not None:
            _merge(spec, folder)
        raise
    wall = time.perf_counter() - started - (cluster.shutdown_s if cluster is not None else 0.0)
    if folder is not None:
        results = _merge(spec, folder)
    else:
        rows = tables.rows_table(collected)
        results = tables.merge(spec, rows, complete=tables.unfinished_count(rows, total) == 0)
    unfinished = tables.unfinished_count(results, total)
    return SweepRun(
        table=results,
        output=folder,
        variants=total,
        resumed=len(done),
        ran=counts["ran"],
        failed=counts["failed"],
        wall_s=wall,
        cluster=cluster,
        complete=unfinished == 0,
        unfinished=unfinished,
        crashed=results.column("status").to_pylist().count(STATUS_CRASHED),
    )


def _run_serial(job: SweepJob, pending: list[tuple[int, tuple[Any, ...]]], keep: Callable, batch: int | None) -> None:
    """Every pending variant in this process, in order, through the same `run_batch` a Dask worker runs;
    one part per batch, sized as on one Dask slot (batches.Batcher)."""
    batcher = Batcher(pending, 1, fixed=batch)
    while group := batcher.next_group():
        rows = run_batch(job, group)
        batcher.measured(rows)
        keep(rows)


def sweep_job(spec: SweepSpec, log_dir: Path | None = None) -> SweepJob:
    """What every variant needs (execute.SweepJob), with the bytes of the mesh files the variants may
    load (meshes.py): the job a worker anywhere can run."""
    from rbcli.scene.yaml_located import parse_located_yaml
    from rbcli.sweeps.meshes import mesh_names, read_mesh_files

    scene_dir = str(Path(spec.scene_path).resolve().parent)
    scene_data = parse_located_yaml(spec.scene_text, spec.scene_path).value
    meshes = mesh_names(scene_data, ((axis.path, axis.values) for axis in spec.axes))
    return SweepJob(
        scene_data=scene_data,
        scene_text=spec.scene_text,
        scene_file=spec.scene_path,
        scene_dir=scene_dir,
        paths=tuple(axis.path for axis in spec.axes),
        frames=spec.frames,
        log_dir=None if log_dir is None else str(log_dir.resolve()),
        mesh_files=read_mesh_files(meshes, scene_dir),
        client_host=socket.gethostname(),
    )


def _folder(spec: SweepSpec, output: str | Path | None) -> Path:
    from rbcli.record.output_file import safe_file_stem

    if output is not None:
        return Path(output)
    if spec.output:
        return Path(spec.output)
    return DEFAULT_OUTPUT_DIR / safe_file_stem(spec.name)


def _fingerprint(spec: SweepSpec, job: SweepJob) -> str:
    """The sweep's fingerprint, and the mesh files' hashes when it has any: a folder whose rows came from
    other mesh bytes belongs to another sweep (the same as the spec's for a sweep without meshes)."""
    if not job.mesh_files:
        return spec.fingerprint
    meshes = "".join(f"\n{name} {digest}" for name, digest, _ in job.mesh_files)
    return hashlib.sha256((spec.fingerprint + meshes).encode()).hexdigest()


def _claim(folder: Path, spec: SweepSpec, fresh: bool, fingerprint: str) -> None:
    """Make `folder` this sweep's: refuse another sweep's results unless `fresh` (which removes them)."""
    from rbcli.sweeps.table import MANIFEST_FILE, PARTS_DIR, RESULTS_FILE

    manifest = folder / MANIFEST_FILE
    if fresh:
        for name in (PARTS_DIR, "logs"):
            shutil.rmtree(folder / name, ignore_errors=True)
        for name in (RESULTS_FILE, MANIFEST_FILE):
            (folder / name).unlink(missing_ok=True)
    elif manifest.is_file():
        try:
            owner = json.loads(manifest.read_text(encoding="utf-8")).get("fingerprint")
        except (OSError, ValueError):
            owner = None
        if owner != fingerprint:
            raise SweepOutputError(
                f"{folder} holds the results of another sweep (its sweep file, base scene or mesh files have "
                "changed since); "
                "use --fresh to discard them, or another --output folder"
            )
    elif (folder / PARTS_DIR).is_dir() and any((folder / PARTS_DIR).iterdir()):
        raise SweepOutputError(f"{folder}/{PARTS_DIR} holds parts of an unknown sweep; use --fresh or another --output")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        temporary = manifest.with_name(f".{MANIFEST_FILE}.{os.getpid()}.tmp")
        record = {"fingerprint": fingerprint, "name": spec.name, "variants": spec.variant_count}
        temporary.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        os.replace(temporary, manifest)
    except OSError as exc:
        raise SweepOutputError(f"cannot write to {folder}: {exc.strerror or exc}") from None


def _merge(spec: SweepSpec, folder: Path) -> pa.Table:
    from rbcli.sweeps import table as tables

    results = tables.read_parts(folder)
    merged = tables.merge(spec, results, complete=tables.unfinished_count(results, spec.variant_count) <= 0)
    tables.write_results(merged, folder / tables.RESULTS_FILE)
    return merged
