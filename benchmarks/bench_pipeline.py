"""The step pipeline's cost, measured in one run (run on demand, not a test):

1. the chunk loops (rbcli/physics/chunk_loop.py, impulse and record stages around the update)
   against a frozen copy of the pre-pipeline loops (benchmarks/frozen_chunks.py), split2 and rk4, at
   N = 1, 100, 10,000 free bodies under gravity: interleaved medians, ratio new / frozen (target <= 1.05);
2. the Python API `Simulation.step(1000)` against the bare chunk loop for the same 1,000 steps
   (targets: <= 1.3x at N = 1, <= 1.1x at N = 100 and 10,000);
3. `load_scene` + compile of a 10,000-body generated scene (target < 0.3 s; reported, not asserted).

    python benchmarks/bench_pipeline.py [--repeats 15]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from frozen_chunks import FROZEN  # noqa: E402

import rbcli  # noqa: E402
from rbcli.physics.data import make_data  # noqa: E402
from rbcli.physics.integrators import get_integrator  # noqa: E402
from rbcli.physics.step import empty_buffers  # noqa: E402
from rbcli.scene.spec import BodySpec, RecordSpec, SceneSpec, SimulationSpec  # noqa: E402

DT = 1e-3


def free_bodies(count: int, integrator: str) -> SceneSpec:
    rng = np.random.default_rng(0)
    bodies = []
    for i in range(count):
        q = rng.normal(size=4)
        bodies.append(
            BodySpec(
                name=f"b{i}",
                particle_position=rng.normal(size=(4, 3)),
                particle_mass=rng.uniform(0.5, 2.0, size=4),
                position=rng.normal(size=3),
                orientation_wxyz=q / np.linalg.norm(q),
                velocity=rng.normal(size=3),
                angular_momentum=rng.normal(size=3),
            )  # fmt: skip
        )
    sim = SimulationSpec(dt=DT, duration=1.0, integrator=integrator, record=RecordSpec(10**9, ("bodies",)))
    return SceneSpec(name="bench", simulation=sim, bodies=tuple(bodies), gravity=np.array([0.0, 0.0, -9.81]))


def steps_for(n: int) -> int:
    return {1: 100_000, 100: 2_000, 10_000: 40}[n]


def compare_chunks(integrator: str, n: int, repeats: int) -> tuple[float, float]:
    """Median seconds per step of (chunk loop, frozen), timed alternately from the same initial state."""
    sim = rbcli.Simulation(free_bodies(n, integrator))
    # the tables as runs pass them (None for unused force types: their stages compiled away)
    km, forces, initial = sim.model.kernel(), sim.forces.kernel(), sim.compiled.initial_state
    chunk = get_integrator(integrator).chunk()
    frozen = FROZEN[integrator]
    frames = empty_buffers(2, n)
    steps = steps_for(n)

    def new() -> float:
        data = make_data(initial, sim.model, chunk.SCRATCH_WIDTH, forces=sim.forces).kernel()
        started = time.perf_counter()
        chunk.run_chunk(km, forces, data, DT, 0, steps, 10**9, frames, 0)
        return (time.perf_counter() - started) / steps

    def old() -> float:
        d = make_data(initial, sim.model, chunk.SCRATCH_WIDTH, forces=sim.forces)
        s = d.state
        started = time.perf_counter()
        frozen(km, forces, d.force, DT, 0, steps, 10**9, s.x, s.q, s.P, s.L, d.F, d.tau, d.scratch, frames, 0)
        return (time.perf_counter() - started) / steps

    new(), old()  # compile or load
    a, b = [], []
    for _ in range(repeats):
        a.append(new())
        b.append(old())
    return statistics.median(a), statistics.median(b)


def compare_api(n: int, repeats: int, integrator: str = "split2") -> tuple[float, float]:
    """Median seconds of sim.step(1000) and of the bare chunk for 1,000 steps, alternately."""
    sim = rbcli.Simulation(free_bodies(n, integrator))
    km, forces = sim.model.kernel(), sim.forces.kernel()  # what Simulation passes its chunk
    chunk = get_integrator(integrator).chunk()
    data = make_data(sim.compiled.initial_state, sim.model, chunk.SCRATCH_WIDTH, forces=sim.forces).kernel()
    frames = empty_buffers(1, n)
    steps = 1000
    repeats = repeats if n < 10_000 else min(repeats, 5)

    def api() -> float:
        started = time.perf_counter()
        sim.step(steps)
        return time.perf_counter() - started

    def bare() -> float:
        started = time.perf_counter()
        chunk.run_chunk(km, forces, data, DT, 0, steps, 2**62, frames, 0)
        return time.perf_counter() - started

    api(), bare()
    a, b = [], []
    for _ in range(repeats):
        a.append(api())
        b.append(bare())
    return statistics.median(a), statistics.median(b)


def load_and_compile_seconds(count: int = 10_000) -> float:
    text = (
        "name: grid\nsimulation: {dt: 0.001, duration: 0.01, integrator: split2}\n"
        "bodies:\n  - grid:\n      name: cell\n"
        f"      count: [{count}, 1, 1]\n      spacing: 0.5\n      origin: [0, 0, 0]\n"
        "      template:\n        particles:\n"
        "          positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]]\n          masses: 1.0\n"
    )
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "grid.yaml"
        path.write_text(text)
        started = time.perf_counter()
        rbcli.prepare(rbcli.load_scene(path))
        first = time.perf_counter() - started
        started = time.perf_counter()
        rbcli.prepare(rbcli.load_scene(path))
        return min(first, time.perf_counter() - started)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    args = parser.parse_args()
    print("chunk loops (chunk_loop.py) vs the frozen pre-pipeline loops (median ns per step, interleaved)")
    print(f"{'integrator':<10} {'N':>6} {'loop':>12} {'frozen':>12} {'ratio':>7}")
    for integrator in ("split2", "rk4"):
        for n in (1, 100, 10_000):
            new, old = compare_chunks(integrator, n, args.repeats)
            print(f"{integrator:<10} {n:>6} {new * 1e9:>12.0f} {old * 1e9:>12.0f} {new / old:>7.3f}")
    print("\nSimulation.step vs the bare chunk (split2, median of one call)")
    print(f"{'N':>6} {'steps':>6} {'sim.step [ms]':>14} {'bare [ms]':>10} {'ratio':>7}")
    for n in (1, 100, 10_000):
        api, bare = compare_api(n, args.repeats)
        steps = 1000
        print(f"{n:>6} {steps:>6} {api * 1e3:>14.3f} {bare * 1e3:>10.3f} {api / bare:>7.3f}")
    try:
        seconds = load_and_compile_seconds()
        print(f"\nload_scene + compile of a 10,000-body grid scene: {seconds:.2f} s")
    except Exception as exc:  # noqa: BLE001 - a scene-format change should not hide the rest
        print(f"\nload_scene + compile: not measured ({type(exc).__name__}: {exc})")


if __name__ == "__main__":
    main()
