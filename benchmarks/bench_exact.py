"""Cost of `exact` against split2, measured in the same run on the same 10,000 free bodies under gravity.

    python benchmarks/bench_exact.py [--bodies 10000] [--repeats 7]

Rows, each the median over repeats (spread = max / min printed) in ns per body and per unit of work:
  split2 step                 sim.step(100): ns per body-step (the reference of every ratio)
  exact evaluation            sim.step(1) 10 s after the anchors: one deferred step, then the state of
                              every body evaluated from its anchor (the chunk's end): ns per body per
                              evaluation, what a recorded frame costs (the issue's target: <= 4x split2)
  exact, recorded every 100   sim.step(100): 100 deferred steps and one evaluation, ns per body-step
  exact, every step written   a drag of 1e-300 N s/m makes the forces non-constant, so every step
                              is written (the orientation at the force evaluation and at the step's end:
                              two evaluations) and the wrench evaluated: ns per body-step
  one-shot flow               free_rotation_exact_batch from the initial state over the evaluation's
                              horizon, what each evaluation cost before the anchor's constants were
                              kept (ns per body)
The machine's load moves every row alike; the ratios are what to read.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_speed import free_bodies, scene  # noqa: E402

from rbcli.api import prepare
from rbcli.physics.elliptic import JACOBI_WORK_SIZE
from rbcli.physics.free_rotation_exact import free_rotation_exact_batch
from rbcli.runner.simulation import Simulation
from rbcli.scene.force_specs import ForceDrag


def timed(run: Callable[[], None], repeats: int) -> tuple[float, float]:
    """(median seconds, max / min) over repeats, after one warm-up call."""
    run()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run()
        times.append(time.perf_counter() - start)
    return statistics.median(times), max(times) / min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()
    n, repeats = args.bodies, args.repeats
    bodies = free_bodies(n)
    rows: dict[str, tuple[float, float]] = {}

    split2 = Simulation(prepare(scene(bodies, integrator="split2")))
    seconds, spread = timed(lambda: split2.step(100), repeats)
    rows["split2 step"] = (seconds / (100 * n), spread)

    exact = Simulation(prepare(scene(bodies, integrator="exact")))
    # the anchors, then 100 s on (deferred steps): each evaluation below is at a horizon of several periods,
    # the closed form's case (short arcs, lambda h < dist / 2, integrate psi' by Gauss-Legendre instead)
    exact.step(round(100.0 / exact.dt))
    seconds, spread = timed(lambda: exact.step(1), repeats)
    rows["exact evaluation"] = (seconds / n, spread)
    seconds, spread = timed(lambda: exact.step(100), repeats)
    rows["exact, recorded every 100"] = (seconds / (100 * n), spread)

    zero_drag = (ForceDrag(linear=1e-300),)  # a drag row that changes nothing: the forces are no longer constant
    eager = Simulation(prepare(scene(bodies, forces=zero_drag, integrator="exact")))
    seconds, spread = timed(lambda: eager.step(10), repeats)
    rows["exact, every step written"] = (seconds / (10 * n), spread)

    s, horizon = exact.compiled.initial_state, exact.time  # the same bodies and horizon as the evaluation
    inertia, out, work = exact.model.body_inertia, np.empty_like(s.q), np.empty(JACOBI_WORK_SIZE)
    seconds, spread = timed(lambda: free_rotation_exact_batch(inertia, s.q, s.L, horizon, out, work), repeats)
    rows["one-shot flow"] = (seconds / n, spread)

    reference = rows["split2 step"][0]
    print(f"{n} free bodies under gravity, median of {repeats} (spread max/min)")
    for name, (seconds, spread) in rows.items():
        print(f"  {name:28s} {seconds * 1e9:8.1f} ns  {seconds / reference:6.2f}x split2  (spread {spread:.2f})")


if __name__ == "__main__":
    main()
