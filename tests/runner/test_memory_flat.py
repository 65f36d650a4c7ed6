"""Peak memory of `rbsim run` does not grow with the run's length: frames stream to the file in blocks.

A real `rbsim run` subprocess of 10 tumbling bodies recording every step, at 4,000 and 40,000 steps, to
.mcap and to .rrd; its peak resident set size comes from the kernel (`os.wait4`'s rusage of that child,
started by a small launcher, so the test process's own size does not count). The long run's states
alone are 40,000 x 10 x 13 x 8 B = 42 MB (the .mcap is ~50 MB): a run that kept its frames would grow by
at least that much, so the bound on the growth, 20 MiB, is generous (measured: +2.5 MiB for .mcap,
+3.1 MiB for .rrd) and still fails such a run. The control shows that the measurement sees such growth:
`rbcli.simulate`, which keeps every frame in memory by design, grows by more than the bound over the
same two lengths (+112 MiB). ~12 s.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BODIES = 10
SHORT, LONG = 4_000, 40_000
GROWTH_BOUND_BYTES = 20 * 2**20
SCENE = f"""\
name: long-run
simulation: {{dt: 0.001, steps: {SHORT}, integrator: split2}}
bodies:
  - random:
      name: r
      count: {BODIES}
      seed: 1
      box: {{min: [0, 0, 0], max: [1, 1, 1]}}
      velocity_sigma: 0.1
      random_orientation: true
      template:
        particles: {{positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], masses: 1}}
        angular_velocity: [1, 2, 3]
"""


# Linux counts the resident set a process had before exec in its peak (ru_maxrss), and a forked child
# starts with its parent's: children of the test process (hundreds of MB after a few tests) would all peak
# at its size. So a small Python process starts the command and reports that grandchild's own peak.
LAUNCHER = """
import os, subprocess, sys
with open(os.devnull, "w") as out:
    process = subprocess.Popen(sys.argv[1:], stdout=out, stderr=sys.stderr)
    _, status, usage = os.wait4(process.pid, 0)
print(os.waitstatus_to_exitcode(status), usage.ru_maxrss)
"""


def peak_rss_bytes(args: list[str]) -> int:
    """Peak resident set size of a command's own process [bytes] (Linux reports ru_maxrss in KiB)."""
    result = subprocess.run([sys.executable, "-c", LAUNCHER, *args], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    code, kib = map(int, result.stdout.split())
    assert code == 0, result.stderr
    return kib * 1024


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("long") / "long.yaml"
    path.write_text(SCENE)
    return path


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ru_maxrss units and wait4 as on Linux")
@pytest.mark.parametrize("suffix", [".mcap", ".rrd"])
def test_peak_memory_of_a_run_does_not_grow_with_its_length(scene, tmp_path, suffix):
    peaks = {}
    for steps in (SHORT, LONG):
        output = tmp_path / f"run{steps}{suffix}"
        command = [sys.executable, "-m", "rbcli", "run", str(scene), "--duration", str(steps * 1e-3), "-o", str(output)]
        peaks[steps] = peak_rss_bytes([*command, "-q"])
        assert output.stat().st_size > 0
        output.unlink()  # ~50 MB each
    growth = peaks[LONG] - peaks[SHORT]
    assert growth < GROWTH_BOUND_BYTES, f"peak RSS {peaks[SHORT] / 2**20:.1f} -> {peaks[LONG] / 2**20:.1f} MiB"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ru_maxrss units and wait4 as on Linux")
def test_the_measurement_sees_a_run_that_keeps_its_frames(scene):
    """Control: rbcli.simulate returns every frame (an in-memory Trajectory), so its peak grows with length."""
    peaks = {}
    for steps in (SHORT, LONG):
        code = f"import rbcli; t = rbcli.simulate({str(scene)!r}, duration={steps * 1e-3}); assert len(t.t) > {steps}"
        peaks[steps] = peak_rss_bytes([sys.executable, "-c", code])
    assert peaks[LONG] - peaks[SHORT] > GROWTH_BOUND_BYTES, f"{peaks[SHORT] / 2**20:.1f} -> {peaks[LONG] / 2**20:.1f}"
