"""The run-cost estimate (scene/run_cost.py) beside the measured CPU time of shipped scenes, warm.

    python benchmarks/bench_run_cost.py [--seconds S] [scene ...]

Each scene (default: a spread of shipped ones: free bodies, forces, contact spheres, shapes, joints,
joints with shapes) is compiled and stepped once (its kernels compiled or loaded), reset, then run for
its whole duration or S simulated seconds, whichever is shorter, on one thread; CPU time of this process
(time.process_time). Prints the estimate for the same steps, the measured time and their ratio. The
estimate's costs are meant to say which minute a run takes: a ratio within ~2-3x either way is what it
promises.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rbcli import Simulation  # noqa: E402
from rbcli.api import prepare  # noqa: E402
from rbcli.scene.run_cost import run_cost  # noqa: E402

SCENES = (
    "scenes/tutorial.yaml",
    "scenes/verification/spring_tether.yaml",
    "scenes/contact/box_drop.yaml",
    "scenes/contact/box_stack.yaml",
    "scenes/contact/dominoes.yaml",
    "scenes/verification/contact_pile.yaml",
    "scenes/joints/chain_100.yaml",
    "scenes/joints/ragdoll.yaml",
    "scenes/joints/capsule_ragdoll.yaml",
)


def measure(path: Path, seconds: float) -> tuple[float, float, int]:
    """(estimated, measured CPU s, steps) for min(duration, seconds) of the scene."""
    compiled = prepare(path)
    steps = min(compiled.settings.steps, max(1, round(seconds / compiled.settings.dt)))
    estimate = run_cost(replace(compiled, settings=replace(compiled.settings, steps=steps))).seconds
    sim = Simulation(compiled, threads=1)
    sim.step(1)
    sim.reset()
    started = time.process_time()
    sim.step(steps)
    return estimate, time.process_time() - started, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenes", nargs="*", default=list(SCENES))
    parser.add_argument("--seconds", type=float, default=3.0)
    options = parser.parse_args()
    print(f"{'scene':44} {'steps':>8} {'estimate':>9} {'measured':>9} {'ratio':>6}")
    for name in options.scenes:
        estimate, measured, steps = measure(ROOT / name, options.seconds)
        print(f"{name:44} {steps:8,} {estimate:8.3g}s {measured:8.3g}s {measured / estimate:6.2f}", flush=True)
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
