"""Sweeps on Dask against the same variants run one by one (issue 21's speed targets; not a test).

Two sweeps:
- flip: a Monte Carlo of the intermediate-axis flip (scenes/verification/intermediate_axis.yaml), one
  body per variant, its angular momentum drawn around the intermediate axis, split2 at dt = 1e-4 s over
  20 s (200,000 steps a variant); enough variants for >= 10 s serial;
- pile: 64 variants of the 1,000-ball pile (scenes/contact/sphere_pile.yaml), the contact friction on a
  grid from 0.1 to 0.8.

Each runs serially in this process, then on a LocalCluster of 1 and of 2 worker processes (one thread
each). The sweep's wall time starts after the cluster is up and every worker has loaded the kernels,
and ends with the last row, before the cluster is closed (start-up, warm-up and shut-down are reported
apart); the serial run is warmed the same way. Reported: wall times, speed-up serial / 2 workers
(target >= 1.7), the 1-worker overhead over serial (target < 10 %) and per variant, and where a worker's
extra time goes: idle (slots x wall minus the variants' own time, the rows' wall_s summed), its variants
running slower than serially, the CPU time Dask itself spends per variant (the client process, with the
scheduler and nannies), and the workers' CPU time against the serial run's (a measure that the load of
other processes leaves alone, unlike wall times). Every run's rows are checked equal (wall time aside).

    python benchmarks/bench_sweep.py            # both sweeps (about 6 minutes on 2 cores)
    python benchmarks/bench_sweep.py --quick    # fewer variants and steps: a smoke run
    python benchmarks/bench_sweep.py --repeat 3 # on a shared machine: 3 interleaved rounds, medians
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
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


def _cpu_seconds() -> dict[str, float]:
    """CPU time [s] of this process (the client, and a LocalCluster's scheduler and nannies: they run in
    it) and of the worker processes it spawned."""
    import psutil

    seconds = {"client": time.process_time(), "worker": 0.0}
    for child in psutil.Process().children(recursive=True):
        try:
            if "spawn_main" in " ".join(child.cmdline()):  # multiprocessing's spawned child: a Dask worker
                cpu = child.cpu_times()
                seconds["worker"] += cpu.user + cpu.system
        except psutil.Error:
            continue
    return seconds


def _run(spec, workers: int | None) -> dict:  # noqa: ANN001 - a SweepSpec
    """One run: its wall time, the variants' own time (busy: the rows' wall_s summed), the CPU time of
    the client, nannies and workers during the sweep (warm-up and start-up excluded), tasks, rows."""
    from rbcli.sweeps.run import run_sweep

    marks: dict[str, dict[str, float]] = {}
    seen = [0]

    def on_start(total: int, done: int, cluster: object) -> None:
        marks["start"] = _cpu_seconds()

    def on_rows(rows: list[dict]) -> None:
        seen[0] += len(rows)
        if seen[0] >= spec.variant_count:  # the last batch: the cluster is still up
            marks["end"] = _cpu_seconds()

    scheduler = "serial" if workers is None else None
    run = run_sweep(spec, scheduler=scheduler, workers=workers, use_folder=False, on_start=on_start, on_rows=on_rows)
    cluster = run.cluster
    cpu = {role: marks["end"][role] - marks["start"][role] for role in marks["start"]}
    return {
        "wall_s": run.wall_s,
        "busy_s": sum(run.table.column("wall_s").to_pylist()),
        "cpu_s": cpu,
        "startup_s": None if cluster is None else cluster.startup_s,
        "warmup_s": None if cluster is None else cluster.warmup_s,
        "shutdown_s": None if cluster is None else cluster.shutdown_s,
        "tasks": None if cluster is None else cluster.tasks,
        "batch": None if cluster is None else cluster.batch,
        "rows": _comparable(run.table),
    }


CONFIGS = {"serial": None, "workers1": 1, "workers2": 2}


def measure(name: str, text: str, folder: Path, repeat: int) -> dict:
    from rbcli.sweeps.load import analyse_sweep_text

    spec, issues = analyse_sweep_text(text, f"<{name}>", folder)
    if spec is None:
        raise SystemExit("\n".join(map(str, issues)))
    n = spec.variant_count
    print(f"{name}: {n} variants", file=sys.stderr, flush=True)
    result: dict = {"sweep": name, "variants": n, "load": [os.getloadavg()[0]]}
    runs: dict[str, list[dict]] = {config: [] for config in CONFIGS}
    reference = None
    # the configurations take turns (in a rotating order), so a change of the machine's load falls on
    # all of them alike; each is reported by its median
    for round_ in range(repeat):
        order = list(CONFIGS)
        order = order[round_ % 3 :] + order[: round_ % 3]
        for config in order:
            run = _run(spec, CONFIGS[config])
            rows = run.pop("rows")
            reference = reference or rows
            assert rows == reference, f"{config}: rows differ from the first run's"
            runs[config].append(run)
            extra = "" if run["startup_s"] is None else (
                f" (start-up {run['startup_s']:.2f} s, warm-up {run['warmup_s']:.2f} s, "
                f"shut-down {run['shutdown_s']:.2f} s, "
                f"{run['tasks']} tasks of <= {run['batch']})"
            )  # fmt: skip
            print(f"  {config:8s} {run['wall_s']:7.2f} s{extra}", file=sys.stderr, flush=True)
        result["load"].append(os.getloadavg()[0])
    result["runs"] = runs
    for config, config_runs in runs.items():
        result[config] = {key: statistics.median(r[key] for r in config_runs) for key in ("wall_s", "busy_s")} | {
            "cpu_s": {
                role: statistics.median(r["cpu_s"][role] for r in config_runs) for role in config_runs[0]["cpu_s"]
            }
        }
        if config != "serial":
            for key in ("startup_s", "warmup_s", "shutdown_s", "tasks", "batch"):
                result[config][key] = statistics.median(r[key] for r in config_runs)
    serial_s = result["serial"]["wall_s"]
    one, two = result["workers1"]["wall_s"], result["workers2"]["wall_s"]
    result["serial_s"] = serial_s
    result["speedup_2"] = serial_s / two
    result["overhead_1"] = one / serial_s - 1.0
    result["overhead_per_variant_ms"] = (one - serial_s) / n * 1e3
    result["serial_per_variant_ms"] = serial_s / n * 1e3
    # where a worker's extra time goes: idle between its variants (wall x slots - busy), and its variants
    # running slower than the serial ones (busy on workers / busy serial)
    for workers in (1, 2):
        config = result[f"workers{workers}"]
        config["idle_fraction"] = 1.0 - config["busy_s"] / (workers * config["wall_s"])
        config["busy_over_serial"] = config["busy_s"] / result["serial"]["busy_s"] - 1.0
        config["dask_cpu_per_variant_ms"] = config["cpu_s"]["client"] / n * 1e3
        config["worker_cpu_over_serial"] = config["cpu_s"]["worker"] / result["serial"]["cpu_s"]["client"] - 1.0
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer variants and steps (a smoke run)")
    parser.add_argument("--repeat", type=int, default=1, help="interleaved runs of each, the median kept")
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
          "| overhead / variant [ms] | idle (1, 2) | variant slow-down (1, 2) | Dask CPU / variant (2) [ms] "
          "| worker CPU over serial (1, 2) | tasks (2) | start-up (2) [s] | warm-up (2) [s] "
          "| shut-down (2) [s] |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for r in results:
        one, two = r["workers1"], r["workers2"]
        print(
            f"| {r['sweep']} | {r['variants']} | {r['serial_s']:.2f} | {one['wall_s']:.2f} | {two['wall_s']:.2f} "
            f"| {r['speedup_2']:.2f}x | {100 * r['overhead_1']:+.1f} % | {r['overhead_per_variant_ms']:+.2f} "
            f"| {100 * one['idle_fraction']:.1f} %, {100 * two['idle_fraction']:.1f} % "
            f"| {100 * one['busy_over_serial']:+.1f} %, {100 * two['busy_over_serial']:+.1f} % "
            f"| {two['dask_cpu_per_variant_ms']:.2f} "
            f"| {100 * one['worker_cpu_over_serial']:+.1f} %, {100 * two['worker_cpu_over_serial']:+.1f} % "
            f"| {two['tasks']:.0f} "
            f"| {two['startup_s']:.2f} | {two['warmup_s']:.2f} | {two['shutdown_s']:.2f} |"
        )
    print(json.dumps(results, indent=1), file=sys.stderr)


if __name__ == "__main__":  # Dask's worker processes are spawned: they must not run this again
    main()
