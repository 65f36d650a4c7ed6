"""The threaded step (issue 28 item 1) against the serial one and MuJoCo, measured in the same run.

    python benchmarks/bench_threads.py [--quick] [--repeats N]

`Simulation.step` of split2 on 1 thread (the serial loop) and on every core (`threads="all"`: the loop
calling `step_parallel`, used from runner/threads.py's PARALLEL_MIN_BODIES bodies on), body-steps per
wall second, best of the repeats, interleaved so a change of machine load hits both alike:
  free bodies under gravity (bench_speed's bodies) at N = 100, 300, 1,000, 10,000, beside MuJoCo Euler
    (bench_speed's model: `mj_step(nstep)`, the faster of its two timings there, on one core);
  bench_speed's spring chain of 1,000 bodies;
  scenes/contact/sphere_pile.yaml (1,000 balls, contact) over its first steps.
Each row says whether the two runs ended bitwise equal (they must), and the header the machine's load.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_speed  # noqa: E402

from rbcli.runner.simulation import Simulation  # noqa: E402
from rbcli.runner.threads import PARALLEL_MIN_BODIES, available_cores  # noqa: E402
from rbcli.scene.compile import compile_scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def timed_steps(sim: Simulation, steps: int) -> float:
    started = time.perf_counter()
    sim.step(steps)
    return time.perf_counter() - started


def compare(label: str, compiled, bodies: int, steps: int, repeats: int, mujoco: bool) -> None:  # noqa: ANN001
    serial, threaded = Simulation(compiled, threads=1), Simulation(compiled, threads="all")
    serial.step(1)
    threaded.step(1)
    best = {"serial": float("inf"), "threaded": float("inf")}
    for _ in range(repeats):
        best["serial"] = min(best["serial"], timed_steps(serial, steps))
        best["threaded"] = min(best["threaded"], timed_steps(threaded, steps))
    same = all(
        np.array_equal(getattr(serial.data.state, k), getattr(threaded.data.state, k)) for k in ("x", "q", "P", "L")
    )
    rate = {k: bodies * steps / v for k, v in best.items()}
    line = (
        f"{label:28s} 1 thread {rate['serial']:9.3g}   {threaded.threads} threads {rate['threaded']:9.3g}   "
        f"gain {rate['threaded'] / rate['serial']:5.2f}x   bitwise {'yes' if same else 'NO'}"
    )
    if mujoco:
        runners, _ = bench_speed.mujoco_runners(compiled)
        run = runners["MuJoCo mj_step(nstep)"](steps)
        run()
        mj = min(run() for _ in range(repeats))
        mj_rate = bodies * steps / mj
        line += (
            f"   MuJoCo Euler {mj_rate:9.3g}: rbsim {rate['serial'] / mj_rate:5.2f}x / "
            f"{rate['threaded'] / mj_rate:5.2f}x"
        )
    print(line, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps and repeats")
    parser.add_argument("--repeats", type=int, default=None)
    options = parser.parse_args()
    repeats = options.repeats or (3 if options.quick else 7)
    budget = 2e6 if options.quick else 1e7  # body-steps per timed run
    load = os.getloadavg()
    print(f"threads: {available_cores()} cores; threaded loop from {PARALLEL_MIN_BODIES} bodies; "
          f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; body-steps/s, best of {repeats}")  # fmt: skip
    try:
        import mujoco  # noqa: F401

        have_mujoco = True
    except ImportError:
        have_mujoco = False
    for n in (100, 300, 1_000, 10_000):
        compiled = compile_scene(bench_speed.scene(bench_speed.free_bodies(n)))
        compare(f"free bodies N = {n:,}", compiled, n, max(20, int(budget / n)), repeats, have_mujoco)
    chain = compile_scene(bench_speed.spring_chain(1_000))
    compare("spring chain N = 1,000", chain, 1_000, max(20, int(budget / 1_000)), repeats, False)
    from rbcli.scene.load import load_scene

    pile = compile_scene(load_scene(ROOT / "scenes" / "contact" / "sphere_pile.yaml"))
    compare("sphere pile N = 1,000", pile, 1_000, 100 if options.quick else 300, max(2, repeats // 2), False)


if __name__ == "__main__":
    main()
