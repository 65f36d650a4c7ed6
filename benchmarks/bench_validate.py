"""Validating a large explicit-particle scene: `rbsim validate` against plain YAML loading of the same file.

    python benchmarks/bench_validate.py [--particles 160000] [--repeats 3]
    python benchmarks/bench_validate.py --chain 5000 [--repeats 3]

In a temporary folder, a scene of one body given by `--particles` explicit positions (nine decimals each,
8.2 MB at 160,000; tracker issue 20, item 7, measured a 9 MB one) and a scalar mass. Each command is a
whole process; its wall time, CPU time and peak RSS (the child's ru_maxrss) are measured, `--repeats`
rounds with the commands interleaved so that a change of machine load hits them alike, medians reported:
  - baseline: `python -c "yaml.safe_load(...)"` (PyYAML's Python loader: what a script would do),
  - baseline C: the same with `yaml.CSafeLoader` (libyaml parses, Python constructs),
  - `python -m rbcli validate scene.yaml` (YAML with locations, JSON Schema, checks, mass properties).
`--chain LINKS` times instead a hinge chain of LINKS capsule links given by one chain generator (issue 46,
item 4: 5,000 links in <= 2 s) and the same chain written out by hand, against `python -c pass`.
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


CHAIN_TARGET_SECONDS = 2.0  # issue 46, item 4: validate a generated 5,000-link chain in <= 2 s
CHAIN_LINK = "{shape: {type: capsule, radius: 0.004, height: 0.012, axis: x}, count: 30, mass: 0.01}"
CHAIN_JOINT = "{type: hinge, axis: [0, 1, 0], damping: 0.001}"


def write_chain(path: Path, links: int, *, by_hand: bool) -> None:
    """A hinge chain of `links` capsules 2 cm apart along x from (0, 0, 2): one chain generator, or (by_hand)
    the same bodies and joints written out one by one (the scene loads to the same specs)."""
    lines = ["simulation: {dt: 0.0005, duration: 0.01}", "gravity: [0, 0, -9.81]", "bodies:"]
    if not by_hand:
        lines += ["  - chain:", "      name: link", f"      count: {links}", "      start: [0, 0, 2]",
                  "      direction: [1, 0, 0]", "      spacing: 0.02", f"      joint: {CHAIN_JOINT}",
                  f"      template: {CHAIN_LINK}"]  # fmt: skip
    else:
        link = CHAIN_LINK[1:-1]
        lines += [f"  - {{name: link{k}, position: [{(k + 0.5) * 0.02!r}, 0, 2], {link}}}" for k in range(links)]
        lines.append("joints:")
        lines += [
            f"  - {{name: link_joint{k}, bodies: [link{k}, {f'link{k - 1}' if k else 'world'}], "
            f"anchor: [{k * 0.02!r}, 0, 2], {CHAIN_JOINT[1:]}"
            for k in range(links)
        ]
    path.write_text("\n".join(lines) + "\n")


def run_rounds(commands: dict[str, list[str]], repeats: int) -> dict[str, tuple[float, ...]]:
    """Medians of (wall [s], CPU [s], peak RSS [MB]) per command, printed with the wall time's spread."""
    results: dict[str, list[tuple[float, float, float]]] = {name: [] for name in commands}
    for command in commands.values():  # one unmeasured run each: imports and file cache warm
        measure(command)
    for round_ in range(repeats):
        order = list(commands) if round_ % 2 == 0 else list(reversed(commands))
        for name in order:
            results[name].append(measure(commands[name]))
    print(f"{platform.machine()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f}; medians of {repeats}")
    width = max(30, *(len(name) for name in commands))
    print(f"{'command':<{width}} {'wall [s]':>9} {'(min-max)':>15} {'CPU [s]':>8} {'peak RSS [MB]':>14}")
    medians = {}
    for name, runs in results.items():
        walls = [w for w, _, _ in runs]
        medians[name] = tuple(statistics.median(column) for column in zip(*runs, strict=True))
        spread = f"({min(walls):.2f}-{max(walls):.2f})"
        wall, cpu, rss = medians[name]
        print(f"{name:<{width}} {wall:>9.2f} {spread:>15} {cpu:>8.2f} {rss:>14.0f}")
    return medians


def chain_main(links: int, repeats: int) -> None:
    with tempfile.TemporaryDirectory(prefix="rbsim-bench-validate-") as folder:
        generated, by_hand = Path(folder) / "chain.yaml", Path(folder) / "chain_by_hand.yaml"
        write_chain(generated, links, by_hand=False)
        write_chain(by_hand, links, by_hand=True)
        sizes = generated.stat().st_size, by_hand.stat().st_size
        print(f"a {links:,}-link hinge chain of capsules (27 particles each): one chain generator ({sizes[0]:,} "
              f"bytes), and written out by hand ({sizes[1]:,} bytes)")  # fmt: skip
        medians = run_rounds(
            {
                "baseline: python -c pass": [sys.executable, "-c", "pass"],
                "rbsim validate (generator)": [sys.executable, "-m", "rbcli", "validate", str(generated)],
                "rbsim validate (by hand)": [sys.executable, "-m", "rbcli", "validate", str(by_hand)],
            },
            repeats,
        )
    wall, cpu, _ = medians["rbsim validate (generator)"]
    verdict = ["NOT met", "met"]
    print(f"target (generator < {CHAIN_TARGET_SECONDS:g} s): {verdict[wall < CHAIN_TARGET_SECONDS]} in wall time, "
          f"{verdict[cpu < CHAIN_TARGET_SECONDS]} in CPU time")  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--particles", type=int, default=160_000)
    parser.add_argument("--chain", type=int, default=0, metavar="LINKS", help="time a generated chain instead")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    if args.chain:
        chain_main(args.chain, args.repeats)
        return
    with tempfile.TemporaryDirectory(prefix="rbsim-bench-validate-") as folder:
        scene = Path(folder) / "cloud.yaml"
        write_scene(scene, args.particles)
        size = scene.stat().st_size
        load = "import sys, yaml; yaml.load(open(sys.argv[1], encoding='utf-8'), Loader=yaml.{})"
        print(f"{args.particles:,} explicit particles, {size / 1e6:.1f} MB scene")
        medians = run_rounds(
            {
                "baseline: yaml.safe_load": [sys.executable, "-c", load.format("SafeLoader"), str(scene)],
                "baseline: yaml CSafeLoader": [sys.executable, "-c", load.format("CSafeLoader"), str(scene)],
                "rbsim validate": [sys.executable, "-m", "rbcli", "validate", str(scene)],
            },
            args.repeats,
        )
    wall, cpu, rss = medians["rbsim validate"]
    base_wall, base_cpu, _ = medians["baseline: yaml.safe_load"]
    print(f"rbsim validate / yaml.safe_load: {wall / base_wall:.2f} in wall time, {cpu / base_cpu:.2f} in CPU time")

    def verdict(seconds: float) -> str:
        return "met" if seconds < TARGET_SECONDS and rss < TARGET_MB else "NOT met"

    target = f"< {TARGET_SECONDS:g} s and < {TARGET_MB:g} MB"
    print(f"target ({target}): {verdict(wall)} in wall time, {verdict(cpu)} in CPU time")


if __name__ == "__main__":
    main()
