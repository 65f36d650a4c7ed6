"""A results table in words: what `rbsim info results.parquet` prints and `rbsim sweep` ends with."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc  # a submodule: `import pyarrow` alone does not load it
import pyarrow.parquet as pq

from rbcli.sweeps.table import RESULT_SCHEMA, sweep_metadata

# Metrics shown as min / median / max over the completed variants, when present.
SUMMARY_METRICS = (
    ("energy_drift", "energy drift"),
    ("momentum_drift", "momentum drift"),
    ("angular_momentum_drift", "angular momentum drift"),
    ("rotation_error_max", "rotation error max [rad]"),
    ("position_error_max", "position error max [m]"),
    ("wall_s", "wall time per variant [s]"),
)
SHOWN_FAILURES = 10


def read_results(path: str | Path) -> pa.Table:
    """A results table from its Parquet file."""
    return pq.read_table(path)


def status_counts(table: pa.Table) -> Counter[str]:
    return Counter(str(s) for s in table.column("status").to_pylist())


def failures(table: pa.Table, limit: int = SHOWN_FAILURES) -> list[str]:
    """`variant n (params): status: message` for the first failed variants."""
    axes = [a["column"] for a in sweep_metadata(table).get("axes", []) if a.get("column") in table.column_names]
    lines = []
    for row in table.filter(pc.not_equal(table.column("status"), "completed")).slice(0, limit).to_pylist():
        params = ", ".join(f"{name} = {_short(row[name])}" for name in axes)
        lines.append(f"variant {row['variant']} ({params}): {row['status']}: {row['message']}")
    return lines


def describe(table: pa.Table, path: str | Path | None = None) -> str:
    """Several lines: the sweep, its axes, how many variants finished and how, metric ranges, failures."""
    meta = sweep_metadata(table)
    if "status" not in table.column_names or "variant" not in table.column_names:
        raise ValueError("not an rbsim sweep table (no variant and status columns)")
    total = int(meta.get("variants", table.num_rows))
    lines = [
        f"sweep:      {meta.get('name', '?')}" + (f" ({path})" if path else ""),
        f"scene:      {meta.get('scene', '?')}",
        f"variants:   {table.num_rows} of {total} finished"
        + ("" if table.num_rows >= total else " (incomplete: resume)"),
    ]
    random = any(a.get("kind") == "random" for a in meta.get("axes", []))
    if random:
        lines.append(f"samples:    {meta.get('samples')} (seed {meta.get('seed')})")
    for axis in meta.get("axes", []):
        column = axis.get("column")
        if column in table.column_names:
            lines.append(f"axis:       {column} ({axis.get('kind')}): {_axis_values(table.column(column))}")
    counts = status_counts(table)
    lines.append("status:     " + ", ".join(f"{n} {status}" for status, n in counts.most_common()))
    completed = table.filter(pc.equal(table.column("status"), "completed"))
    width = max(len(label) for _, label in SUMMARY_METRICS) + 1
    metrics = []
    for column, label in SUMMARY_METRICS:
        values = sorted(v for v in completed.column(column).to_pylist() if v is not None)
        if values:
            median = values[len(values) // 2]
            metrics.append(f"  {label + ':':<{width}} {values[0]:.3g}, {median:.3g}, {values[-1]:.3g}")
    if metrics:
        lines += ["completed variants (min, median, max):", *metrics]
    extra = [c for c in table.column_names if c not in RESULT_SCHEMA.names and c not in _axis_columns(meta)]
    if extra:
        lines.append("other:      " + ", ".join(extra))
    shown = failures(table)
    if shown:
        failed = sum(n for status, n in counts.items() if status != "completed")
        lines.append(
            f"failed:     {failed} variant{'s' * (failed != 1)}" + (" (first shown)" if failed > len(shown) else "")
        )
        lines.extend(f"  {line}" for line in shown)
    return "\n".join(lines)


def _axis_columns(meta: dict[str, Any]) -> set[str]:
    return {str(a.get("column")) for a in meta.get("axes", [])}


def _axis_values(column: pa.ChunkedArray) -> str:
    values = column.to_pylist()
    distinct: list[Any] = []
    for v in values:
        if v not in distinct:
            distinct.append(v)
        if len(distinct) > 6:
            break
    numbers = [v for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
    if len(distinct) > 6 and len(numbers) == len(values):
        return f"{len(set(values))} values from {min(numbers):.6g} to {max(numbers):.6g}"
    if len(distinct) > 6:
        return f"{len(values)} values, e.g. " + ", ".join(_short(v) for v in distinct[:3])
    return ", ".join(_short(v) for v in distinct)


def _short(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}" if math.isfinite(value) else str(value)
    if isinstance(value, list):
        return "[" + ", ".join(_short(v) for v in value) + "]"
    text = str(value)
    return text if len(text) <= 40 else text[:37] + "..."
