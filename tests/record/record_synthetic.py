"""Synthetic runs for the recording tests: a header and frame blocks with no physics behind them.

Not a conftest.py: tests/conftest.py is imported as `conftest` by other suites. Test modules import
the `*_fixture` functions below, which pytest then registers under their `name`."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

from rbcli.record.frame import FrameBlock, RunHeader, RunSummary

# names of different byte lengths (one non-ASCII) so the /tf encoder's grouping by length is exercised
BODY_NAMES = ("a", "body_b", "böx")
INVARIANT_NAMES = ("energy_kinetic", "energy_total", "momentum_x")
BLOCK_SIZES = (5, 7, 4)
DT = 0.1  # k * 0.1 is rarely an exact float (0.30000000000000004): exercises ns rounding
SCENE_TEXT = "name: synthetic\nbodies:\n  - name: a  # comment kept verbatim\n"


def make_header(body_names=BODY_NAMES, invariant_names=INVARIANT_NAMES, seed: int = 0) -> RunHeader:
    rng = np.random.default_rng(seed)
    # particle counts 4, 1, 6, ... (a single-particle body included)
    offsets = tuple(rng.normal(size=(1 if i == 1 else 4 + 2 * i, 3)) for i in range(len(body_names)))
    return RunHeader(
        scene_name="synthetic",
        scene_text=SCENE_TEXT,
        scene_path="scenes/synthetic.yaml",
        scene_sha256=hashlib.sha256(SCENE_TEXT.encode()).hexdigest(),
        body_names=tuple(body_names),
        body_mass=rng.uniform(0.5, 2.0, size=len(body_names)),
        body_particle_offset=offsets,
        integrator="euler-matrix",
        dt=DT,
        duration=2.0,
        record_every=1,
        streams=("bodies", "invariants"),
        rbsim_version="0.1.0",
        seed=7,
        invariant_names=tuple(invariant_names),
    )


def make_blocks(header: RunHeader, sizes=BLOCK_SIZES, seed: int = 1, diverge: bool = True) -> list[FrameBlock]:
    """Blocks of random states; with diverge, the last frame holds a NaN and a huge value."""
    rng = np.random.default_rng(seed)
    n = len(header.body_names)
    blocks, s0 = [], 0
    for k in sizes:
        step = np.arange(s0, s0 + k, dtype=np.int64)
        q = rng.normal(size=(k, n, 4))
        q /= np.linalg.norm(q, axis=-1, keepdims=True)
        inv = {name: rng.normal(size=k) + 10.0 for name in header.invariant_names}
        blocks.append(
            FrameBlock(
                step=step,
                t=step * header.dt,
                x=rng.normal(size=(k, n, 3)),
                q=q,
                v=rng.normal(size=(k, n, 3)),
                omega=rng.normal(size=(k, n, 3)),
                P=rng.normal(size=(k, n, 3)),
                L=rng.normal(size=(k, n, 3)),
                invariants=inv,
            )
        )
        s0 += k
    if "momentum_x" in header.invariant_names:
        blocks[0].invariants["momentum_x"][0] = 0.0  # starts at zero: no relative drift
    if diverge:
        blocks[-1].x[-1, 0, 0] = np.nan
        blocks[-1].P[-1, 1, 2] = 1e300
    return blocks


def concat(blocks: list[FrameBlock], attr: str) -> np.ndarray:
    return np.concatenate([getattr(b, attr) for b in blocks], axis=0)


def write_run(sink, header: RunHeader, blocks: list[FrameBlock], status: str = "diverged") -> RunSummary:
    """Drive a sink as the runner does: open, write each block, close with a summary."""
    frames = sum(len(b) for b in blocks)
    steps = int(blocks[-1].step[-1]) if blocks else 0
    summary = RunSummary(
        status, steps, frames, steps * header.dt, "state became non-finite" if status == "diverged" else ""
    )
    sink.open(header)
    for block in blocks:
        sink.write(block)
    sink.close(summary)
    return summary


@pytest.fixture(scope="session", name="synthetic")
def synthetic_fixture():
    header = make_header()
    return header, make_blocks(header)


@pytest.fixture(scope="session", name="mcap_path")
def mcap_path_fixture(tmp_path_factory, synthetic):
    from rbcli.record.mcap_sink import SinkMcap

    path = tmp_path_factory.mktemp("mcap") / "run.mcap"
    write_run(SinkMcap(path), *synthetic)
    return path


@pytest.fixture(scope="session", name="rrd_path")
def rrd_path_fixture(tmp_path_factory, synthetic):
    from rbcli.record.rerun_sink import SinkRerun

    path = tmp_path_factory.mktemp("rrd") / "run.rrd"
    write_run(SinkRerun(path, flush_frames=6), *synthetic)  # several flushes of gathered blocks
    return path
