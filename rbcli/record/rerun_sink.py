"""Rerun recording: an .rrd streamed to disk, laid out for the Rerun viewer.

Entities (timelines `time`, a duration [s], and `step`, a sequence):

    bodies/<name>              Transform3D per recorded step: translation = centre of mass, rotation
    bodies/<name>/particles    static Points3D in the body's frame, so the cloud follows the body
    trajectories               static LineStrips3D of the centre-of-mass paths, written at close
    invariants/<name>          Scalars per recorded step
    particles                  Points3D of every particle in the world frame (only with that stream)
    scene                      static TextDocument: the scene YAML
    run, summary               static TextDocuments (markdown) with the run parameters and the ending

Run parameters are also recording properties (`rbsim`, `rbsim.summary`), and the default blueprint
shows the 3D view beside one time-series plot per invariant family.

Per-step data goes out with `send_columns`, one call per entity per flush. Rerun's cost is mostly per
call (tens of microseconds), so the sink gathers blocks until `flush_frames` frames or `flush_bytes`
of input are buffered: memory stays bounded and the file grows as the run goes.

This is the only module that imports rerun; the reader for the files it writes is here too
(`read_rrd_file`), and `record.read` wraps it.
"""

from __future__ import annotations

import uuid
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa  # a rerun-sdk dependency: columns are built as arrow arrays straight from numpy
import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import Chunk

from rbcli.record.frame import FrameBlock, RunHeader, RunSummary

APPLICATION_ID = "rbsim"
TIMELINE_TIME = "time"
TIMELINE_STEP = "step"

# Distinct, colour-blind-friendly body colours (Okabe-Ito), cycled by body index.
PALETTE = np.array(
    [[0, 114, 178], [230, 159, 0], [0, 158, 115], [204, 121, 167], [86, 180, 233], [213, 94, 0], [240, 228, 66]],
    dtype=np.uint8,
)


def body_entity(name: str) -> str:
    """The entity path of a body (its name escaped as one path part)."""
    return f"bodies/{rr.escape_entity_path_part(name)}"


def invariant_family(name: str) -> str:
    """Invariants plotted together: the name without its last `_part` (energy_kinetic -> energy)."""
    return name.rsplit("_", 1)[0] if "_" in name else name


def particle_display_radius(offsets: np.ndarray, fallback: float) -> float:
    """A radius [m] that makes a cloud read as a solid: half the median nearest-neighbour spacing.

    The run header carries no particle radius, so this is a display guess; distances use at most 512
    particles against all others, so it stays cheap for big clouds.
    """
    pts = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 2:
        return fallback
    probe = pts[np.linspace(0, len(pts) - 1, min(len(pts), 512)).astype(int)]
    d2 = ((probe[:, None, :] - pts[None, :, :]) ** 2).sum(axis=-1)
    d2[d2 == 0.0] = np.inf  # the probe itself (and exact duplicates)
    nearest = np.sqrt(d2.min(axis=1))
    nearest = nearest[np.isfinite(nearest)]
    return float(0.5 * np.median(nearest)) if nearest.size else fallback


def particle_display_radii(clouds: Sequence[np.ndarray], fallback: float) -> np.ndarray:
    """`particle_display_radius` of every cloud; clouds of equal size (<= 512 particles) are done together,
    a few at a time, as one (B, n, n) distance computation instead of B Python-level calls."""
    clouds = [np.asarray(c, dtype=np.float64).reshape(-1, 3) for c in clouds]
    radii = np.full(len(clouds), float(fallback))
    by_size: dict[int, list[int]] = {}
    for i, pts in enumerate(clouds):
        if 2 <= len(pts) <= 512:
            by_size.setdefault(len(pts), []).append(i)
        elif len(pts) > 512:
            radii[i] = particle_display_radius(pts, fallback)
    for size, members in by_size.items():
        per_batch = max(1, (8 << 20) // (8 * size * size))  # ~8 MB of distances at a time
        for start in range(0, len(members), per_batch):
            idx = members[start : start + per_batch]
            pts = np.stack([clouds[i] for i in idx])  # (B, n, 3)
            d2 = ((pts[:, :, None, :] - pts[:, None, :, :]) ** 2).sum(axis=-1)
            d2[d2 == 0.0] = np.inf  # each point itself (and exact duplicates)
            nearest = np.sqrt(d2.min(axis=2))  # (B, n)
            finite = np.isfinite(nearest)
            for row, i in enumerate(idx):
                values = nearest[row][finite[row]]
                radii[i] = float(0.5 * np.median(values)) if values.size else fallback
    return radii


class _ArrowBatch:
    """A prebuilt arrow array as a `rr.ComponentBatchLike` (so a column can be a zero-copy slice)."""

    def __init__(self, array: Any) -> None:
        self._array = array

    def as_arrow_array(self) -> Any:
        return self._array


def _rgba32(rgb: np.ndarray) -> np.ndarray:
    """Opaque RGB colours (..., 3) uint8 as Rerun's packed 0xRRGGBBAA uint32 (...)."""
    c = np.asarray(rgb, dtype=np.uint32)
    return (c[..., 0] << 24) | (c[..., 1] << 16) | (c[..., 2] << 8) | np.uint32(0xFF)


def _markdown_table(rows: dict[str, str]) -> str:
    lines = ["| key | value |", "|---|---|"]
    lines += [f"| {k} | {str(v).replace('|', '/')} |" for k, v in rows.items()]
    return "\n".join(lines) + "\n"


def run_properties(header: RunHeader) -> dict[str, str]:
    """Run parameters as recording properties; Rerun stores quaternions as xyzw."""
    return {**header.parameters(), "quaternion_order": "xyzw in Rerun (rbsim arrays are wxyz)"}


def default_blueprint(invariant_names: Sequence[str]) -> rrb.Blueprint:
    """The 3D view beside the invariant plots (one plot per family: energies, momentum, ...)."""
    families: dict[str, list[str]] = {}
    for name in invariant_names:
        families.setdefault(invariant_family(name), []).append(f"invariants/{name}")
    plots = [rrb.TimeSeriesView(name=fam, origin="invariants", contents=paths) for fam, paths in families.items()]
    view3d = rrb.Spatial3DView(name="bodies", origin="/", contents=["bodies/**", "trajectories", "particles"])
    texts = rrb.Tabs(rrb.TextDocumentView(origin="scene", name="scene"), rrb.TextDocumentView(origin="run", name="run"))
    right = rrb.Vertical(*plots, texts) if plots else texts
    return rrb.Blueprint(rrb.Horizontal(view3d, right, column_shares=[3, 2]), collapse_panels=False)


class SinkRerun:
    """Records a run to an .rrd file (see the module docstring for the layout).

    flush_frames / flush_bytes: how many frames (or bytes of x and q input) to gather before sending.
    trajectory_points: at most this many points per body path (older points are thinned by 2 to fit).
    """

    def __init__(
        self,
        path: str | Path,
        *,
        flush_frames: int = 1024,
        flush_bytes: int = 32 * 1024 * 1024,
        trajectory_points: int = 4096,
    ) -> None:
        self.path = Path(path)
        self._flush_frames, self._flush_bytes = flush_frames, flush_bytes
        self._trajectory_points = trajectory_points
        self._rec: rr.RecordingStream | None = None
        self._closed = False
        self.frames_written = 0

    def open(self, header: RunHeader) -> None:
        self._header = header
        self._bodies = [body_entity(n) for n in header.body_names]
        # gathered per block, only what is sent: t, step, x and q as float32 (N, k, 3|4) body-major,
        # invariants, particle positions (the block itself is not kept: v, omega, P, L are not sent)
        self._pending: list[dict[str, Any]] = []
        self._pending_bytes = 0
        self._path_points: list[np.ndarray] = []  # (k, N, 3) float32 kept centre-of-mass samples
        self._path_stride, self._path_seen = 1, 0
        self._clouds_logged = False
        # send_properties=False: no wall-clock start time in the file; the name is sent explicitly.
        rec = self._rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4(), send_properties=False)
        rec.save(self.path, default_blueprint=default_blueprint(header.invariant_names))
        rec.send_recording_name(header.scene_name)
        props = run_properties(header)
        # drop_untyped_nones given by name (its default), so mypy does not match **props (str values) against it
        rec.send_property("rbsim", rr.AnyValues(drop_untyped_nones=True, **props))
        rec.log("scene", rr.TextDocument(header.scene_text, media_type=rr.MediaType.TEXT), static=True)
        rec.log("run", rr.TextDocument(_markdown_table(props), media_type=rr.MediaType.MARKDOWN), static=True)
        rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        # descriptor and arrow type of each Transform3D column, taken from rerun itself, so the per-flush
        # arrays can be built straight from numpy (zero copy) instead of through the archetype helpers
        ref = [
            *rr.Transform3D.columns(translation=np.zeros((1, 3)), quaternion=[[0.0, 0.0, 0.0, 1.0]]),
            *rr.Points3D.columns(positions=np.zeros((1, 3)), radii=[1.0], colors=PALETTE[:1]),
        ]
        self._columns = {
            c.component_descriptor().component: (c.component_descriptor(), c.component_batch.as_arrow_array().type)
            for c in ref
        }

    def _array(self, component: str, values: np.ndarray) -> tuple[Any, Any]:
        """(descriptor, arrow array) of `component` built once from flat numpy values; per-body columns
        are zero-copy slices of it."""
        descriptor, arrow_type = self._columns[component]
        if isinstance(arrow_type, pa.FixedSizeListType):
            return descriptor, pa.FixedSizeListArray.from_arrays(pa.array(values.reshape(-1)), type=arrow_type)
        return descriptor, pa.array(values, type=arrow_type)

    def _log_clouds(self, first: FrameBlock | None) -> None:
        """Static particle clouds in body frames; single-particle bodies get a size from the scene scale.

        All bodies' points, radii and colours are three arrow arrays; each body's static chunk holds
        slices of them, and the chunks go to Rerun in one `send_chunks` call (`rr.log` with the
        archetype cost ~0.25 ms per body, one `send_columns` per body ~0.1 ms).
        """
        assert self._rec is not None
        scale = 1.0
        if first is not None and len(first) and first.x.shape[1] > 1:
            span = np.ptp(first.x[0], axis=0).max()
            scale = float(span) if np.isfinite(span) and span > 0 else 1.0
        clouds = [np.asarray(c, dtype=np.float64).reshape(-1, 3) for c in self._header.body_particle_offset]
        counts = np.array([len(c) for c in clouds], dtype=np.int64)
        starts = np.concatenate([[0], np.cumsum(counts)])
        radii = particle_display_radii(clouds, fallback=0.02 * scale).astype(np.float32)
        colors = _rgba32(PALETTE[np.arange(len(clouds)) % len(PALETTE)])
        stacked = np.concatenate(clouds).astype(np.float32) if clouds else np.zeros((0, 3), np.float32)
        positions = self._array("Points3D:positions", stacked)
        radius, color = self._array("Points3D:radii", radii), self._array("Points3D:colors", colors)
        one = pa.array(np.array([0, 1], dtype=np.int32))
        chunks = []
        for i, entity in enumerate(self._bodies):
            if not counts[i]:
                continue
            columns = [
                rr.ComponentColumn(
                    positions[0],
                    _ArrowBatch(positions[1].slice(starts[i], counts[i])),
                    offsets=pa.array(np.array([0, counts[i]], np.int32)),
                ),
                rr.ComponentColumn(radius[0], _ArrowBatch(radius[1].slice(i, 1)), offsets=one),
                rr.ComponentColumn(color[0], _ArrowBatch(color[1].slice(i, 1)), offsets=one),
            ]
            chunks.append(Chunk.from_columns(f"{entity}/particles", [], columns))
        rr.send_chunks(chunks, recording=self._rec)
        self._clouds_logged = True

    def write(self, block: FrameBlock) -> None:
        if self._rec is None or self._closed:
            raise RuntimeError("SinkRerun.write before open() or after close()")
        if not self._clouds_logged:
            self._log_clouds(block)
        # body-major float32 now, while the block is hot in cache; rotations as Rerun's xyzw. A diverged
        # run may hold values beyond float32: they become inf, without a warning on the user's terminal.
        body_count, k_count = block.x.shape[1], len(block)
        xf = np.empty((body_count, k_count, 3), dtype=np.float32)
        qf = np.empty((body_count, k_count, 4), dtype=np.float32)
        with np.errstate(over="ignore", invalid="ignore"):
            xf[...] = block.x.transpose(1, 0, 2)
            qf[..., :3] = block.q[..., 1:].transpose(1, 0, 2)
            qf[..., 3] = block.q[..., 0].T
            pp = None if block.particle_position is None else np.asarray(block.particle_position, dtype=np.float32)
        inv = {name: np.asarray(block.invariants[name], dtype=np.float64) for name in self._header.invariant_names}
        self._pending.append({"t": block.t, "step": block.step, "x": xf, "q": qf, "inv": inv, "particles": pp})
        self._pending_bytes += xf.nbytes + qf.nbytes + (pp.nbytes if pp is not None else 0)
        self._keep_path(block.x)
        if sum(len(p["t"]) for p in self._pending) >= self._flush_frames or self._pending_bytes >= self._flush_bytes:
            self._flush()

    def _keep_path(self, x: np.ndarray) -> None:
        """Keep every stride-th centre of mass; when over budget, drop every other point, double stride."""
        idx = np.arange(self._path_seen, self._path_seen + len(x))
        self._path_seen += len(x)
        keep = idx % self._path_stride == 0
        if keep.any():
            with np.errstate(over="ignore", invalid="ignore"):
                self._path_points.append(np.asarray(x[keep], dtype=np.float32))
        if sum(len(p) for p in self._path_points) > self._trajectory_points:
            self._path_points = [np.concatenate(self._path_points)[::2]]
            self._path_stride *= 2

    def _flush(self) -> None:
        """Send the gathered frames: one chunk per body (all in one send_chunks) and per invariant."""
        if not self._pending:
            return
        assert self._rec is not None
        pending, self._pending, self._pending_bytes = self._pending, [], 0
        t = np.concatenate([p["t"] for p in pending])
        step = np.concatenate([p["step"] for p in pending]).astype(np.int64)
        k_count = len(t)
        # integer ns, rounded: TimeColumn would truncate t * 1e9 (0.3 s -> 299999999 ns)
        times = [
            rr.TimeColumn(TIMELINE_TIME, duration=np.rint(t * 1e9).astype(np.int64).astype("timedelta64[ns]")),
            rr.TimeColumn(TIMELINE_STEP, sequence=step),
        ]
        # (N*K, width) per component, body-major, so each body's column is a zero-copy slice
        arrays = {}
        for name, key in (("Transform3D:translation", "x"), ("Transform3D:quaternion", "q")):
            values = np.concatenate([p[key] for p in pending], axis=1).reshape(-1)
            descriptor, arrow_type = self._columns[name]
            arrays[descriptor] = pa.FixedSizeListArray.from_arrays(pa.array(values), type=arrow_type)
        offsets = pa.array(np.arange(k_count + 1, dtype=np.int32))  # one transform per row
        chunks = []
        for i, entity in enumerate(self._bodies):
            cols = [
                rr.ComponentColumn(d, _ArrowBatch(arr.slice(i * k_count, k_count)), offsets=offsets)
                for d, arr in arrays.items()
            ]
            chunks.append(Chunk.from_columns(entity, times, cols))
        rr.send_chunks(chunks, recording=self._rec)  # one call for every body
        for name in self._header.invariant_names:
            values = np.concatenate([p["inv"][name] for p in pending])
            self._rec.send_columns(f"invariants/{name}", indexes=times, columns=rr.Scalars.columns(scalars=values))
        if all(p["particles"] is not None for p in pending):
            pp = np.concatenate([p["particles"] for p in pending], axis=0)
            points = rr.Points3D.columns(positions=pp.reshape(-1, 3)).partition(np.full(k_count, pp.shape[1]))
            self._rec.send_columns("particles", indexes=times, columns=points)
        self.frames_written += k_count

    def close(self, summary: RunSummary) -> None:
        """Send what is gathered, the trajectories and the summary, then finish the file (any status)."""
        if self._closed or self._rec is None:
            self._closed = True
            return
        self._closed = True
        rec = self._rec
        try:
            self._flush()
            if not self._clouds_logged:
                self._log_clouds(None)
            if self._path_points and self._bodies:
                paths = np.concatenate(self._path_points)  # (k, N, 3)
                # non-finite points (a diverged run) would break the strip and the view bounds
                per_body = np.ascontiguousarray(paths.transpose(1, 0, 2))
                if np.isfinite(paths).all():
                    strips = list(per_body)
                else:
                    strips = [p[np.isfinite(p).all(axis=1)] for p in per_body]
                colors = PALETTE[np.arange(len(strips)) % len(PALETTE)]
                rec.log(
                    "trajectories", rr.LineStrips3D(strips, colors=colors, radii=rr.Radius.ui_points(1.0)), static=True
                )
            ending = summary.fields(self.frames_written)
            rec.send_property("rbsim.summary", rr.AnyValues(drop_untyped_nones=True, **ending))
            rec.log("summary", rr.TextDocument(_markdown_table(ending), media_type=rr.MediaType.MARKDOWN), static=True)
        finally:
            rec.flush()
            rec.disconnect()  # finishes the file sink: footer and manifest
            self._rec = None


# --- reading ---------------------------------------------------------------------------------------


@dataclass
class RrdContents:
    """What read_rrd_file finds: per entity, rows sorted by step (rotations converted to wxyz)."""

    entity_paths: list[str]
    properties: dict[str, dict[str, str]]
    scene_text: str
    body_time: dict[str, np.ndarray] = field(default_factory=dict)  # entity -> (T,) [s]
    body_step: dict[str, np.ndarray] = field(default_factory=dict)  # entity -> (T,)
    body_translation: dict[str, np.ndarray] = field(default_factory=dict)  # entity -> (T, 3) [m]
    body_quaternion: dict[str, np.ndarray] = field(default_factory=dict)  # entity -> (T, 4) wxyz
    invariant_time: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (T,) [s]
    invariants: dict[str, np.ndarray] = field(default_factory=dict)  # name -> (T,)
    particle_offset: dict[str, np.ndarray] = field(default_factory=dict)  # body entity -> (n, 3) body frame


def _flat(column: Any, width: int) -> np.ndarray:
    """A list<...> column with one instance per row (scalar or fixed-size list) -> (rows, width)."""
    values = column.flatten()
    while hasattr(values, "flatten"):
        values = values.flatten()
    values = values.to_numpy(zero_copy_only=False)
    return np.asarray(values, dtype=np.float64).reshape(-1, width)


def read_rrd_file(path: str | Path, *, bodies: bool = True) -> RrdContents:
    """Read an .rrd written by SinkRerun with rerun's own chunk reader (rerun.chunk.RrdReader).

    bodies=False skips the per-body and particle chunks (enough for a summary of the invariants).
    """
    from rerun.chunk import RrdReader

    paths: set[str] = set()
    properties: dict[str, dict[str, str]] = {}
    scene = ""
    parts: dict[str, dict[str, list[np.ndarray]]] = {}
    offsets: dict[str, np.ndarray] = {}
    stream = RrdReader(path).stream()
    if not bodies:
        stream = stream.drop(content=["/bodies/**", "/trajectories", "/particles"])
    for chunk in stream:
        entity = chunk.entity_path
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if entity.startswith("/__properties"):
            if entity != "/__properties":
                prop = properties.setdefault(entity.removeprefix("/__properties/"), {})
                for name in names[1:]:
                    prop[name] = batch.column(name).to_pylist()[-1][0]
            continue
        paths.add(entity)
        if entity == "/scene" and "TextDocument:text" in names:
            scene = batch.column("TextDocument:text").to_pylist()[-1][0]
        if entity.endswith("/particles") and chunk.is_static and "Points3D:positions" in names:
            offsets[entity.removesuffix("/particles")] = _flat(batch.column("Points3D:positions"), 3)
        if chunk.is_static or TIMELINE_STEP not in names:
            continue
        acc = parts.setdefault(entity, {})
        acc.setdefault("step", []).append(batch.column(TIMELINE_STEP).to_numpy())
        ns = batch.column(TIMELINE_TIME).cast("int64").to_numpy()
        acc.setdefault("time", []).append(ns * 1e-9)
        for name, width in (("Transform3D:translation", 3), ("Transform3D:quaternion", 4)):
            if name in names:
                acc.setdefault(name, []).append(_flat(batch.column(name), width))
        if "Scalars:scalars" in names:
            acc.setdefault("scalar", []).append(_flat(batch.column("Scalars:scalars"), 1)[:, 0])
    out = RrdContents(sorted(paths), properties, scene, particle_offset=offsets)
    for entity, acc in parts.items():
        order = np.argsort(np.concatenate(acc["step"]), kind="stable")
        cat = {k: np.concatenate(v)[order] for k, v in acc.items()}
        if entity.startswith("/invariants/") and "scalar" in cat:
            name = entity.removeprefix("/invariants/")
            out.invariant_time[name], out.invariants[name] = cat["time"], cat["scalar"]
        elif "Transform3D:translation" in cat:
            out.body_time[entity], out.body_step[entity] = cat["time"], cat["step"]
            out.body_translation[entity] = cat["Transform3D:translation"]
            out.body_quaternion[entity] = cat["Transform3D:quaternion"][:, [3, 0, 1, 2]]
    return out


def verify_rrd_command(path: str | Path) -> list[str]:
    """The `rerun rrd verify` command line for a file (the CLI bundled with rerun-sdk)."""
    import sys

    return [sys.executable, "-m", "rerun", "rrd", "verify", str(path)]


def open_viewer_command(path: str | Path, *, web: bool = False) -> list[str]:
    """The command that opens a file in the Rerun viewer shipped with rerun-sdk (web: served on 127.0.0.1)."""
    import sys

    cmd = [sys.executable, "-m", "rerun", str(path)]
    return cmd + ["--web-viewer", "--bind", "127.0.0.1"] if web else cmd
