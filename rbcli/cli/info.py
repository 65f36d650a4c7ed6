"""`rbsim info FILE`: what a recording holds and how well the run kept its invariants.

Each invariant is labelled from the recorded scene's own force terms (api.conserved_invariants,
physics/conservation.py): "drift" for a quantity those terms keep constant (its change is the
integrator's error), "change" for one they change (momentum under gravity, energy under drag), which is
physics and not an error. `--json` prints the same as one JSON object for scripts.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from rbcli.cli import messages

if TYPE_CHECKING:
    from rbcli.record.read import RunInfo

DRIFT, CHANGE, UNCLASSIFIED = "drift", "change", "unclassified"
LEGEND = {
    DRIFT: "kept constant by the scene's forces: its change is the integrator's error",
    CHANGE: "changed by the scene's forces themselves (not an error)",
    UNCLASSIFIED: "the recorded scene could not be loaded, so this is not classified",
}


def info(
    file: Annotated[
        Path, typer.Argument(metavar="FILE", help="A recording (.mcap or .rrd) or a sweep's results (.parquet).")
    ],
    as_json: Annotated[
        bool, typer.Option("--json", help="Print one JSON object (for scripts) instead of text")
    ] = False,
) -> None:
    """Print scene, bodies, steps, duration, integrator, dt, status and each invariant's drift or change (a
    sweep's table: its axes, how many variants finished and how, metric ranges and the failed variants)."""
    from rbcli.record.read import recording_format, summarize

    if not file.is_file():
        raise messages.fail(f"recording not found: {file}", expected="a .mcap, .rrd or .parquet file")
    if file.suffix.lower() == ".parquet":
        _sweep_info(file, as_json)
        return

    def read(file: Path) -> tuple[RunInfo, dict[str, str], list[str], str]:
        fmt = recording_format(file)
        summary = summarize(file)
        return (summary, *invariant_kinds(file, fmt, summary))

    try:
        # rerun's .rrd reader aborts the process on some damaged files (a Rust panic): read those apart
        is_rrd = file.suffix.lower() == ".rrd"
        summary, kinds, terms, why = _in_child(read, file) if is_rrd else read(file)
    except Exception as exc:  # a corrupt or foreign file: say so, never a traceback
        raise messages.fail(f"cannot read {file}: {exc}") from None
    if as_json:
        typer.echo(json.dumps(info_json(summary, kinds, terms, why), indent=2))
        return
    typer.echo(info_text(summary, kinds, terms, why))


def _in_child(function, *args):  # noqa: ANN001, ANN002, ANN202
    """function(*args) in a forked child, its result (or exception) pickled back: a reader that aborts
    the process (rerun-sdk 0.41's .rrd reader panics in arrow on some damaged payloads, found by fuzzing)
    then costs the child, and the user gets one line. The child's stderr goes nowhere (the panic's
    backtrace); where fork does not exist, the function runs here."""
    import os
    import pickle
    import signal

    if not hasattr(os, "fork"):  # pragma: no cover - Windows
        return function(*args)
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: never returns
        code = 0
        try:
            os.close(read_end)
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, 2)
            try:
                payload = pickle.dumps((True, function(*args)))
            except Exception as exc:  # noqa: BLE001 - handed to the parent as it is
                payload = pickle.dumps((False, ValueError(messages.one_line(str(exc)) or type(exc).__name__)))
            with os.fdopen(write_end, "wb") as pipe:
                pipe.write(payload)
        except BaseException:  # noqa: BLE001
            code = 1
        finally:
            os._exit(code)
    os.close(write_end)
    with os.fdopen(read_end, "rb") as pipe:
        data = pipe.read()
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status) or not data:
        how = f"killed by {signal.Signals(os.WTERMSIG(status)).name}" if os.WIFSIGNALED(status) else "no result"
        raise ValueError(f"rerun's .rrd reader crashed on this file ({how}): a damaged recording?")
    ok, value = pickle.loads(data)
    if not ok:
        raise value
    return value


def invariant_kinds(file: Path, fmt: str, summary: RunInfo) -> tuple[dict[str, str], list[str], str]:
    """(invariant name -> DRIFT, CHANGE or UNCLASSIFIED; the scene's force terms; why unclassified, or "")
    from the scene the recording carries."""
    from rbcli.api import conserved_invariants, force_terms

    names = [d.name for d in summary.drifts]
    try:
        spec = _recorded_scene(file, fmt)
        kept = conserved_invariants(spec, names)
        terms = list(force_terms(spec))
    except Exception as exc:  # a scene that no longer loads (a mesh file moved): say so, label nothing
        return {name: UNCLASSIFIED for name in names}, [], messages.one_line(str(exc)) or type(exc).__name__
    return {name: DRIFT if kept[name] else CHANGE for name in names}, terms, ""


def _recorded_scene(file: Path, fmt: str):  # noqa: ANN202 - a SceneSpec
    """The scene stored in the recording, loaded (relative mesh paths from the original scene's folder
    when it still exists, else from the recording's)."""
    from rbcli.scene.load import load_scene_text

    if fmt == "mcap":
        from rbcli.record.mcap_layout import METADATA_RUN
        from rbcli.record.mcap_read import read_mcap_contents
        from rbcli.record.mcap_recovery import read_mcap_prefix

        try:
            contents = read_mcap_contents(file)
            text, meta = contents.scene_text, contents.metadata.get(METADATA_RUN, {})
        except ValueError:  # cut short: read front to back
            prefix = read_mcap_prefix(file)
            text, meta = prefix.scene_text, prefix.metadata.get(METADATA_RUN, {})
    else:
        from rbcli.record.read import read_rrd

        run = read_rrd(file, bodies=False)
        text, meta = run.scene_text, run.metadata
    if not text:
        raise ValueError("the recording holds no scene")
    scene_path = Path(meta.get("scene_path") or file)
    base = scene_path.parent if scene_path.parent.is_dir() else file.parent
    return load_scene_text(text, file=str(scene_path), base_dir=base)


def info_text(summary: RunInfo, kinds: dict[str, str], terms: list[str], why: str) -> str:
    """The run's header (record.read.RunInfo) and the invariants, each labelled drift or change."""
    lines = [str(dataclasses.replace(summary, drifts=[]))]
    if summary.drifts:
        width = max(len(d.name) for d in summary.drifts)
        lines += [
            "",
            f"{'invariant':<{width}}  {'kind':<6}  {'f(0)':>14}  {'max|f-f(0)|':>12}  {'relative':>10}",
        ]
        for d in summary.drifts:
            rel = f"{d.relative:10.3e}" if d.relative is not None else f"{'-':>10}"
            extra = f"  ({d.nonfinite} non-finite)" if d.nonfinite else ""
            kind = kinds.get(d.name, UNCLASSIFIED)
            label = kind if kind != UNCLASSIFIED else "?"
            lines.append(f"{d.name:<{width}}  {label:<6}  {d.initial:14.6e}  {d.max_abs:12.3e}  {rel}{extra}")
        known = UNCLASSIFIED not in kinds.values()
        lines += ["", f"force terms: {(', '.join(terms) or 'none') if known else 'unknown'}"]
        lines += [f"{k}: {LEGEND[k]}" for k in (DRIFT, CHANGE) if k in kinds.values()]
        if UNCLASSIFIED in kinds.values():
            lines.append(f"?: {LEGEND[UNCLASSIFIED]} ({why})")
    return "\n".join(lines)


def info_json(summary: RunInfo, kinds: dict[str, str], terms: list[str], why: str) -> dict[str, Any]:
    """The summary as JSON-ready data: non-finite numbers as null (JSON has no NaN)."""
    data: dict[str, Any] = {
        "file": str(summary.path),
        "format": summary.format,
        "scene": summary.scene_name,
        "bodies": list(summary.body_names),
        "integrator": summary.integrator,
        "dt": _number(summary.dt),
        "duration": _number(summary.duration),
        "record_every": summary.record_every,
        "frames": summary.frames,
        "steps": summary.steps if summary.steps >= 0 else None,
        "t_end": _number(summary.t_end),
        "status": summary.status,
        "message": summary.message,
        "rbsim_version": summary.rbsim_version,
        "force_terms": terms,
        "invariants": [
            {
                "name": d.name,
                "kind": kinds.get(d.name, UNCLASSIFIED),
                "initial": _number(d.initial),
                "final": _number(d.final),
                "max_abs_change": _number(d.max_abs),
                "relative": _number(d.relative),
                "nonfinite": d.nonfinite,
            }
            for d in summary.drifts
        ],
        "kinds": {k: v for k, v in LEGEND.items() if k in kinds.values()},
    }
    if why:
        data["unclassified_because"] = why
    return data


def _number(value: float | None) -> float | None:
    return float(value) if value is not None and math.isfinite(value) else None


def _sweep_info(file: Path, as_json: bool) -> None:
    from rbcli.sweeps.report import describe, failures, read_results, status_counts

    try:
        table = read_results(file)
        if as_json:
            counts = status_counts(table)
            data = {
                "file": str(file),
                "format": "sweep",
                "variants": table.num_rows,
                "status": dict(counts.most_common()),
                "columns": table.column_names,
                "failures": failures(table),
            }
            typer.echo(json.dumps(data, indent=2))
            return
        text = describe(table, file)
    except Exception as exc:  # a corrupt or foreign file: say so, never a traceback
        raise messages.fail(f"cannot read {file} as a sweep's results: {exc}") from None
    typer.echo(text)
