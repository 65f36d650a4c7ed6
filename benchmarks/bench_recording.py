"""What recording costs: FrameBlock generation against writing the same blocks through each sink.

Run on demand:  python benchmarks/bench_recording.py [--bodies 1000] [--frames 1000] [--step-us 30]

This isolates the sinks: the blocks come from a cheap analytic stand-in for the runner (bodies on
circles, spinning about fixed axes: smooth like real trajectories, so compression sees realistic data),
written in the calling thread. The whole path (the runner, its recording thread, each sink) against a
run without recording is the recording section of `benchmarks/bench_speed.py`. Each sink is timed from
open() to the end of close(), so background work that must finish before the file is complete (zstd
chunks, Rerun's encoder thread, footers) is included.

Wall times on a shared machine swing with its load; the `cpu us/fr` column (process CPU time, all
threads) is the steadier measure of what a sink costs.

The issue's target: recording every step may add at most 50 % to a run of 1,000 bodies x 1,000 steps,
whose compiled step takes ~20-50 us. The report gives each sink's cost per recorded frame, that cost
over one step, and the `record_every` that would meet the target.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rbcli.record.frame import FrameBlock, RunHeader, RunSummary  # noqa: E402

INVARIANTS = ("energy_kinetic", "energy_potential", "energy_total", "momentum_x", "momentum_y", "momentum_z")


def runner_block_frames(body_count: int) -> int:
    """The block size rbcli.runner.loop picks: ~8 MiB of 13 float64 per body per frame, 1..1024."""
    return int(np.clip(8 * 1024 * 1024 // max(1, 13 * 8 * body_count), 1, 1024))


def make_header(body_count: int, particles: int = 8) -> RunHeader:
    rng = np.random.default_rng(0)
    return RunHeader(
        scene_name="bench",
        scene_text="name: bench\n",
        scene_path=None,
        scene_sha256="0" * 64,
        body_names=tuple(f"body_{i}" for i in range(body_count)),
        body_mass=np.ones(body_count),
        body_particle_offset=tuple(0.1 * rng.normal(size=(particles, 3)) for _ in range(body_count)),
        integrator="bench",
        dt=1e-3,
        duration=1.0,
        record_every=1,
        streams=("bodies", "invariants"),
        rbsim_version="bench",
        invariant_names=INVARIANTS,
    )


def make_blocks(body_count: int, frames: int, block_frames: int, dt: float = 1e-3) -> list[FrameBlock]:
    """Bodies on circles of radius r_i at rate w_i, spinning at s_i about a fixed axis a_i."""
    rng = np.random.default_rng(1)
    n = body_count
    r, w, s = rng.uniform(1, 10, n), rng.uniform(0.5, 2, n), rng.uniform(1, 5, n)
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    blocks = []
    for s0 in range(0, frames, block_frames):
        step = np.arange(s0, min(frames, s0 + block_frames), dtype=np.int64)
        t = step * dt
        ang = t[:, None] * w  # (K, N)
        x = np.stack([r * np.cos(ang), r * np.sin(ang), 0.1 * ang], axis=-1)
        v = np.stack([-r * w * np.sin(ang), r * w * np.cos(ang), np.broadcast_to(0.1 * w, ang.shape)], axis=-1)
        half = 0.5 * s * t[:, None]
        q = np.concatenate([np.cos(half)[..., None], np.sin(half)[..., None] * axis], axis=-1)
        omega = np.broadcast_to(s[:, None] * axis, x.shape).copy()
        energy = 0.5 * (v**2).sum(axis=(1, 2))
        inv = {name: energy + i for i, name in enumerate(INVARIANTS)}
        blocks.append(
            FrameBlock(step=step, t=t, x=x, q=q, v=v, omega=omega, P=v.copy(), L=omega * 0.01, invariants=inv)
        )
    return blocks


def time_sink(make_sink: Callable[[], object], header: RunHeader, blocks: list[FrameBlock]) -> dict[str, float]:
    """Wall seconds spent in open, in all writes, and in close; and the process CPU seconds of it all
    (every thread, Rerun's encoder included), which a busy shared machine inflates far less."""
    frames = sum(len(b) for b in blocks)
    sink = make_sink()
    c0 = time.process_time()
    t0 = time.perf_counter()
    sink.open(header)  # type: ignore[attr-defined]
    t1 = time.perf_counter()
    for block in blocks:
        sink.write(block)  # type: ignore[attr-defined]
    t2 = time.perf_counter()
    sink.close(RunSummary("completed", frames - 1, frames, float(blocks[-1].t[-1])))  # type: ignore[attr-defined]
    t3 = time.perf_counter()
    return {"open": t1 - t0, "write": t2 - t1, "close": t3 - t2, "total": t3 - t0, "cpu": time.process_time() - c0}


def naive_tf_us_per_frame(header: RunHeader, block: FrameBlock, frames: int = 20) -> float:
    """Reference: /tf built with one foxglove protobuf object per body (what the numpy encoder avoids)."""
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    t0 = time.perf_counter()
    for k in range(min(frames, len(block))):
        msg = FrameTransforms()
        ns = round(float(block.t[k]) * 1e9)
        for i, name in enumerate(header.body_names):
            tr = msg.transforms.add(parent_frame_id="world", child_frame_id=name)
            tr.timestamp.FromNanoseconds(ns)
            tr.translation.x, tr.translation.y, tr.translation.z = block.x[k, i]
            tr.rotation.w, tr.rotation.x, tr.rotation.y, tr.rotation.z = block.q[k, i]
        msg.SerializeToString()
    return (time.perf_counter() - t0) / min(frames, len(block)) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=1000)
    parser.add_argument("--frames", type=int, default=1000)
    parser.add_argument("--block", type=int, default=0, help="frames per block [default: as the runner sizes them]")
    parser.add_argument("--step-us", type=float, default=30.0, help="cost of one compiled step to compare with [us]")
    parser.add_argument("--repeat", type=int, default=2, help="runs per sink; the best is reported")
    parser.add_argument("--out", type=Path, default=None, help="directory for the files [default: a temp dir]")
    args = parser.parse_args()

    from rbcli.record.mcap_sink import SinkMcap
    from rbcli.record.rerun_sink import SinkRerun

    block_frames = args.block or runner_block_frames(args.bodies)
    header = make_header(args.bodies)
    t0, c0 = time.perf_counter(), time.process_time()
    blocks = make_blocks(args.bodies, args.frames, block_frames)
    gen, gen_cpu = time.perf_counter() - t0, time.process_time() - c0
    frames = sum(len(b) for b in blocks)

    out = args.out or Path(tempfile.mkdtemp(prefix="rbsim-bench-"))
    out.mkdir(parents=True, exist_ok=True)
    sinks = {
        "SinkMcap zstd": lambda: SinkMcap(out / "bench.mcap"),
        "SinkMcap lz4": lambda: SinkMcap(out / "bench-lz4.mcap", compression="lz4"),
        "SinkMcap none": lambda: SinkMcap(out / "bench-raw.mcap", compression="none"),
        "SinkRerun": lambda: SinkRerun(out / "bench.rrd"),
    }
    files = {"SinkMcap zstd": "bench.mcap", "SinkMcap lz4": "bench-lz4.mcap", "SinkMcap none": "bench-raw.mcap"}
    files["SinkRerun"] = "bench.rrd"

    print(f"rbsim recording benchmark: {args.bodies} bodies x {frames} frames, blocks of {block_frames} frames")
    print(f"reference step: {args.step_us:g} us (run of {frames} steps: {frames * args.step_us / 1e3:.1f} ms)")
    print(
        f"generate FrameBlocks (stand-in runner): {gen * 1e3:.1f} ms = {gen / frames * 1e6:.1f} us/frame "
        f"(cpu {gen_cpu / frames * 1e6:.1f} us/frame)\n"
    )
    head = f"{'sink':<15} {'open':>8} {'write':>9} {'close':>8} {'us/frame':>9} {'cpu us/fr':>9} {'x step':>7}"
    print(head + f" {'x gen':>6} {'MB':>7}  record_every for <=50%")
    for name, make in sinks.items():
        best = min((time_sink(make, header, blocks) for _ in range(args.repeat)), key=lambda r: r["total"])
        per_frame = best["total"] / frames * 1e6
        needed = max(1, math.ceil(per_frame / (0.5 * args.step_us)))
        size = (out / files[name]).stat().st_size / 1e6
        print(
            f"{name:<15} {best['open'] * 1e3:6.0f}ms {best['write'] * 1e3:7.0f}ms {best['close'] * 1e3:6.0f}ms "
            f"{per_frame:9.0f} {best['cpu'] / frames * 1e6:9.0f} {per_frame / args.step_us:6.1f}x "
            f"{best['total'] / gen:5.1f}x {size:7.1f}  {needed}"
        )
    from rbcli.record.mcap_encoders import StateEncoder, TransformsEncoder

    encoders = {"/rbsim/state": StateEncoder(args.bodies), "/tf": TransformsEncoder(header.body_names)}
    print("\nMCAP encoders alone (numpy, wire format):")
    for topic, encoder in encoders.items():
        t0 = time.perf_counter()
        for block in blocks:
            encoder.encode(block)
        print(f"  {topic:<13} {(time.perf_counter() - t0) / frames * 1e6:7.1f} us/frame")
    naive = naive_tf_us_per_frame(header, blocks[0])
    print(f"  /tf with one foxglove protobuf object per body instead: {naive:7.0f} us/frame")
    print(f"files in {out}")


if __name__ == "__main__":
    main()
