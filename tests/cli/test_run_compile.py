"""`rbsim run` while numba compiles a scene's kernels (issue 44), each in a fresh process on an empty
numba cache (a warm cache compiles nothing, so it could not tell):

- the compile is announced when numba really compiles (its compile events), not when loading the kernels
  from the cache merely takes a while (the 0.5 s timer of before said "compiling kernels (first run
  only)" on warm runs whose load took longer);
- SIGINT or SIGTERM during the compile ends the command with 130 / 143 and one line, writes no output,
  and leaves numba's cache whole: every index names data files that exist and unpickle, no temporary file
  is left, and the next run on that cache completes with the states `rbcli.simulate` computes, bit for
  bit (a Ctrl-C there used to end in numba's `RuntimeError: no compiled object yet for <Library ...>`
  after a traceback of some 300 lines, exit 1).

The scene is one body with the euler-matrix loop, the cheapest to compile (~4 s, 12 functions)."""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import rbcli
from rbcli.record.read import read_mcap

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

# `rbsim run ...` sent SIGINT from inside the ctypes callback in which LLVM hands numba the object code of a
# function it will cache (numba's CPUCodeLibrary._object_compiled_hook): where a Ctrl-C that came during
# LLVM's work is handled. A KeyboardInterrupt raised there was dropped by ctypes, the function's save then
# failed with `RuntimeError: no compiled object yet for <Library ...>` (164 lines, exit 1, with this scene)
IN_THE_CALLBACK = (
    "import os, signal, sys; from numba.core import codegen; hook = codegen.CPUCodeLibrary._object_compiled_hook; "
    "sent = []\n"
    "def hook_with_a_signal(cls, ll_module, buf):\n"
    "    library = getattr(ll_module, '_CPUCodeLibrary__library', None)\n"
    "    if not sent and getattr(library, '_object_caching_enabled', False):\n"
    "        sent.append(os.kill(os.getpid(), signal.SIGINT))\n"
    "    hook(ll_module, buf)\n"
    "codegen.CPUCodeLibrary._object_compiled_hook = classmethod(hook_with_a_signal)\n"
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
    assert lines[0].startswith(COMPILING) and "rbcli.physics.chunk_loop.run_chunk[euler_matrix]" in lines[0], stderr
    # then what it compiled: the chunk loop and what it calls, and the recording's derive_outputs
    assert lines[1].startswith("compiled kernels: ") and int(lines[1].split()[2]) >= 2, stderr
    assert lines[2].startswith("completed: 100 steps") and len(lines) == 3, stderr

    warm = rbsim(cache, "run", str(SCENE), "-o", str(out), "--duration", DURATION, python=("-c", SLOW_LOAD))
    _, stderr = warm.communicate(timeout=300)
    assert warm.returncode == 0, stderr
    assert stderr.startswith("completed: 100 steps") and len(stderr.splitlines()) == 1, stderr


def cache_problems(cache: Path) -> list[str]:
    """What is wrong with a numba cache folder: an index naming a data file that is missing or does not
    unpickle (numba would fail to rebuild it, or take it for a miss), a temporary file left by a cut write."""
    problems = [f"left over: {path.name}" for path in cache.rglob("*.tmp.*")]
    for index in cache.rglob("*.nbi"):
        with open(index, "rb") as f:
            pickle.load(f)  # numba's version
            _, overloads = pickle.loads(f.read())
        for name in overloads.values():
            data = index.parent / name
            try:
                pickle.loads(data.read_bytes())
            except Exception as exc:  # noqa: BLE001 - any failure is the finding
                problems.append(f"{index.name} -> {name}: {type(exc).__name__}: {exc}")
    return problems


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)], ids=["INT", "TERM"])
def test_a_stop_signal_while_compiling_exits_cleanly_and_the_next_run_completes(tmp_path, signum, status):
    cache, out = tmp_path / "cache", tmp_path / "out" / "run.mcap"
    run = rbsim(cache, "run", str(SCENE), "-o", str(out), "--duration", DURATION)
    assert run.stderr is not None
    first = run.stderr.readline()  # stderr is a pipe: the line printed when numba starts compiling
    assert first.startswith(COMPILING), first + run.communicate()[1]
    deadline = time.monotonic() + 60.0
    while not list(cache.rglob("*.nbc")):  # stopped with some functions compiled and saved, others not yet
        assert run.poll() is None and time.monotonic() < deadline, "the compile ended before any was saved"
        time.sleep(0.005)
    started = time.monotonic()
    run.send_signal(signum)
    _, rest = run.communicate(timeout=120)
    assert run.returncode == status, first + rest
    assert time.monotonic() - started < 10.0  # the next compile event, not the end of the compile
    name = signal.Signals(signum).name
    assert rest.splitlines() == [
        f"stopped by {name} while compiling kernels (those finished are cached for the next run); nothing written"
    ], rest
    assert not out.parent.exists() or list(out.parent.iterdir()) == []  # no output, no partial
    assert cache_problems(cache) == []

    again = rbsim(cache, "run", str(SCENE), "-o", str(out), "--duration", DURATION, "-q")
    _, stderr = again.communicate(timeout=300)
    assert again.returncode == 0 and stderr == "", stderr
    assert cache_problems(cache) == []
    recorded, expected = read_mcap(out), rbcli.simulate(SCENE, duration=float(DURATION))
    assert recorded.step.tolist() == expected.step.tolist() == list(range(101))
    for quantity in ("x", "q", "P", "L"):  # MCAP stores float64: bit for bit
        assert np.array_equal(getattr(recorded, quantity), getattr(expected, quantity)), quantity


def test_a_signal_inside_llvms_object_code_callback_still_ends_the_run_cleanly(tmp_path):
    cache, out = tmp_path / "cache", tmp_path / "out" / "run.mcap"
    run = rbsim(cache, "run", str(SCENE), "-o", str(out), "--duration", DURATION, python=("-c", IN_THE_CALLBACK))
    _, stderr = run.communicate(timeout=300)
    lines = stderr.splitlines()
    assert run.returncode == 130, stderr
    assert len(lines) == 2 and lines[0].startswith(COMPILING) and lines[1].startswith("stopped by SIGINT"), stderr
    assert not out.parent.exists()
    assert cache_problems(cache) == []
    again = rbsim(cache, "run", str(SCENE), "-o", str(out), "--duration", DURATION, "-q")
    _, stderr = again.communicate(timeout=300)
    assert again.returncode == 0 and stderr == "" and read_mcap(out).frames == 101, stderr
