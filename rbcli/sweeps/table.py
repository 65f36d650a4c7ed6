"""The results table: one row per variant, its parameters beside its metrics, in Parquet (pyarrow).

Columns, in order:
- `variant` (int64): the variant's number (spec.py fixes the numbering);
- one column per axis, named by the axis (its `name`, else its path), holding the value set there;
- `status` ("completed", "diverged", "invalid": the scene loader rejected the combination, "error": it
  raised), `message`;
- `steps`, `t_end` [s], `dt` [s], `integrator`, `body_count`;
- `energy_initial`, `energy_final` [J]; `energy_drift`, `momentum_drift`, `angular_momentum_drift`
  (relative, max over the recorded frames; null where the scene does not conserve the quantity, as
  `rbsim study`); `quaternion_norm_defect_max`;
- `rotation_error_max`, `rotation_error_final` [rad], `position_error_max`, `position_error_final` [m]
  against the exact solution (null where the scene has none);
- `x_final`, `q_final` (w, x, y, z), `v_final`, `omega_final`, `L_final`: the final state of every body
  in the user's frames (body_count lists of 3 or 4): the run's last recorded frame, bitwise its log's;
- `wall_s` [s]: the variant's wall time (load, run, metrics), the one column that differs between runs;
- `log`: the variant's recording, when logs are on.

The sweep itself (file, scene and its sha256, seed, samples, axes, fingerprint) is in the schema's
metadata under `rbsim_sweep` (JSON).

Parts: the client writes each finished batch as `parts/part-<first>-<n>-<token>.parquet`, written to a
temporary name and renamed into place, so a part is complete or absent whatever stops the sweep. The
finished variants are those with a row in the parts that is the variant's own result: a row "lost" to
the cluster (or an older rbsim's "error" row saying the cluster failed the task) is not, and resuming
runs that variant again; with `retry_failed` only "completed" rows count. A variant can so have several
rows (also after a worker was lost while its batch's part was being written); `merge` keeps one: the
best (completed, then the variant's own failures, then lost), and of equals the last written.
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from rbcli.sweeps.execute import RESULT_COLUMNS, STATUS_COMPLETED, lost_to_the_cluster
from rbcli.sweeps.spec import SweepSpec

RESULTS_FILE = "results.parquet"
PARTS_DIR = "parts"
MANIFEST_FILE = "sweep.json"
METADATA_KEY = b"rbsim_sweep"

_TYPES = {
    "int64": pa.int64(),
    "float64": pa.float64(),
    "string": pa.string(),
    "vectors": pa.list_(pa.list_(pa.float64())),
}
RESULT_SCHEMA = pa.schema([(name, _TYPES[kind]) for name, kind in RESULT_COLUMNS])
# Columns whose values differ from run to run of the same variant (everything else is bitwise the same).
VOLATILE_COLUMNS = ("wall_s",)


def rows_table(rows: Sequence[dict[str, Any]]) -> pa.Table:
    """Result rows (dicts from execute.run_variant) as a table of RESULT_SCHEMA; missing keys are null."""
    columns = {f.name: [row.get(f.name) for row in rows] for f in RESULT_SCHEMA}
    return pa.table(columns, schema=RESULT_SCHEMA)


def parameter_table(spec: SweepSpec, variants: Iterable[int]) -> pa.Table:
    """The axis values of the given variants, one column per axis. A column whose values pyarrow cannot
    give one type (numbers beside strings, say) holds each value as JSON text."""
    indices = list(variants)
    values = [spec.variant_values(i) for i in indices]
    columns: dict[str, pa.Array] = {"variant": pa.array(indices, pa.int64())}
    for k, axis in enumerate(spec.axes):
        column = [v[k] for v in values]
        try:
            columns[axis.column] = pa.array(column)
        except (pa.ArrowInvalid, pa.ArrowTypeError):
            columns[axis.column] = pa.array([json.dumps(v) for v in column], pa.string())
    return pa.table(columns)


def write_part(folder: Path, rows: Sequence[dict[str, Any]]) -> Path:
    """One finished batch as a part file, renamed into place once complete."""
    parts = folder / PARTS_DIR
    parts.mkdir(parents=True, exist_ok=True)
    first = min(int(row["variant"]) for row in rows)
    target = parts / f"part-{first:07d}-{len(rows)}-{uuid.uuid4().hex[:8]}.parquet"
    _write_atomic(rows_table(rows), target)
    return target


def read_parts(folder: Path) -> pa.Table:
    """Every row in the folder's parts, in the order the parts were written (may hold a variant more than
    once, see the docstring)."""
    files = list((folder / PARTS_DIR).glob("part-*.parquet")) if (folder / PARTS_DIR).is_dir() else []
    files.sort(key=lambda f: (f.stat().st_mtime_ns, f.name))  # a retried variant's later row comes later
    tables = [pq.read_table(f, schema=RESULT_SCHEMA) for f in files]
    return pa.concat_tables(tables) if tables else RESULT_SCHEMA.empty_table()


def row_rank(status: str | None, message: str | None) -> int:
    """0 completed, 1 the variant's own failure (diverged, invalid, error, crashed), 2 lost to the cluster."""
    if status == STATUS_COMPLETED:
        return 0
    return 2 if lost_to_the_cluster(status, message) else 1


def finished_variants(folder: Path, *, retry_failed: bool = False) -> set[int]:
    """The variants that have their own result in the folder's parts (any row but a lost one; with
    `retry_failed`, a completed row): resuming skips them."""
    rows = read_parts(folder).select(["variant", "status", "message"]).to_pylist()
    worst = 0 if retry_failed else 1
    return {int(r["variant"]) for r in rows if row_rank(r["status"], r["message"]) <= worst}


def unfinished_count(table: pa.Table, variants: int) -> int:
    """Of variants 0 .. variants - 1, those without their own result in a table of rows (parts or merged):
    no row, or only rows lost to the cluster."""
    rows = table.select(["variant", "status", "message"]).to_pylist()
    own = {int(r["variant"]) for r in rows if row_rank(r["status"], r["message"]) < 2}
    return variants - len(own & set(range(variants)))


def merge(spec: SweepSpec, results: pa.Table, *, complete: bool) -> pa.Table:
    """Parameters joined to results, one row per variant (the best, of equals the last: see the module
    docstring), in variant order; the sweep in the metadata."""
    variants = results.column("variant").to_pylist()
    ranks = [row_rank(s, m) for s, m in zip(results.column("status").to_pylist(),
                                            results.column("message").to_pylist(), strict=True)]  # fmt: skip
    chosen: dict[int, int] = {}
    for position, variant in enumerate(variants):
        held = chosen.get(int(variant))
        if held is None or ranks[position] <= ranks[held]:
            chosen[int(variant)] = position
    order = sorted(chosen)
    results = results.take(pa.array([chosen[v] for v in order], pa.int64()))
    params = parameter_table(spec, order)
    table = params
    for name in RESULT_SCHEMA.names[1:]:
        table = table.append_column(RESULT_SCHEMA.field(name), results.column(name))
    meta = dict(spec.metadata(), complete=complete, finished=len(order))
    return table.replace_schema_metadata({METADATA_KEY: json.dumps(meta).encode()})


def write_results(table: pa.Table, target: Path) -> None:
    """The merged table as `target`, renamed into place once complete."""
    _write_atomic(table, target)


def sweep_metadata(table_or_path: pa.Table | str | Path) -> dict[str, Any]:
    """The `rbsim_sweep` metadata of a results table (or file); {} when it has none."""
    schema = table_or_path.schema if isinstance(table_or_path, pa.Table) else pq.read_schema(table_or_path)
    raw = (schema.metadata or {}).get(METADATA_KEY)
    return json.loads(raw) if raw else {}


def _write_atomic(table: pa.Table, target: Path) -> None:
    temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        pq.write_table(table, temporary)
        with open(temporary, "rb+") as handle:
            os.fsync(handle.fileno())  # the data before the name: after a crash the part is whole or absent
        os.replace(temporary, target)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
