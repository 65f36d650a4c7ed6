"""How steady `rbsim study`'s cost axis is: the spread of each point's timing and the jumps between
neighbouring step sizes (issue 19: a benchmark, not a test; target spread below 1.3x on a quiet machine).

    python benchmarks/bench_study.py                  # both cases, 0.2 s of timing per point
    python benchmarks/bench_study.py --min-time 0.05  # shorter (as `rbsim study --quick`)

Cases, each exactly as `rbsim study SCENE --quick` runs it (three steps dt, dt/2, dt/4 and at most 100
coarse steps: the short runs, 1-4 bodies and 100-400 steps per point, whose whole-run timings used to
jump 2-4x between neighbouring dts):
  - the intermediate-axis flip (1 body, exact reference), every integrator plus MuJoCo's rows when
    mujoco is installed;
  - the spring chain (4 bodies, springs, dampers and drag: numerical reference), every integrator.
Reported per integrator: the spread of each point (slowest / fastest timing sample, CPU time of the
serial run's thread), and the largest ratio of per-step costs between neighbouring dts (1.0 = the
per-step cost does not depend on dt, as it should not); with the wall-clock median beside the CPU one,
so a busy machine shows as wall > CPU. The machine's load average is printed first: a spread above
target at a load above the core count says more about the machine than about the timing.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SPREAD_TARGET = 1.3
CASES = (
    ("intermediate-axis flip", "scenes/verification/intermediate_axis.yaml"),
    ("spring chain", "scenes/forces/spring_chain.yaml"),
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--min-time", type=float, default=0.2, help="CPU seconds of timing per point [s].")
    args = parser.parse_args()

    from rbcli.api import load_scene
    from rbcli.cli.study import QUICK_DT_EXPONENTS, QUICK_MAX_STEPS, QUICK_TOLERANCES
    from rbcli.runner.study import study

    load = os.getloadavg()
    print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores; "
          f"{args.min_time:g} s of timing per point")  # fmt: skip
    worst = []
    for title, path in CASES:
        spec = load_scene(ROOT / path)
        dts = [spec.simulation.dt * 2.0**k for k in QUICK_DT_EXPONENTS]
        duration = min(spec.simulation.duration, QUICK_MAX_STEPS * max(dts))
        started = time.perf_counter()
        result = study(spec, dts=dts, duration=duration, tolerances=QUICK_TOLERANCES, min_time=args.min_time)
        elapsed = time.perf_counter() - started
        print(f"\n## {title} ({path}): {result.body_count} bodies, {duration:g} s, dts {dts} ({elapsed:.0f} s)")
        print(f"{'integrator':<16}{'steps':>14}{'ns/body-step (CPU)':>34}{'wall/CPU':>10}{'spread':>20}{'jump':>7}")
        for name in dict.fromkeys(r.integrator for r in result.runs):
            runs = [r for r in result.runs if r.integrator == name and r.tolerance is None]
            if not runs:
                continue
            ns = [r.ns_per_body_step for r in runs]
            spreads = [r.cost_spread for r in runs]
            jump = max(max(a, b) / min(a, b) for a, b in zip(ns, ns[1:], strict=False)) if len(ns) > 1 else 1.0
            wall = statistics.median(r.wall_seconds_per_step / r.seconds_per_step for r in runs)
            worst.append(max(spreads))
            print(f"{name:<16}{'/'.join(str(r.steps) for r in runs):>14}{' '.join(f'{v:9.0f}' for v in ns):>34}"
                  f"{wall:>10.2f}{' '.join(f'{s:5.2f}x' for s in spreads):>20}{jump:>6.2f}x")  # fmt: skip
        for note in result.notes:
            print(f"note: {note}")
    median, top = statistics.median(worst), max(worst)
    verdict = "met" if top < SPREAD_TARGET else ("met by the median" if median < SPREAD_TARGET else "not met")
    print(f"\nspread (slowest / fastest sample): median of the per-integrator maxima {median:.2f}x, "
          f"largest {top:.2f}x; target < {SPREAD_TARGET}x on a quiet machine: {verdict}")  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
