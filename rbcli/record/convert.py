"""MCAP -> RRD: replay an rbsim MCAP recording through SinkRerun (used by `rbsim replay --save`).

The RRD written here has the same layout as one recorded live (entities, blueprint, properties),
because the frames go through the same sink; only the t = 0 particle clouds, the scene text and the
run parameters come from the MCAP file's point clouds, attachment and metadata instead of the run.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from rbcli.record.frame import RunHeader, RunSummary


def header_from_mcap_metadata(
    meta: dict[str, str], scene_text: str, particle_offset: dict[str, np.ndarray]
) -> RunHeader:
    """Rebuild the RunHeader a run wrote into an MCAP file's `rbsim` metadata record."""
    names = tuple(json.loads(meta.get("body_names", "[]")))
    mass = json.loads(meta.get("body_mass", "[]")) or [float("nan")] * len(names)
    return RunHeader(
        scene_name=meta.get("scene_name", ""),
        scene_text=scene_text,
        scene_path=meta.get("scene_path") or None,
        scene_sha256=meta.get("scene_sha256", ""),
        body_names=names,
        body_mass=np.asarray(mass, dtype=np.float64),
        body_particle_offset=tuple(particle_offset.get(n, np.zeros((0, 3))) for n in names),
        integrator=meta.get("integrator", ""),
        dt=float(meta.get("dt", "nan")),
        duration=float(meta.get("duration", "nan")),
        record_every=int(meta.get("record_every", "1")),
        streams=tuple(json.loads(meta.get("streams", "[]"))),
        rbsim_version=meta.get("rbsim_version", ""),
        seed=int(meta.get("seed", "0")),
        invariant_names=tuple(json.loads(meta.get("invariant_names", "[]"))),
        units=meta.get("units", "SI (m, kg, s, rad)"),
        quaternion_order=meta.get("quaternion_order", "wxyz"),
    )


def mcap_to_rrd(source: str | Path, destination: str | Path, *, block_frames: int = 256) -> int:
    """Write `destination` (.rrd) from an rbsim MCAP file, streaming blocks; returns the frame count."""
    from rbcli.record.mcap_layout import METADATA_RUN, METADATA_SUMMARY
    from rbcli.record.mcap_read import iter_mcap_blocks, read_mcap_contents
    from rbcli.record.read import check_format_version
    from rbcli.record.rerun_sink import SinkRerun

    contents = read_mcap_contents(source)
    if METADATA_RUN not in contents.metadata:
        raise ValueError(f"{source}: no '{METADATA_RUN}' metadata record; not an rbsim recording")
    check_format_version(source, contents.metadata[METADATA_RUN])
    header = header_from_mcap_metadata(contents.metadata[METADATA_RUN], contents.scene_text, contents.particle_offset)
    ending = contents.metadata.get(METADATA_SUMMARY, {})
    sink = SinkRerun(destination)
    sink.open(header)
    frames, status, last_step, last_t = 0, "interrupted", 0, 0.0
    try:
        for block in iter_mcap_blocks(source, block_frames):
            sink.write(block)
            frames += len(block)
            last_step, last_t = int(block.step[-1]), float(block.t[-1])
        status = ending.get("status", "unknown")
    finally:
        sink.close(
            RunSummary(
                status=status,
                steps=int(ending.get("steps", last_step)),
                frames=int(ending.get("frames", frames)),
                t_end=float(ending.get("t_end", last_t)),
                message=ending.get("message", ""),
            )
        )
    return frames
