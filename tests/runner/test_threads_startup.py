"""`rbsim run` of the tutorial's scene starts no thread pool (issue 28 item 1): numba's threading layer
is launched by the first parallel region, so a run that needs none must leave it uninitialised."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

_PROBE = """
import sys
from rbcli.cli.app import run_app
code = run_app(["run", sys.argv[1], "-o", sys.argv[2]])
assert not code, code
import numba.np.ufunc.parallel as parallel
print("POOL", bool(parallel._is_initialized))
"""


def test_tutorial_run_starts_no_thread_pool(tmp_path: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", _PROBE, str(ROOT / "scenes" / "tutorial.yaml"), str(tmp_path / "t.mcap")],
        capture_output=True,
        text=True,
        env=env,
        cwd=tmp_path,
        timeout=300,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    assert "POOL False" in out.stdout, out.stdout[-2000:]
