"""`rbsim run` ends its process without the interpreter's teardown (rbcli/cli/app.py: `main`, ~0.2 s
of freeing numba's objects, docs/performance.md "Start-up"); nothing that can be seen changes: the exit
status, what is printed, the file, atexit handlers and the threads still running are as before."""

import subprocess
import sys
from pathlib import Path

from rbcli.record.read import read_mcap

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"

# gravity of 1e98 m/s^2 pushes |x| past the 1e100 blow-up limit after a few steps (tests/runner/test_loop.py)
DIVERGING = """\
name: blow-up
simulation: {dt: 1.0, duration: 100.0, integrator: euler-matrix}
gravity: [0, 0, -1.0e98]
bodies:
  - name: rock
    particles: {positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0]], masses: [1.0, 0.5, 0.5]}
"""

# main() as the console script runs it, with an atexit handler, a thread that is still running when the
# command ends (it prints once the run's file is in place), and an object that only teardown would delete
WITH_HANDLERS = """\
import atexit, os, sys, threading, time

class Teardown:
    def __del__(self):
        print("torn down")

kept = Teardown()
atexit.register(lambda: print("atexit handler ran"))
out = sys.argv[sys.argv.index("-o") + 1]

def late():
    while not os.path.exists(out):
        time.sleep(0.01)
    time.sleep(0.2)
    print("thread finished")

threading.Thread(target=late).start()
sys.argv = ["rbsim", "run", *sys.argv[1:]]
from rbcli.cli.app import main
main()
print("not reached")
"""


def _rbsim(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "rbcli", *args], cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_a_completed_run_exits_0_with_its_summary_and_the_whole_file(tmp_path):
    out = tmp_path / "t.mcap"
    result = _rbsim("run", str(TUTORIAL), "-o", str(out), "--duration", "0.05")
    assert result.returncode == 0, result.stderr
    assert "completed: 50 steps x 1 bodies" in result.stderr and result.stdout == ""
    assert read_mcap(out).frames == 51
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.mcap"]


def test_a_diverging_run_exits_3_and_an_invalid_one_1(tmp_path):
    scene = tmp_path / "blow_up.yaml"
    scene.write_text(DIVERGING)
    out = tmp_path / "run.mcap"
    result = _rbsim("run", str(scene), "-o", str(out), "-q")
    assert result.returncode == 3, result.stderr
    assert "diverged at step" in result.stderr and read_mcap(out).summary["status"] == "diverged"
    result = _rbsim("run", str(tmp_path / "nope.yaml"), "-o", str(tmp_path / "never.mcap"))
    assert result.returncode == 1 and "scene file not found" in result.stderr
    assert not (tmp_path / "never.mcap").exists()


def test_threads_are_joined_atexit_handlers_run_and_stdout_is_flushed(tmp_path):
    out = tmp_path / "t.mcap"
    args = [str(TUTORIAL), "-o", str(out), "--duration", "0.01", "-q"]
    result = subprocess.run(
        [sys.executable, "-c", WITH_HANDLERS, *args], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    assert result.returncode == 0, result.stderr
    # the order of the interpreter's own exit; "torn down" would be the teardown this exit skips
    assert result.stdout.splitlines() == ["thread finished", "atexit handler ran"]
    assert read_mcap(out).frames == 11


def test_other_commands_exit_as_usual():
    result = _rbsim("validate", str(TUTORIAL))
    assert result.returncode == 0 and "ok (1 body" in result.stdout
