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


_LARGE = """
name: many
simulation: {dt: 0.001, duration: 0.05, integrator: split2, record: {every: 10}}
gravity: [0, 0, -9.81]
bodies:
  - grid:
      name: b
      count: [20, 15, 1]
      spacing: [1.0, 1.0, 1.0]
      jitter: [0.1, 0.1, 0.1]
      seed: 2
      template:
        particles: {positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]], masses: [1, 0.5, 0.5, 0.25]}
        angular_momentum: [0.01, 0.02, 0.03]
"""

_THREADED_PROBE = """
import sys
from rbcli.cli.app import run_app
for threads, out in (("2", sys.argv[2]), ("1", sys.argv[3])):
    code = run_app(["run", sys.argv[1], "-o", out, "--threads", threads, "--quiet"])
    assert not code, code
import numba.np.ufunc.parallel as parallel
print("POOL", bool(parallel._is_initialized))
"""


def test_a_large_scene_runs_on_threads_with_the_bits_of_one_thread(tmp_path: Path) -> None:
    """In a fresh process (the threaded kernel loaded from numba's cache through kernel_cache's fast
    path, or compiled): `--threads 2` on 300 bodies starts the pool, and its log equals `--threads 1`'s."""
    import numpy as np

    from rbcli.record.read import read_recording

    scene = tmp_path / "many.yaml"
    scene.write_text(_LARGE)
    two, one = tmp_path / "two.mcap", tmp_path / "one.mcap"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop("RBSIM_THREADS", None)
    out = subprocess.run([sys.executable, "-c", _THREADED_PROBE, str(scene), str(two), str(one)],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)  # fmt: skip
    assert out.returncode == 0, out.stderr[-2000:]
    assert "POOL True" in out.stdout, out.stdout[-2000:]
    a, b = read_recording(two), read_recording(one)
    assert a.x.shape == (6, 300, 3)
    for name in ("x", "q", "P", "L"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


def test_a_bad_thread_count_is_a_usage_error(tmp_path: Path) -> None:
    from rbcli.cli.app import run_app

    assert (
        run_app(["run", str(ROOT / "scenes" / "tutorial.yaml"), "--threads", "none", "-o", str(tmp_path / "t.mcap")])
        == 2
    )
    assert not (tmp_path / "t.mcap").exists()
