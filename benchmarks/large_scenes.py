"""Large inputs (issue 17, item 8): wall time and peak memory of `rbsim validate` and `rbsim run` on
scenes of 10^6 particles, of a scene file just under the 10 MB limit, and of a 50 MB scene file (refused).

    python benchmarks/large_scenes.py            # ~1-2 min on a 2-core machine with a warm kernel cache

Each command is a child process; its peak resident set size comes from `os.wait4` (the kernel's
accounting of that child alone). Prints one row per case; docs/robustness.md ("Long and large") has the
numbers of a run.
"""

from __future__ import annotations

import argparse
import os
import random
import subprocess
import sys
import tempfile
import time
from pathlib import Path

GRID = """\
name: million-grid
simulation: {dt: 0.001, steps: 10, integrator: split2}
bodies:
  - grid:
      name: box
      count: [10, 10, 10]
      spacing: 1.0
      template: {shape: {type: box, size: [0.1, 0.1, 0.1]}, spacing: 0.01, density: 1000}
"""
ONE_BODY = """\
name: million-one
simulation: {dt: 0.001, steps: 10, integrator: split2}
bodies:
  - name: block
    shape: {type: box, size: [1.0, 1.0, 1.0]}
    spacing: 0.01
    density: 1000
"""


def explicit_scene(path: Path, size_bytes: int, seed: int = 0) -> int:
    """A scene of one body with explicit particles whose file is about `size_bytes` long; returns the count."""
    rng = random.Random(seed)
    count = 0
    with open(path, "w") as out:
        out.write("name: explicit\nsimulation: {dt: 0.001, steps: 10}\nbodies:\n  - name: b\n")
        out.write("    particles:\n      masses: 1.0\n      positions:\n")
        written = out.tell()
        while written < size_bytes - 100:
            line = f"        - [{rng.random():.15f}, {rng.random():.15f}, {rng.random():.15f}]\n"
            out.write(line)
            written += len(line)
            count += 1
    return count


def measure(args: list[str]) -> tuple[int, float, float, float, str]:
    """(exit status, wall time [s], CPU time [s], peak RSS [MiB], last line of its output) of one child
    process (CPU time: user + system, what a loaded machine does not inflate)."""
    with tempfile.TemporaryFile() as out:
        started = time.perf_counter()
        process = subprocess.Popen(args, stdout=out, stderr=subprocess.STDOUT)
        _, status, usage = os.wait4(process.pid, 0)
        wall = time.perf_counter() - started
        out.seek(0)
        lines = out.read().decode(errors="replace").strip().splitlines()
    cpu = usage.ru_utime + usage.ru_stime
    return os.waitstatus_to_exitcode(status), wall, cpu, usage.ru_maxrss / 1024, (lines or [""])[-1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--skip-under-limit", action="store_true", help="skip the 9.9 MB explicit scene")
    args = parser.parse_args()
    rbsim = [sys.executable, "-m", "rbcli"]
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        (folder / "grid.yaml").write_text(GRID)
        (folder / "one.yaml").write_text(ONE_BODY)
        cases = [
            ("10^6 particles, 1,000 bodies: validate", [*rbsim, "validate", str(folder / "grid.yaml")]),
            ("  run 10 steps to .mcap", [*rbsim, "run", str(folder / "grid.yaml"), "-o", f"{name}/g.mcap", "-q"]),
            ("  run 10 steps to .rrd", [*rbsim, "run", str(folder / "grid.yaml"), "-o", f"{name}/g.rrd", "-q"]),
            ("10^6 particles, 1 body: validate", [*rbsim, "validate", str(folder / "one.yaml")]),
            ("  run 10 steps to .mcap", [*rbsim, "run", str(folder / "one.yaml"), "-o", f"{name}/o.mcap", "-q"]),
            ("  run 10 steps to .rrd", [*rbsim, "run", str(folder / "one.yaml"), "-o", f"{name}/o.rrd", "-q"]),
        ]
        count = explicit_scene(folder / "big50.yaml", 50 * 2**20)
        cases.append(
            (f"50 MB file ({count:,} explicit particles): validate", [*rbsim, "validate", f"{name}/big50.yaml"])
        )
        cases.append(("  run", [*rbsim, "run", f"{name}/big50.yaml", "-o", f"{name}/b.mcap", "-q"]))
        if not args.skip_under_limit:
            count = explicit_scene(folder / "big9.yaml", int(9.9 * 2**20))
            label = f"9.9 MB file ({count:,} explicit particles): validate"
            cases.append((label, [*rbsim, "validate", f"{name}/big9.yaml"]))
        print(f"{'case':58s} {'exit':>4s} {'wall [s]':>9s} {'CPU [s]':>8s} {'peak RSS [MiB]':>15s}  last line")
        for label, command in cases:
            code, wall, cpu, rss, last = measure(command)
            print(f"{label:58s} {code:4d} {wall:9.2f} {cpu:8.2f} {rss:15.0f}  {last[:150]}", flush=True)


if __name__ == "__main__":
    main()
