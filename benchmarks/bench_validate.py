"""Validating a large explicit-particle scene: `rbsim validate` against plain YAML loading of the same file.

    python benchmarks/bench_validate.py [--particles 160000] [--repeats 3]

In a temporary folder, a scene of one body given by `--particles` explicit positions (nine decimals each,
8.2 MB at 160,000; tracker issue 20, item 7, measured a 9 MB one) and a scalar mass. Each command is a
whole process; its wall time, CPU time and peak RSS (the child's ru_maxrss) are measured, `--repeats`
rounds with the commands interleaved so that a change of machine load hits them alike, medians reported:
  - baseline: `python -c "yaml.safe_load(...)"` (PyYAML's Python loader: what a script would do),
  - baseline C: the same with `yaml.CSafeLoader` (libyaml parses, Python constructs),
  - `python -m rbcli validate scene.yaml` (YAML with locations, JSON Schema, checks, mass properties).
Targets: validate under 3 s and under 200 MB peak (on an unloaded machine: the 2-core development
machine is shared, so compare with the baselines of the same run, and look at the CPU time, which load
changes least).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
TARGET_SECONDS = 3.0
TARGET_MB = 200.0


def write_scene(path: Path, particles: int, seed: int = 0) -> None:
    rng = np.random.default_rng(seed)
    positions = rng.normal(size=(particles, 3))
    lines = [
        "simulation: {dt: 0.001, duration: 0.01}",
        "bodies:",
        "  - name: cloud",
        "    particles:",
        "      positions:",
    ]
    lines += [f"        - [{x:.9f}, {y:.9f}, {z:.9f}]" for x, y, z in positions]
    lines.append("      masses: 1.0")
    path.write_text("\n".join(lines) + "\n")


def measure(command: list[str]) -> tuple[float, float, float]:
    """(wall time [s], CPU time [s] (user + system: what a loaded machine changes least), peak RSS [MB]) of one
    whole process."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    start = time.perf_counter()
    process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env)
    _, status, usage = os.wait4(process.pid, 0)
    wall = time.perf_counter() - start
    process.returncode = os.waitstatus_to_exitcode(status)
    if process.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed: {process.stderr.read().decode() if process.stderr else ''}")
    return wall, usage.ru_utime + usage.ru_stime, usage.ru_maxrss / 1024.0  # ru_maxrss: kB on Linux


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=160_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="rbsim-bench-validate-") as folder:
        scene = Path(folder) / "cloud.yaml"
        write_scene(scene, args.particles)
        size = scene.stat().st_size
        load = "import sys, yaml; yaml.load(open(sys.argv[1], encoding='utf-8'), Loader=yaml.{})"
        commands = {
            "baseline: yaml.safe_load": [sys.executable, "-c", load.format("SafeLoader"), str(scene)],
            "baseline: yaml CSafeLoader": [sys.executable, "-c", load.format("CSafeLoader"), str(scene)],
            "rbsim validate": [sys.executable, "-m", "rbcli", "validate", str(scene)],
        }
        results: dict[str, list[tuple[float, float, float]]] = {name: [] for name in commands}
        for command in commands.values():  # one unmeasured run each: imports and file cache warm
            measure(command)
        for round_ in range(args.repeats):
            order = list(commands) if round_ % 2 == 0 else list(reversed(commands))
            for name in order:
                results[name].append(measure(commands[name]))
    print(f"{args.particles:,} explicit particles, {size / 1e6:.1f} MB scene; {platform.machine()}, "
          f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; medians of {args.repeats}")  # fmt: skip
    print(f"{'command':<30} {'wall [s]':>9} {'(min-max)':>15} {'CPU [s]':>8} {'peak RSS [MB]':>14}")
    medians = {}
    for name, runs in results.items():
        walls = [w for w, _, _ in runs]
        medians[name] = tuple(statistics.median(column) for column in zip(*runs, strict=True))
        spread = f"({min(walls):.2f}-{max(walls):.2f})"
        wall, cpu, rss = medians[name]
        print(f"{name:<30} {wall:>9.2f} {spread:>15} {cpu:>8.2f} {rss:>14.0f}")
    wall, cpu, rss = medians["rbsim validate"]
    base_wall, base_cpu, _ = medians["baseline: yaml.safe_load"]
    print(f"rbsim validate / yaml.safe_load: {wall / base_wall:.2f} in wall time, {cpu / base_cpu:.2f} in CPU time")

    def verdict(seconds: float) -> str:
        return "met" if seconds < TARGET_SECONDS and rss < TARGET_MB else "NOT met"

    target = f"< {TARGET_SECONDS:g} s and < {TARGET_MB:g} MB"
    print(f"target ({target}): {verdict(wall)} in wall time, {verdict(cpu)} in CPU time")


if __name__ == "__main__":
    main()
