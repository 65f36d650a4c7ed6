"""The suite's own plumbing (tests/conftest.py): an xdist worker that is slow to finish its session ends
without a KeyboardInterrupt traceback on the suite's stderr."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
# the suite's sessionfinish hook, and a worker whose end outlasts execnet's 5 s grace inside a garbage
# collection's callback, as the suite's workers do in full collections (hypothesis's gc_callback is where
# the stray KeyboardInterrupt was printed): Python swallows and prints an exception raised there
SLOW_WORKER_END = """\
import gc
import importlib.util
import time

spec = importlib.util.spec_from_file_location("rbsim_tests_conftest", {conftest!r})
suite = importlib.util.module_from_spec(spec)
spec.loader.exec_module(suite)
pytest_sessionfinish = suite.pytest_sessionfinish


def slow_collection(phase, info):
    if phase == "start":
        time.sleep(6.0)


def pytest_unconfigure(config):
    if hasattr(config, "workerinput"):
        gc.callbacks.append(slow_collection)
        try:
            gc.collect()
        finally:
            gc.callbacks.remove(slow_collection)
"""


@pytest.mark.slow
def test_execnets_shutdown_interrupt_does_not_reach_a_finished_worker(tmp_path):
    (tmp_path / "test_one.py").write_text("def test_one():\n    pass\n")
    (tmp_path / "conftest.py").write_text(SLOW_WORKER_END.format(conftest=str(ROOT / "tests" / "conftest.py")))
    # EXECNET_DEBUG=2: execnet traces to stderr, so the test sees that it did send its SIGINT
    env = {**os.environ, "PYTHONPATH": str(ROOT), "EXECNET_DEBUG": "2"}
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-n", "1", "-p", "no:cacheprovider", "test_one.py"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    output = done.stdout + done.stderr
    assert done.returncode == 0, output
    assert "sending ourselves a SIGINT" in done.stderr, output  # the worker's end did outlast the grace
    assert "KeyboardInterrupt" not in output, output
