"""`rbsim run` (in-process, Typer's CliRunner) on generated scenes and generated command-line options.

- Valid tiny scenes run to completion (exit 0) and the .mcap holds exactly what `rbcli.simulate` gives.
- Broken scenes are refused before any work: exit 1, every error line located (`file:line:col: error:`),
  nothing written.
- Options (dt, duration, integrator, record-every, tolerance, compression, output path and format, each
  valid or hostile: NaN, inf, 0, negative, 1e-300, text, a folder, an unwritable place) end in a
  documented exit code with a message and never a traceback; a refused run writes nothing.
Scenes here use two integrators and no force terms so a cold numba cache compiles few kernels;
benchmarks/fuzz_long.py runs every integrator, force type and contact. ~20 s with a warm cache.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from fuzz_cases import (
    LOCATED,
    TINY,
    broken_scene,
    check_command,
    ci_settings,
    dump,
    planned_steps,
    run_arguments,
    valid_scene,
)
from hypothesis import assume, given
from typer.testing import CliRunner

import rbcli
from rbcli.cli.app import app

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")  # no numpy warning may reach a terminal
CI_SCENES = dict(forces=False, contact=False, integrators=("split2", "dopri5"))


def files_in(folder: Path) -> set[Path]:
    return {p for p in folder.rglob("*") if p.is_file()}


@ci_settings(15)
@given(valid_scene(**CI_SCENES))
def test_valid_generated_scenes_run_and_record_what_simulate_gives(scene):
    with tempfile.TemporaryDirectory() as folder:
        path, output = Path(folder) / "scene.yaml", Path(folder) / "out.mcap"
        path.write_text(dump(scene), encoding="utf-8", errors="surrogatepass")
        result = CliRunner().invoke(app, ["run", str(path), "-o", str(output), "-q"])
        check_command(result, codes={0})
        recorded = rbcli.read_recording(output)
        expected = rbcli.simulate(path)
        assert recorded.status == "completed"
        np.testing.assert_array_equal(recorded.step, expected.step)
        np.testing.assert_array_equal(recorded.x, expected.x)  # float64 in .mcap: bitwise
        np.testing.assert_array_equal(recorded.q, expected.q)


@ci_settings(30)
@given(broken_scene(**CI_SCENES))
def test_broken_generated_scenes_are_refused_located_and_write_nothing(text):
    with tempfile.TemporaryDirectory() as folder:
        path, output = Path(folder) / "scene.yaml", Path(folder) / "out.mcap"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        result = CliRunner().invoke(app, ["run", str(path), "-o", str(output), "-q"])
        check_command(result, codes={0, 1, 3})
        if result.exit_code == 1:
            errors = [line for line in result.stderr.splitlines() if "error:" in line]
            assert errors, result.stderr
            for line in errors:
                match = LOCATED.match(line)
                assert match and match["file"] == str(path), line
            assert files_in(Path(folder)) == {path}, "a refused run wrote a file"


@ci_settings(60)
@given(run_arguments())
def test_run_options_end_in_a_documented_exit_code(args):
    # a plan between 2e4 steps and the 1e10 body-step bound would run (minutes): not a fuzz case
    assume(not 2e4 < planned_steps(args, 1e-3, 1e-2) <= 1e10)
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        (folder / "scene.yaml").write_text(TINY)
        (folder / "file.txt").write_text("not a folder")
        (folder / "existing_dir").mkdir()
        before = files_in(folder)
        at = args.index("-o") + 1
        if args[at] and not args[at].startswith("/"):
            args[at] = str(folder / args[at])
        result = CliRunner().invoke(app, ["run", str(folder / "scene.yaml"), *args, "-q"])
        check_command(result)
        if result.exit_code in (1, 2):
            assert files_in(folder) == before, f"a refused run wrote a file: {result.stderr}"
