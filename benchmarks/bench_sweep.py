"""Sweeps on Dask against the same variants run one by one (issue 21's speed targets; not a test).

Two sweeps:
- flip: a Monte Carlo of the intermediate-axis flip (scenes/verification/intermediate_axis.yaml), one
  body per variant, its angular momentum drawn around the intermediate axis, split2 at dt = 1e-4 s over
  20 s (200,000 steps a variant); enough variants for >= 10 s serial;
- pile: 64 variants of the 1,000-ball pile (scenes/contact/sphere_pile.yaml), the contact friction on a
  grid from 0.1 to 0.8.

Each runs serially in this process, then on a LocalCluster of 1 and of 2 worker processes (one thread
each). The sweep's wall time starts after the cluster is up and every worker has loaded the kernels
(start-up and warm-up are reported apart); the serial run is warmed the same way. Reported: wall times,
speed-up serial / 2 workers (target >= 1.7), the 1-worker overhead over serial (target < 10 %) and per
variant. Every run's rows are checked equal to the serial rows (wall time aside).

    python benchmarks/bench_sweep.py            # both sweeps (about 6 minutes on 2 cores)
    python benchmarks/bench_sweep.py --quick    # fewer variants and steps: a smoke run
    python benchmarks/bench_sweep.py --repeat 3 # on a shared machine: each configuration's fastest of 3
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

FLIP = """\
name: bench-flip
scene: {scene}
samples: {samples}
seed: 21
axes:
  - path: bodies[0].angular_momentum
    random: {{distribution: normal, mean: [0.01, 10.0, 0.0], std: [0.01, 0.0, 0.01]}}
  - path: simulation.integrator
    values: [split2]
  - path: simulation.dt
    values: [{dt}]
"""

PILE = """\
name: bench-pile
scene: {scene}
axes:
  - path: contact.material.friction
    grid: {{start: 0.1, stop: 0.8, num: {num}}}
  - path: simulation.duration
    values: [{duration}]
"""


def _comparable(table) -> list[dict]:  # noqa: ANN001 - a pyarrow Table
    return table.drop_columns(["wall_s"]).to_pylist()


def measure(name: str, text: str, folder: Path, repeat: int) -> dict:
    from rbcli.sweeps.load import analyse_sweep_text
    from rbcli.sweeps.run import run_sweep

    spec, issues = analyse_sweep_text(text, f"<{name}>", folder)
    if spec is None:
        raise SystemExit("\n".join(map(str, issues)))
    n = spec.variant_count
    print(f"{name}: {n} variants", file=sys.stderr, flush=True)
    result: dict = {"sweep": name, "variants": n, "load": [os.getloadavg()[0]]}
    reference = None
    # the configurations take turns, and each keeps its fastest run: another process's work on this
    # machine only ever slows a run down
    for _ in range(repeat):
        serial = run_sweep(spec, scheduler="serial", use_folder=False)
        reference = reference or _comparable(serial.table)
        result["serial_s"] = min(result.get("serial_s", float("inf")), serial.wall_s)
        print(f"  serial    {serial.wall_s:7.2f} s", file=sys.stderr, flush=True)
        for workers in (1, 2):
            run = run_sweep(spec, workers=workers, use_folder=False)
            assert _comparable(run.table) == reference, "rows differ from the serial run"
            cluster = run.cluster
            assert cluster is not None
            best = result.get(f"workers{workers}")
            if best is None or run.wall_s < best["wall_s"]:
                result[f"workers{workers}"] = {
                    "wall_s": run.wall_s,
                    "startup_s": cluster.startup_s,
                    "warmup_s": cluster.warmup_s,
                    "batch": cluster.batch,
                }
            print(
                f"  {workers} worker{'s' * (workers > 1)} {run.wall_s:7.2f} s (start-up {cluster.startup_s:.2f} s, "
                f"warm-up {cluster.warmup_s:.2f} s, batch {cluster.batch})",
                file=sys.stderr,
                flush=True,
            )
        result["load"].append(os.getloadavg()[0])
    serial_s = result["serial_s"]
    one, two = result["workers1"]["wall_s"], result["workers2"]["wall_s"]
    result["speedup_2"] = serial_s / two
    result["overhead_1"] = one / serial_s - 1.0
    result["overhead_per_variant_ms"] = (one - serial_s) / n * 1e3
    result["serial_per_variant_ms"] = serial_s / n * 1e3
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer variants and steps (a smoke run)")
    parser.add_argument("--repeat", type=int, default=1, help="runs of each configuration, the fastest kept")
    parser.add_argument("--only", choices=("flip", "pile"), help="run one of the two sweeps")
    args = parser.parse_args()
    flip_scene = REPO / "scenes" / "verification" / "intermediate_axis.yaml"
    pile_scene = REPO / "scenes" / "contact" / "sphere_pile.yaml"
    cases = {
        "flip": FLIP.format(scene=flip_scene, samples=16 if args.quick else 192, dt=1e-3 if args.quick else 1e-4),
        "pile": PILE.format(scene=pile_scene, num=8 if args.quick else 64, duration=0.1 if args.quick else 1.0),
    }
    results = []
    with tempfile.TemporaryDirectory() as folder:
        for name, text in cases.items():
            if args.only and name != args.only:
                continue
            results.append(measure(name, text, Path(folder), args.repeat))
    print("| sweep | variants | serial [s] | 1 worker [s] | 2 workers [s] | speed-up (2) | overhead (1) "
          "| overhead / variant [ms] | start-up (2) [s] | warm-up (2) [s] |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        one, two = r["workers1"], r["workers2"]
        print(
            f"| {r['sweep']} | {r['variants']} | {r['serial_s']:.2f} | {one['wall_s']:.2f} | {two['wall_s']:.2f} "
            f"| {r['speedup_2']:.2f}x | {100 * r['overhead_1']:+.1f} % | {r['overhead_per_variant_ms']:+.2f} "
            f"| {two['startup_s']:.2f} | {two['warmup_s']:.2f} |"
        )
    print(json.dumps(results, indent=1), file=sys.stderr)


if __name__ == "__main__":  # Dask's worker processes are spawned: they must not run this again
    main()
