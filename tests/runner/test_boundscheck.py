"""The step kernels under numba's bounds checking at the frame-buffer edges (benchmarks/boundscheck_kernels.py).

Compiled kernels do not check indices: at 40,330 bodies a one-frame buffer was written past its end and
the heap corrupted without an error. The script recompiles the kernels with NUMBA_BOUNDSCHECK=1 in a
fresh cache, so an out-of-bounds index raises IndexError, and runs split2 and adaptive dopri5 with frame
buffers of 1 and 2 frames (runs of 2c-1 ... 2c frames, record_every 1 and 3) to memory, .mcap and .rrd,
each compared bit for bit with the run at the default capacity. Reverting the runner's hand-over of a
full buffer, or the kernel's own guard, makes it fail with an IndexError (checked when it was written).
~25 s with a cold cache on a 2-core machine, nearly all of it compiling the two integrators.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

SCRIPT = Path(__file__).resolve().parents[2] / "benchmarks" / "boundscheck_kernels.py"


def test_quick_boundscheck_passes():
    out = subprocess.run(
        [sys.executable, str(SCRIPT), "--quick"], capture_output=True, text=True, timeout=300, cwd=SCRIPT.parents[1]
    )
    log = out.stdout + out.stderr
    assert out.returncode == 0, log[-6000:]
    # the run really was bounds-checked and covered both integrators at both capacities
    assert "NUMBA_BOUNDSCHECK=1, fresh cache" in out.stdout
    for case in ("edge split2 cap=1", "edge split2 cap=2", "edge dopri5-adaptive cap=1", "edge dopri5-adaptive cap=2"):
        assert case in out.stdout, case
    assert " FAIL " not in out.stdout
