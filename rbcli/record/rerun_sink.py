"""Rerun recording: an .rrd streamed to disk, laid out for the Rerun viewer.

Entities (timelines `time`, a duration [s], and `step`, a sequence):

    bodies/<name>              Transform3D per recorded step: translation = centre of mass, rotation
    bodies/<name>/particles    static Points3D in the body's frame, so the cloud follows the body
    trajectories               static LineStrips3D of the centre-of-mass paths, written at close
    invariants/<name>          Scalars per recorded step
    particles                  Points3D of every particle in the world frame (only with that stream)
    contacts                   Points3D of the frame's contact points, world frame, with a
                               `normal_force` [N] per point (only with that stream)
    scene                      static TextDocument: the scene YAML
    run, summary               static TextDocuments (markdown) with the run parameters and the ending

Run parameters are also recording properties (`rbsim`, `rbsim.summary`), and the default blueprint
shows the 3D view beside one time-series plot per invariant family.

A scene of more than BODY_ENTITIES_MAX bodies is written with all bodies in ONE entity instead:

    bodies                     Boxes3D per recorded step: centers = centres of mass, quaternions =
                               orientations, one instance per body in header order; static half_sizes
                               (the box about the centre of mass that holds the body's particles, body
                               frame) and colours; static `particle_offset` (all bodies' clouds, float64
                               x, y, z, body frames, concatenated) and `particle_count` (per body)

Why: the footer Rerun writes into every .rrd (its manifest, which `RrdReader` and the viewer read
before any data) has a column per entity and component, and rerun's reader refuses a manifest whose
flatbuffer holds more than 1,000,000 tables: with an entity per body (~54 tables each) the file is
unreadable from ~18,700 bodies (rerun-sdk 0.41.0: readable at 18,500 bodies, "TooManyTables" at 18,750).
The one-entity layout has a fixed number of columns whatever the body count; the viewer draws each body
as its oriented box (an entity's points cannot follow a per-instance transform).

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

# Bodies up to which each gets its own entities; above it, the one-entity layout (module docstring).
# ~1.9x below the measured limit of 18,500-18,750 bodies, for the fixed entities and for rerun versions;
# a test writes exactly this many bodies and opens the file with rerun's reader.
BODY_ENTITIES_MAX = 10_000
ENTITY_BODIES = "bodies"
# Centre-of-mass path samples kept for `trajectories`, over all bodies: 2^22 float32 x, y, z = 48 MiB, so
# memory stays flat for big scenes too (4,096 points per body up to 1,024 bodies, fewer above).
TRAJECTORY_POINTS_TOTAL = 1 << 22

# Distinct, colour-blind-friendly body colours (Okabe-Ito), cycled by body index.
PALETTE = np.array(
    [[0, 114, 178], [230, 159, 0], [0, 158, 115], [204, 121, 167], [86, 180, 233], [213, 94, 0], [240, 228, 66]],
    dtype=np.uint8,
)


def body_entity(name: str) -> str:
    """The entity path of a body (its name escaped as one path part)."""
    return f"bodies/{rr.escape_entity_path_part(name)}"


def bodies_in_one_entity(body_count: int) -> bool:
    """True when a run of this many bodies is written in the one-entity layout (module docstring)."""
    return body_count > BODY_ENTITIES_MAX


def invariant_family(name: str) -> str:
    """Invariants plotted together: the name without its last `_part` (energy_kinetic -> energy)."""
    return name.rsplit("_", 1)[0] if "_" in name else name


PROBE_BLOCK = 2048  # particles per block of distances: (512, 2048, 3) float64 = 25 MB at most


def particle_display_radius(offsets: np.ndarray, fallback: float) -> float:
    """A radius [m] that makes a cloud read as a solid: half the median nearest-neighbour spacing.

    The run header carries no particle radius, so this is a display guess; distances use at most 512
    particles against all others, in blocks of PROBE_BLOCK particles: time grows with the cloud, memory
    does not (one (512, n, 3) array took 16 GB for a 10^6-particle body).
    """
    pts = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
    if len(pts) < 2:
        return fallback
    probe = pts[np.linspace(0, len(pts) - 1, min(len(pts), 512)).astype(int)]
    nearest_d2 = np.full(len(probe), np.inf)
    for start in range(0, len(pts), PROBE_BLOCK):
        d2 = ((probe[:, None, :] - pts[None, start : start + PROBE_BLOCK, :]) ** 2).sum(axis=-1)
        d2[d2 == 0.0] = np.inf  # the probe itself (and exact duplicates)
        np.minimum(nearest_d2, d2.min(axis=1), out=nearest_d2)
    nearest = np.sqrt(nearest_d2)
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


def default_blueprint(invariant_names: Sequence[str], joint_names: Sequence[str] = ()) -> rrb.Blueprint:
    """The 3D view beside the invariant plots (one plot per family: energies, momentum, ...) and, with the
    joint_forces stream, one plot of the joints' force and torque magnitudes."""
    families: dict[str, list[str]] = {}
    for name in invariant_names:
        families.setdefault(invariant_family(name), []).append(f"invariants/{name}")
    plots = [rrb.TimeSeriesView(name=fam, origin="invariants", contents=paths) for fam, paths in families.items()]
    if joint_names:
        plots.append(rrb.TimeSeriesView(name="joint forces", origin="joint_forces", contents=["joint_forces/**"]))
    view3d = rrb.Spatial3DView(
        name="bodies", origin="/", contents=["bodies/**", "trajectories", "particles", "contacts"]
    )
    texts = rrb.Tabs(rrb.TextDocumentView(origin="scene", name="scene"), rrb.TextDocumentView(origin="run", name="run"))
    right = rrb.Vertical(*plots, texts) if plots else texts
    return rrb.Blueprint(rrb.Horizontal(view3d, right, column_shares=[3, 2]), collapse_panels=False)


class SinkRerun:
    """Records a run to an .rrd file (see the module docstring for the layout).

    flush_frames / flush_bytes: how many frames (or bytes of x and q input) to gather before sending.
    trajectory_points: at most this many points per body path (older points are thinned by 2 to fit),
    and at most TRAJECTORY_POINTS_TOTAL over all bodies.
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
        body_count = len(header.body_names)
        self._batched = bodies_in_one_entity(body_count)
        self._bodies = [] if self._batched else [body_entity(n) for n in header.body_names]
        self._path_budget = max(2, min(self._trajectory_points, TRAJECTORY_POINTS_TOTAL // max(1, body_count)))
        # gathered per block, only what is sent: t, step, x and q as float32 (N, k, 3|4) body-major
        # ((k, N, 3|4) frame-major in the one-entity layout), invariants, particle positions (the block
        # itself is not kept: v, omega, P, L are not sent)
        self._pending: list[dict[str, Any]] = []
        self._pending_bytes = 0
        self._path_points: list[np.ndarray] = []  # (k, N, 3) float32 kept centre-of-mass samples
        self._path_stride, self._path_seen = 1, 0
        self._clouds_logged = False
        # send_properties=False: no wall-clock start time in the file; the name is sent explicitly.
        rec = self._rec = rr.RecordingStream(APPLICATION_ID, recording_id=uuid.uuid4(), send_properties=False)
        rec.save(self.path, default_blueprint=default_blueprint(header.invariant_names, header.joint_names))
        rec.send_recording_name(header.scene_name)
        props = run_properties(header)
        # drop_untyped_nones given by name (its default), so mypy does not match **props (str values) against it
        rec.send_property("rbsim", rr.AnyValues(drop_untyped_nones=True, **props))
        rec.log("scene", rr.TextDocument(header.scene_text, media_type=rr.MediaType.TEXT), static=True)
        rec.log("run", rr.TextDocument(_markdown_table(props), media_type=rr.MediaType.MARKDOWN), static=True)
        rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        # on disk now, before any frame: rerun's batcher would write them only at its first flush, often
        # seconds into a run, and a run killed before that left frames without their run's parameters
        rec.flush(timeout_sec=10.0)
        # descriptor and arrow type of each Transform3D column, taken from rerun itself, so the per-flush
        # arrays can be built straight from numpy (zero copy) instead of through the archetype helpers
        ref = [
            *rr.Transform3D.columns(translation=np.zeros((1, 3)), quaternion=[[0.0, 0.0, 0.0, 1.0]]),
            *rr.Points3D.columns(positions=np.zeros((1, 3)), radii=[1.0], colors=PALETTE[:1]),
            *rr.Boxes3D.columns(centers=np.zeros((1, 3)), quaternions=[[0.0, 0.0, 0.0, 1.0]]),
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
        if self._batched:
            self._log_body_boxes()
            return
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

    def _log_body_boxes(self) -> None:
        """The one-entity layout's static part: box half sizes, colours and every cloud (see the module docstring)."""
        assert self._rec is not None
        clouds = [np.asarray(c, dtype=np.float64).reshape(-1, 3) for c in self._header.body_particle_offset]
        counts = np.array([len(c) for c in clouds], dtype=np.int64)
        stacked = np.concatenate(clouds) if clouds else np.zeros((0, 3))
        half = np.zeros((len(clouds), 3))
        filled = counts > 0
        if filled.any():  # per body max |offset| per axis, in one call: reduceat over the non-empty clouds
            starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
            half[filled] = np.maximum.reduceat(np.abs(stacked), starts[filled], axis=0)
        # a single particle (or an empty cloud) spans nothing: a small cube, a fiftieth of the largest body
        point = ~(half > 0).any(axis=1)
        half[point] = 0.02 * (half.max() if half.max() > 0 else 1.0)
        colors = PALETTE[np.arange(len(clouds)) % len(PALETTE)]
        self._rec.log(
            ENTITY_BODIES,
            rr.Boxes3D(half_sizes=half, colors=colors),
            rr.AnyValues(particle_offset=stacked.reshape(-1), particle_count=counts),
            static=True,
        )
        self._clouds_logged = True

    def write(self, block: FrameBlock) -> None:
        if self._rec is None or self._closed:
            raise RuntimeError("SinkRerun.write before open() or after close()")
        if not self._clouds_logged:
            self._log_clouds(block)
        # float32 in send order now, while the block is hot in cache; rotations as Rerun's xyzw. A diverged
        # run may hold values beyond float32: they become inf, without a warning on the user's terminal.
        body_count, k_count = block.x.shape[1], len(block)
        shape = (k_count, body_count) if self._batched else (body_count, k_count)
        xf = np.empty((*shape, 3), dtype=np.float32)
        qf = np.empty((*shape, 4), dtype=np.float32)
        with np.errstate(over="ignore", invalid="ignore"):
            if self._batched:
                xf[...] = block.x
                qf[..., :3], qf[..., 3] = block.q[..., 1:], block.q[..., 0]
            else:
                xf[...] = block.x.transpose(1, 0, 2)
                qf[..., :3] = block.q[..., 1:].transpose(1, 0, 2)
                qf[..., 3] = block.q[..., 0].T
            pp = None if block.particle_position is None else np.asarray(block.particle_position, dtype=np.float32)
        inv = {name: np.asarray(block.invariants[name], dtype=np.float64) for name in self._header.invariant_names}
        cp = cf = None
        if block.contact_point is not None and block.contact_force is not None:
            with np.errstate(over="ignore", invalid="ignore"):
                cp = [np.asarray(p, dtype=np.float32).reshape(-1, 3) for p in block.contact_point]
            cf = [np.asarray(f, dtype=np.float64) for f in block.contact_force]
        joints = None
        if block.joint_force is not None:  # |force|, |torque| on a joint's first body (its second: world first)
            side_a = np.linalg.norm(block.joint_force[:, :, 0:6], axis=2) > 0.0
            force = np.where(side_a, *(np.linalg.norm(block.joint_force[:, :, k : k + 3], axis=2) for k in (0, 6)))
            torque = np.where(side_a, *(np.linalg.norm(block.joint_force[:, :, k : k + 3], axis=2) for k in (3, 9)))
            joints = (force, torque)
        pending = {"t": block.t, "step": block.step, "x": xf, "q": qf, "inv": inv, "particles": pp, "contacts": cp,
                   "forces": cf, "joints": joints}  # fmt: skip
        self._pending.append(pending)
        self._pending_bytes += xf.nbytes + qf.nbytes + (pp.nbytes if pp is not None else 0)
        self._pending_bytes += sum(p.nbytes for p in cp) if cp is not None else 0
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
        if sum(len(p) for p in self._path_points) > self._path_budget:
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
        if self._batched:
            self._send_body_boxes(pending, times)
        else:
            self._send_body_transforms(pending, times)
        for name in self._header.invariant_names:
            values = np.concatenate([p["inv"][name] for p in pending])
            self._rec.send_columns(f"invariants/{name}", indexes=times, columns=rr.Scalars.columns(scalars=values))
        if all(p["particles"] is not None for p in pending):
            pp = np.concatenate([p["particles"] for p in pending], axis=0)
            points = rr.Points3D.columns(positions=pp.reshape(-1, 3)).partition(np.full(k_count, pp.shape[1]))
            self._rec.send_columns("particles", indexes=times, columns=points)
        if all(p["joints"] is not None for p in pending):
            force = np.concatenate([p["joints"][0] for p in pending])
            torque = np.concatenate([p["joints"][1] for p in pending])
            for j, name in enumerate(self._header.joint_names):
                for what, values in (("force", force), ("torque", torque)):
                    column = rr.Scalars.columns(scalars=np.ascontiguousarray(values[:, j]))
                    self._rec.send_columns(f"joint_forces/{name}/{what}", indexes=times, columns=column)
        if all(p["contacts"] is not None for p in pending):
            cp = [c for p in pending for c in p["contacts"]]
            lengths = np.array([len(c) for c in cp], dtype=np.int64)
            positions = np.concatenate(cp) if cp else np.zeros((0, 3), np.float32)
            forces = np.concatenate([f for p in pending for f in p["forces"]])
            columns = [
                *rr.Points3D.columns(positions=positions).partition(lengths),
                # typed explicitly: an empty float64 array (no contact in any frame) would be dropped as untyped
                *rr.AnyValues.columns(normal_force=pa.array(forces, type=pa.float64())).partition(lengths),
            ]
            self._rec.send_columns("contacts", indexes=times, columns=columns)
        self.frames_written += k_count

    def _send_body_transforms(self, pending: list[dict[str, Any]], times: list[Any]) -> None:
        """One Transform3D chunk per body entity, all in one send_chunks call."""
        k_count = sum(len(p["t"]) for p in pending)
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

    def _send_body_boxes(self, pending: list[dict[str, Any]], times: list[Any]) -> None:
        """The one-entity layout: a row per frame holding every body's centre and orientation."""
        assert self._rec is not None
        k_count = sum(len(p["t"]) for p in pending)
        body_count = len(self._header.body_names)
        columns = []
        for name, key in (("Boxes3D:centers", "x"), ("Boxes3D:quaternions", "q")):
            values = np.concatenate([p[key] for p in pending], axis=0).reshape(-1)
            descriptor, arrow_type = self._columns[name]
            array = pa.FixedSizeListArray.from_arrays(pa.array(values), type=arrow_type)
            # row k holds instances k N ... (k + 1) N - 1; int32 offsets, as rerun takes them: a flush holds
            # about flush_bytes / 28 instances (28 bytes of x and q each) plus one block, far below 2^31
            offsets = pa.array(np.arange(k_count + 1, dtype=np.int32) * np.int32(body_count))
            columns.append(rr.ComponentColumn(descriptor, _ArrowBatch(array), offsets=offsets))
        self._rec.send_columns(ENTITY_BODIES, indexes=times, columns=columns)

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
            if self._path_points and self._header.body_names:
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
class RrdBodies:
    """The bodies of a file in the one-entity layout, in header order: per recorded step, sorted by step."""

    time: np.ndarray  # (T,) [s]
    step: np.ndarray  # (T,)
    translation: np.ndarray  # (T, N, 3) [m]
    quaternion: np.ndarray  # (T, N, 4) wxyz


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
    # the one-entity layout (more than BODY_ENTITIES_MAX bodies); None in the other
    bodies: RrdBodies | None = None
    bodies_particle_offset: tuple[np.ndarray, ...] | None = None  # per body (n_i, 3) body frame [m], float64


def _flat(column: Any, width: int) -> np.ndarray:
    """A list<...> column with one instance per row (scalar or fixed-size list) -> (rows, width)."""
    values = column.flatten()
    while hasattr(values, "flatten"):
        values = values.flatten()
    values = values.to_numpy(zero_copy_only=False)
    return np.asarray(values, dtype=np.float64).reshape(-1, width)


def read_rrd_properties(path: str | Path) -> dict[str, dict[str, str]]:
    """The recording properties of an .rrd (`rbsim`: the run parameters; `rbsim.summary`), nothing else."""
    from rerun.chunk import RrdReader

    properties: dict[str, dict[str, str]] = {}
    for chunk in RrdReader(path).stream().filter(content="/__properties/**"):
        entity = chunk.entity_path
        if entity.startswith("/__properties/"):
            batch = chunk.to_record_batch()
            prop = properties.setdefault(entity.removeprefix("/__properties/"), {})
            for name in batch.schema.names[1:]:
                prop[name] = batch.column(name).to_pylist()[-1][0]
    return properties


def read_rrd_file(path: str | Path, *, bodies: bool = True) -> RrdContents:
    """Read an .rrd written by SinkRerun, in either layout, with rerun's own chunk reader (rerun.chunk.RrdReader).

    bodies=False skips the per-body and particle chunks (enough for a summary of the invariants).
    """
    from rerun.chunk import RrdReader

    paths: set[str] = set()
    properties: dict[str, dict[str, str]] = {}
    scene = ""
    parts: dict[str, dict[str, list[np.ndarray]]] = {}
    offsets: dict[str, np.ndarray] = {}
    clouds: tuple[np.ndarray, ...] | None = None
    stream = RrdReader(path).stream()
    if not bodies:
        stream = stream.drop(content=["/bodies/**", "/trajectories", "/particles", "/contacts"])
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
        if entity == f"/{ENTITY_BODIES}" and chunk.is_static and "particle_offset" in names:
            flat = np.asarray(batch.column("particle_offset")[-1].values, dtype=np.float64).reshape(-1, 3)
            counts = np.asarray(batch.column("particle_count")[-1].values, dtype=np.int64)
            clouds = tuple(np.split(flat, np.cumsum(counts)[:-1])) if counts.size else ()
        if chunk.is_static or TIMELINE_STEP not in names:
            continue
        acc = parts.setdefault(entity, {})
        acc.setdefault("step", []).append(batch.column(TIMELINE_STEP).to_numpy())
        ns = batch.column(TIMELINE_TIME).cast("int64").to_numpy()
        acc.setdefault("time", []).append(ns * 1e-9)
        for name, width in (("Transform3D:translation", 3), ("Transform3D:quaternion", 4)):
            if name in names:
                acc.setdefault(name, []).append(_flat(batch.column(name), width))
        for name, width in (("Boxes3D:centers", 3), ("Boxes3D:quaternions", 4)):
            if name in names:  # every body in each row: (rows, N, width)
                acc.setdefault(name, []).append(_flat(batch.column(name), width).reshape(batch.num_rows, -1, width))
        if "Scalars:scalars" in names:
            acc.setdefault("scalar", []).append(_flat(batch.column("Scalars:scalars"), 1)[:, 0])
    out = RrdContents(sorted(paths), properties, scene, particle_offset=offsets, bodies_particle_offset=clouds)
    for entity, acc in parts.items():
        order = np.argsort(np.concatenate(acc["step"]), kind="stable")
        cat = {k: np.concatenate(v)[order] for k, v in acc.items()}
        if entity.startswith("/invariants/") and "scalar" in cat:
            name = entity.removeprefix("/invariants/")
            out.invariant_time[name], out.invariants[name] = cat["time"], cat["scalar"]
        elif entity == f"/{ENTITY_BODIES}" and "Boxes3D:centers" in cat:
            wxyz = cat["Boxes3D:quaternions"][..., [3, 0, 1, 2]]
            out.bodies = RrdBodies(cat["time"], cat["step"], cat["Boxes3D:centers"], wxyz)
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


# --- work-precision study (`rbsim study --rerun`) ---------------------------------------------------
#
#     study/<error>/<series>        Scalars: the error of each run (max over bodies and recorded times)
#     study/log10_<error>/<series>  Scalars: log10 of it (the viewer's plots have linear axes)
#     study/cost/<series>           Scalars: wall seconds per simulated second, [min, median, max] over
#                                   the timing samples (three lines: the spread)
#     plot                          static EncodedImage: the PNG the command wrote (log-log, error bars)
#     study                         static TextDocument (markdown): reference, notes, every run's row
#
# Each row is logged on two duration timelines: `dt` (the step; for adaptive series the mean accepted
# step) and `cost` (CPU time per simulated second, as a duration), so choosing the `cost` timeline
# shows error against cost and `dt` error and cost against the step; and on the sequence `run`, the
# row's index in the study's table (and JSON), which orders the rows when a dt or a cost repeats. A
# series is one integrator (MuJoCo's rows are `mujoco-euler`, `mujoco-rk4`; an adaptive method by
# tolerance is `<name>-adaptive`).

STUDY_TIMELINE_DT = "dt"
STUDY_TIMELINE_COST = "cost"
STUDY_TIMELINE_RUN = "run"
STUDY_COST_SAMPLES = ("min", "median", "max")


@dataclass(frozen=True)
class StudySeries:
    """One line of a work-precision study: a run per row.

    run (n,): each row's index in the study's table; dt (n,) [s]; cost (n, 3) [s/s] CPU seconds per
    simulated second (min, median, max over samples); errors: name -> (n,) (e.g. rotation_error_max
    [rad]); non-finite errors (diverged runs) are skipped.
    """

    name: str
    run: np.ndarray
    dt: np.ndarray
    cost: np.ndarray
    errors: dict[str, np.ndarray]


def _study_indexes(run: np.ndarray, dt: np.ndarray, cost: np.ndarray) -> list[rr.TimeColumn]:
    """The `run`, `dt` and `cost` timelines of some rows; durations as integer ns, rounded (TimeColumn
    would truncate seconds * 1e9)."""

    def ns(seconds: np.ndarray) -> np.ndarray:
        return np.rint(np.asarray(seconds, dtype=np.float64) * 1e9).astype(np.int64).astype("timedelta64[ns]")

    return [
        rr.TimeColumn(STUDY_TIMELINE_RUN, sequence=np.asarray(run, dtype=np.int64)),
        rr.TimeColumn(STUDY_TIMELINE_DT, duration=ns(dt)),
        rr.TimeColumn(STUDY_TIMELINE_COST, duration=ns(cost)),
    ]


def write_study_rrd(
    path: str | Path, title: str, series: Sequence[StudySeries], plot_png: bytes, text_markdown: str
) -> None:
    """Write a study as an .rrd (layout above); `title` names the recording."""
    rec = rr.RecordingStream(f"{APPLICATION_ID}-study", recording_id=uuid.uuid4(), send_properties=False)
    names = [rr.escape_entity_path_part(s.name) for s in series]
    error_names = list(dict.fromkeys(e for s in series for e in s.errors))
    blueprint = rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial2DView(origin="plot", name="work-precision plot"),
            rrb.Vertical(
                *[rrb.TimeSeriesView(origin=f"study/log10_{e}", name=f"log10 {e}") for e in error_names],
                rrb.TimeSeriesView(origin="study/cost", name="cost [s per simulated s]"),
                rrb.TextDocumentView(origin="study", name="study"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )
    rec.save(path, default_blueprint=blueprint)
    rec.send_recording_name(title)
    rec.log("plot", rr.EncodedImage(contents=plot_png, media_type="image/png"), static=True)
    rec.log("study", rr.TextDocument(text_markdown, media_type=rr.MediaType.MARKDOWN), static=True)
    for line, s in zip(names, series, strict=True):
        dt, cost = np.asarray(s.dt, dtype=np.float64), np.asarray(s.cost, dtype=np.float64).reshape(-1, 3)
        run = np.asarray(s.run, dtype=np.int64)
        rec.log(f"study/cost/{line}", rr.SeriesLines(names=[f"{s.name} {k}" for k in STUDY_COST_SAMPLES]), static=True)
        rec.send_columns(
            f"study/cost/{line}",
            indexes=_study_indexes(run, dt, cost[:, 1]),
            columns=rr.Scalars.columns(scalars=cost).partition([3] * len(dt)),
        )
        for error, values in s.errors.items():
            values = np.asarray(values, dtype=np.float64)
            keep = np.isfinite(values) & np.isfinite(cost[:, 1])
            if not keep.any():
                continue
            indexes = _study_indexes(run[keep], dt[keep], cost[keep, 1])
            rec.send_columns(f"study/{error}/{line}", indexes=indexes, columns=rr.Scalars.columns(scalars=values[keep]))
            # log10 of an exact zero (round-off below the last bit) would be -inf: drawn at 1e-300 instead
            logs = np.log10(np.maximum(values[keep], 1e-300))
            rec.send_columns(f"study/log10_{error}/{line}", indexes=indexes, columns=rr.Scalars.columns(scalars=logs))
    rec.flush()
    rec.disconnect()


@dataclass
class RrdStudy:
    """A study .rrd read back: per scalar entity its timelines (`run` the row index, `dt` and `cost`
    [s]) and values, rows in the study's order; the static images (entity -> (bytes, media type)) and
    text documents."""

    timelines: dict[str, dict[str, np.ndarray]] = field(default_factory=dict)  # entity -> timeline -> (n,)
    values: dict[str, np.ndarray] = field(default_factory=dict)  # entity -> (n, k)
    images: dict[str, tuple[bytes, str]] = field(default_factory=dict)
    texts: dict[str, str] = field(default_factory=dict)


def read_study_rrd(path: str | Path) -> RrdStudy:
    """Read a file of `write_study_rrd` with rerun's own chunk reader (rerun.chunk.RrdReader)."""
    from rerun.chunk import RrdReader

    out = RrdStudy()
    parts: dict[str, dict[str, list[np.ndarray]]] = {}
    for chunk in RrdReader(path).stream():
        entity = chunk.entity_path.lstrip("/")
        batch = chunk.to_record_batch()
        names = batch.schema.names
        if "EncodedImage:blob" in names:
            blob = batch.column("EncodedImage:blob").to_pylist()[-1][0]
            media = (
                batch.column("EncodedImage:media_type").to_pylist()[-1][0] if "EncodedImage:media_type" in names else ""
            )
            out.images[entity] = (bytes(blob), media)
        if "TextDocument:text" in names:
            out.texts[entity] = batch.column("TextDocument:text").to_pylist()[-1][0]
        if chunk.is_static or "Scalars:scalars" not in names:
            continue
        acc = parts.setdefault(entity, {})
        width = len(batch.column("Scalars:scalars")[0].values) if batch.num_rows else 1
        acc.setdefault("values", []).append(_flat(batch.column("Scalars:scalars"), width))
        acc.setdefault(STUDY_TIMELINE_RUN, []).append(batch.column(STUDY_TIMELINE_RUN).to_numpy())
        for timeline in (STUDY_TIMELINE_DT, STUDY_TIMELINE_COST):
            if timeline in names:
                acc.setdefault(timeline, []).append(batch.column(timeline).cast("int64").to_numpy() * 1e-9)
    for entity, acc in parts.items():
        cat = {k: np.concatenate(v) for k, v in acc.items()}
        order = np.argsort(cat[STUDY_TIMELINE_RUN], kind="stable")
        out.values[entity] = cat.pop("values")[order]
        out.timelines[entity] = {k: v[order] for k, v in cat.items()}
    return out
