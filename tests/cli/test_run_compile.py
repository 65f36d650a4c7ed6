"""`rbsim run` while numba compiles a scene's kernels (issue 44), each in a fresh process on an empty
numba cache (a warm cache compiles nothing, so it could not tell): the compile is announced when numba
really compiles (its compile events), not when loading the kernels from the cache merely takes a while
(the 0.5 s timer of before said "compiling kernels (first run only)" on warm runs whose load took longer).

The scene is one body with the euler-matrix loop, the cheapest to compile (~4 s, 12 functions)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "tumbling_plate.yaml"  # one body, euler-matrix
DURATION = "1.0"  # 100 steps: the run after the compile is instant
COMPILING = "compiling kernels"
# `rbsim run ...` with the kernels' load (Simulation.advance of zero steps, which the load makes whether the
# kernels come from the cache or are compiled) taking a second longer: a slow load on a busy machine
SLOW_LOAD = (
    "import sys, time; from rbcli.runner.simulation import Simulation; advance = Simulation.advance; "
    "Simulation.advance = lambda self, n, *a: (time.sleep(1.0) if n == 0 else None, advance(self, n, *a))[1]; "
    "from rbcli.cli.app import main; sys.argv[0] = 'rbsim'; main()"
)


def rbsim(cache: Path, *args: str, python: tuple[str, ...] = ("-m", "rbcli")) -> subprocess.Popen:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    return subprocess.Popen([sys.executable, *python, *args], cwd=ROOT, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip


def test_the_compile_is_announced_only_when_numba_compiles(tmp_path):
    cache, out = tmp_path / "cache", tmp_path / "run.mcap"
    cold = rbsim(cache, "run", str(SCENE), "-o", str(out), "--duration", DURATION)
    _, stderr = cold.communicate(timeout=300)
    assert cold.returncode == 0, stderr
    lines = stderr.splitlines()
    assert lines[0].startswith(COMPILING) and "rbcli.physics.chunks.euler_matrix.run_chunk" in lines[0], stderr
    # then what it compiled: the chunk loop and what it calls, and the recording's derive_outputs
    assert lines[1].startswith("compiled kernels: ") and int(lines[1].split()[2]) >= 2, stderr
    assert lines[2].startswith("completed: 100 steps") and len(lines) == 3, stderr

    warm = rbsim(cache, "run", str(SCENE), "-o", str(out), "--duration", DURATION, python=("-c", SLOW_LOAD))
    _, stderr = warm.communicate(timeout=300)
    assert warm.returncode == 0, stderr
    assert stderr.startswith("completed: 100 steps") and len(stderr.splitlines()) == 1, stderr
