"""One variant, start to end: its scene text, the scene loader, a `Simulation` run, and a row of metrics.

This is what a Dask worker runs (`run_batch`), and what the serial path runs in the client's process;
nothing here imports Dask. A variant that the loader rejects, that diverges or that raises gives a row
too, with its status and message: a sweep never loses the other variants to one bad one.

Kernels: numba keeps each compiled kernel in the worker's process once loaded (from the disk cache, or
compiled on first use), keyed by the integrator and the force types present; every later variant of the
same shape on that worker reuses it, so only the first variant a worker runs pays the load.
"""

from __future__ import annotations

import contextlib
import functools
import os
import re
import socket
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from rbcli.sweeps.meshes import MeshFile, local_scene_dir
from rbcli.sweeps.paths import ScenePath, variant_text

# Row statuses: a run's own ("completed", "diverged"), a variant the scene loader rejects, and any other
# exception while building or running it; on a cluster, a variant that took its worker down on every try
# (out of memory, a crash: its own fault after a bounded number of tries, dask_runner.py) and one whose
# task the cluster lost too often for its own reasons (cancelled, data lost with a worker): no result yet,
# so resuming runs it again.
STATUS_COMPLETED = "completed"
STATUS_DIVERGED = "diverged"
STATUS_INVALID = "invalid"
STATUS_ERROR = "error"
STATUS_CRASHED = "crashed"
STATUS_LOST = "lost"
# The message of a row that an older rbsim recorded as "error" when the cluster lost its task: resuming
# treats it as lost, not as the variant's own failure.
LEGACY_LOST_MESSAGE = "the task failed on the cluster: "
# The row of a variant: (column, type) in table order; "vectors" is a list per body of 3 or 4 floats.
RESULT_COLUMNS = (
    ("variant", "int64"),
    ("status", "string"),
    ("message", "string"),
    ("steps", "int64"),
    ("t_end", "float64"),
    ("dt", "float64"),
    ("integrator", "string"),
    ("body_count", "int64"),
    ("energy_initial", "float64"),
    ("energy_final", "float64"),
    ("energy_drift", "float64"),
    ("momentum_drift", "float64"),
    ("angular_momentum_drift", "float64"),
    ("quaternion_norm_defect_max", "float64"),
    ("rotation_error_max", "float64"),
    ("rotation_error_final", "float64"),
    ("position_error_max", "float64"),
    ("position_error_final", "float64"),
    ("x_final", "vectors"),
    ("q_final", "vectors"),
    ("v_final", "vectors"),
    ("omega_final", "vectors"),
    ("L_final", "vectors"),
    ("wall_s", "float64"),
    ("log", "string"),
)
# The invariants a variant's metrics need; logs add the scene's own streams.
METRIC_STREAMS = ("bodies", "invariants")


@dataclass(frozen=True)
class SweepJob:
    """What every variant of a sweep needs, sent to each worker once.

    scene_data: the base scene's parsed YAML, scene_text its text; scene_file and scene_dir: where it came
    from (messages, the recorded scene path; mesh files resolve against scene_dir).
    paths: each axis's scene path. frames: recorded frames per variant (None: the scene's cadence).
    log_dir: where each variant writes variant-<n>.mcap (None: no logs), as seen by the workers.
    mesh_files: the bytes of every mesh file a variant may load (meshes.py), so a worker that does not
    see scene_dir loads the same bytes from a folder of its own. client_host: the machine the sweep runs
    on; a log written on another machine is named `host:path` in its row.
    """

    scene_data: dict[str, Any]
    scene_text: str
    scene_file: str
    scene_dir: str
    paths: tuple[ScenePath, ...]
    frames: int | None = 101
    log_dir: str | None = None
    mesh_files: tuple[MeshFile, ...] = ()
    client_host: str = ""


def lost_to_the_cluster(status: str | None, message: str | None) -> bool:
    """Whether a row is a failure of the cluster rather than the variant's own (resuming retries it)."""
    return status == STATUS_LOST or (status == STATUS_ERROR and (message or "").startswith(LEGACY_LOST_MESSAGE))


def runtime_versions() -> tuple[str, str]:
    """(rbsim, numba) versions of this process: a worker must match the client's, since a row is bitwise
    the same only from the same code compiled by the same numba."""
    import numba

    from rbcli._version import __version__

    return __version__, str(numba.__version__)


def run_batch(job: SweepJob, variants: list[tuple[int, tuple[Any, ...]]]) -> list[dict[str, Any]]:
    """The rows of a batch of (variant number, axis values), in order. The Dask task."""
    job = _on_this_machine(job)
    return [run_variant(job, index, values) for index, values in variants]


def _on_this_machine(job: SweepJob) -> SweepJob:
    """The job with scene_dir where this process finds its mesh files (meshes.local_scene_dir)."""
    scene_dir = local_scene_dir(job.scene_dir, job.mesh_files)
    return job if scene_dir == job.scene_dir else replace(job, scene_dir=scene_dir)


def warm_up(job: SweepJob, values: tuple[Any, ...]) -> float:
    """Load (or compile) every kernel a variant needs in this process (the steps', the recorder's, the
    exact solution's) by running it for two steps without a log; returns the seconds it took (reported
    apart from the sweep, as the cluster's start-up is)."""
    started = time.perf_counter()
    with contextlib.suppress(Exception):  # the variant's own row will say what is wrong with it
        text = variant_text(job.scene_data, tuple(zip(job.paths, values, strict=True)))
        _run(replace(_on_this_machine(job), log_dir=None), -1, text, steps=2)
    return time.perf_counter() - started


def run_variant(job: SweepJob, index: int, values: tuple[Any, ...]) -> dict[str, Any]:
    """Build, load and run one variant; its row (see `table.RESULT_SCHEMA` for the columns)."""
    from rbcli.scene.spec import SceneError

    started = time.perf_counter()
    row: dict[str, Any] = {"variant": index, "status": STATUS_ERROR, "message": ""}
    text = ""
    try:
        text = variant_text(job.scene_data, tuple(zip(job.paths, values, strict=True)))
        row.update(_run(job, index, text))
    except SceneError as exc:
        errors = [str(issue) for issue in exc.issues if issue.severity == "error"]
        row.update(status=STATUS_INVALID, message="; ".join(errors) or str(exc))
    except Exception as exc:  # noqa: BLE001 - any failure is this variant's row, not the sweep's end
        row.update(status=STATUS_ERROR, message=f"{type(exc).__name__}: {exc}")
    if row["message"] and job.scene_file in row["message"]:
        row["message"] = _relocated(row["message"], job, text)
    if row.get("log") and job.client_host and socket.gethostname() != job.client_host:
        row["log"] = f"{socket.gethostname()}:{row['log']}"  # on this worker's disk, not the client's
    row["wall_s"] = time.perf_counter() - started
    return row


def _relocated(message: str, job: SweepJob, text: str) -> str:
    """`scene.yaml:44:3` in a message about the variant's text (its YAML as the sweep wrote it) turned into
    the place of the same scene value in the base scene file, where the user can find it."""
    from rbcli.scene.yaml_located import parse_located_yaml

    try:
        variant = parse_located_yaml(text, job.scene_file)
    except Exception:  # noqa: BLE001 - a message is better unmapped than lost
        return message
    at: dict[tuple[int, int], tuple[tuple[str | int, ...], bool]] = {}
    for is_key, table in ((False, variant.value_locations), (True, variant.key_locations)):
        for path, loc in table.items():
            known = at.get((loc.line, loc.column))
            if known is None or len(path) < len(known[0]):  # the outermost value starting there: the entry
                at[(loc.line, loc.column)] = (path, is_key)
    base = _base_document(job.scene_text, job.scene_file)

    def base_place(match: re.Match[str]) -> str:
        found = at.get((int(match[1]), int(match[2])))
        return match[0] if found is None else str(base.locate(found[0], key=found[1]))

    return re.sub(re.escape(job.scene_file) + r":(\d+):(\d+)", base_place, message)


@functools.lru_cache(maxsize=4)
def _base_document(text: str, file: str) -> Any:
    from rbcli.scene.yaml_located import parse_located_yaml

    return parse_located_yaml(text, file)


def _run(job: SweepJob, index: int, text: str, steps: int | None = None) -> dict[str, Any]:
    """The variant's row (steps: run only this many, the warm-up's)."""
    from rbcli.analysis.errors import (
        admits_exact_solution,
        conserved_quantities,
        exact_reference,
        invariant_drifts,
        run_errors,
    )
    from rbcli.record.memory_sink import SinkMemory
    from rbcli.runner.simulation import Simulation
    from rbcli.scene.compile import compile_scene
    from rbcli.scene.load import load_scene_text

    spec = load_scene_text(text, job.scene_file, job.scene_dir)
    compiled = compile_scene(spec, duration=None if steps is None else steps * spec.simulation.dt)
    settings = compiled.settings
    every = settings.record_every if job.frames is None else max(1, settings.steps // (job.frames - 1))
    streams = METRIC_STREAMS if job.log_dir is None else tuple(dict.fromkeys((*settings.streams, *METRIC_STREAMS)))
    compiled = replace(compiled, settings=replace(settings, record_every=every, streams=streams))
    sim = Simulation(compiled)
    memory = SinkMemory()
    with _log_sink(job, index, compiled.settings.compression) as (sinks, log):
        summary = sim.run(sinks=[memory, *sinks], threaded=False)
    if summary.status == "interrupted":  # Ctrl-C in a serial sweep: this variant did not finish
        raise KeyboardInterrupt
    traj = memory.trajectory()
    inv = traj.invariants
    energy, momentum, angular = invariant_drifts(traj, conserved_quantities(compiled))
    # the final state as the recording holds it (the run always records its last state): the recorder's
    # compiled outputs give v = P / M and omega = R I^-1 R^T L rounded as the log's frames are, 1-2 ulp from
    # `Simulation.state`'s numpy expressions, and a row must read the same as its recording
    final = {name: getattr(traj, name)[-1] for name in ("x", "q", "v", "omega", "L")}
    row: dict[str, Any] = {
        "status": summary.status,
        "message": summary.message,
        "steps": int(summary.steps),
        "t_end": float(summary.t_end),
        "dt": float(compiled.settings.dt),
        "integrator": compiled.settings.integrator,
        "body_count": int(compiled.model.body_count),
        "energy_initial": float(inv["energy_total"][0]),
        "energy_final": float(inv["energy_total"][-1]),
        "energy_drift": energy,
        "momentum_drift": momentum,
        "angular_momentum_drift": angular,
        "quaternion_norm_defect_max": float(np.max(inv["quaternion_norm_defect"])),
        "x_final": final["x"].tolist(),
        "q_final": final["q"].tolist(),
        "v_final": final["v"].tolist(),
        "omega_final": final["omega"].tolist(),
        "L_final": final["L"].tolist(),
        "log": log,
    }
    if admits_exact_solution(compiled) and traj.t.size:
        rot_max, pos_max, rot_final, pos_final = run_errors(traj, exact_reference(compiled, traj.t))
        row.update(
            rotation_error_max=rot_max,
            position_error_max=pos_max,
            rotation_error_final=rot_final,
            position_error_final=pos_final,
        )
    return row


@contextlib.contextmanager
def _log_sink(job: SweepJob, index: int, compression: str):  # noqa: ANN202 - a context of (sinks, path)
    """The variant's log as an extra sink (none without a log folder), written as a partial file and
    renamed into place when the run ends (record/output_file.py), so a log is complete or absent."""
    if job.log_dir is None:
        yield [], None
        return
    from rbcli.record.output_file import OutputFile, partial_path
    from rbcli.record.sinks import open_file_sink

    target = Path(job.log_dir) / f"variant-{index:06d}.mcap"
    with contextlib.suppress(FileNotFoundError):  # a lost worker's half-written try of this variant
        os.unlink(partial_path(os.path.realpath(target)))
    out = OutputFile(target)
    partial = out.open()
    sink = None
    try:
        sink = open_file_sink(partial, compression=compression)
        yield [sink], str(target)
    except BaseException:
        out.abandon(keep=False)
        raise
    out.commit()
