"""The command line's conventions (issue 20), through real processes whose stderr is a pipe, as in CI and
editors: every error is one line `path:line:col: error: what; expected what` (or `error: ...`) on stderr,
never wrapped (a path longer than 100 characters stays on its line), never Rich markup or colour, with
the exit status of cli/exit_codes.py; colour only on a terminal; `rbsim` alone prints help and exits 0;
`rbsim integrators` imports no kernel; `rbsim info --json` parses and labels drift and change.

Most cases run in one child process (`rbcli.cli.app.run_app`, what `rbsim` runs, once per case, with a
marker line after each on both streams), since a process start costs ~1 s here.
"""

from __future__ import annotations

import ast
import json
import os
import pty
import re
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rbcli.cli.exit_codes import ExitCode, exit_code_lines, exit_code_markdown

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"
# one diagnostic line: an optional location (path, or path:line:col), the severity, the text
DIAGNOSTIC = re.compile(r"^(?:(?P<where>.+?): )?(?P<severity>error|warning): \S.*$")
MARKUP = ("[red", "[/", "[yellow", "[bold", "\x1b[")
DRIVER = """\
import json, sys
from rbcli.cli.app import run_app
for args in json.loads(sys.argv[1]):
    code = run_app(args)
    sys.stdout.write("@@end\\n"); sys.stdout.flush()
    sys.stderr.write(f"@@end {code}\\n"); sys.stderr.flush()
"""
BAD_SCENE = """\
simulation: {dt: 0.001, durtion: 1.0}
bodies:
  - name: a
    particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0]], masses: [1, 1, -1]}
forces:
  - {type: sprin, body: a, anchor: [0, 0, 0], stiffness: 1}
"""


def child_env(**extra: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NO_COLOR", "FORCE_COLOR")}
    env.update(COLUMNS="80", TERM="xterm-256color", PYTHONPATH=str(ROOT), **extra)
    return env


def run_cases(cases: list[list[str]]) -> list[tuple[int, str, str]]:
    """(exit status, stdout, stderr) of each command line, run one after another in one child process."""
    done = subprocess.run(
        [sys.executable, "-c", DRIVER, json.dumps(cases)],
        capture_output=True, text=True, cwd=ROOT, env=child_env(), timeout=300,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    outs = done.stdout.split("@@end\n")[:-1]
    errs = re.split(r"^@@end (-?\d+)\n", done.stderr, flags=re.MULTILINE)  # text, code, text, code, ...
    assert len(outs) == len(cases) == (len(errs) - 1) // 2, done.stderr
    return [(int(errs[2 * i + 1]), outs[i], errs[2 * i]) for i in range(len(cases))]


@pytest.fixture(scope="module")
def deep(tmp_path_factory) -> Path:
    """A folder whose path is longer than 100 characters (errors naming it must not wrap at 80 columns)."""
    folder = tmp_path_factory.mktemp("cli") / ("a-rather-long-folder-name-" * 3) / ("and-another-one-" * 3)
    folder.mkdir(parents=True)
    assert len(str(folder)) > 100
    (folder / "bad.yaml").write_text(BAD_SCENE)
    (folder / "junk.mcap").write_bytes(b"not an mcap file at all")
    return folder


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    from rbcli.api import prepare, run_to_file

    out = tmp_path_factory.mktemp("rec") / "tutorial.mcap"
    run_to_file(prepare(TUTORIAL, duration=0.2), out)
    return out


def error_cases(deep: Path) -> list[tuple[list[str], int, list[str]]]:
    """(command line, exit status, texts its stderr must hold) for every error path of issue 20."""
    tut, bad, missing = str(TUTORIAL), str(deep / "bad.yaml"), str(deep / "missing.yaml")
    out = str(deep / "out.mcap")
    invalid, usage = ExitCode.INVALID, ExitCode.USAGE
    return [
        (["run", tut, "-o", str(deep / "x.txt")], invalid,
         [f"error: --output '{deep / 'x.txt'}': unknown format '.txt'; expected a file name ending in .mcap or .rrd"]),
        (["run", tut, "-o", str(deep / "x.mcp")], invalid, [f"(did you mean {deep / 'x.mcap'}?)"]),
        (["run", tut, "-o", out, "--integrator", "nope"], invalid,
         ["error: --integrator 'nope': unknown integrator; expected one of euler-matrix, "]),
        (["run", tut, "-o", out, "--integrator", "rk5"], invalid, ["unknown integrator (did you mean 'rk4'?)"]),
        (["run", tut, "-o", out, "--compression", "gzip"], invalid,
         ["error: --compression 'gzip': unknown compression; expected one of zstd, lz4, none"]),
        (["run", tut, "-o", out, "--compression", "zst"], invalid, ["(did you mean 'zstd'?)"]),
        (["run", tut, "-o", out, "--tolerance", "1e-6"], invalid,
         ["error: --tolerance 1e-06: a tolerance needs an adaptive integrator"]),
        (["run", missing], invalid, [f"error: scene file not found: {missing}; expected a path to a YAML scene file"]),
        (["run", bad, "-o", out], invalid,
         [f"{bad}:1:25: error: simulation.durtion: unknown key 'durtion'",
          f"{bad}:4:78: error: bodies[0].particles.masses[2]: -1 is out of range; expected a value > 0"]),
        (["validate", bad], invalid, [f"{bad}:6:12: error: forces[0].type: unknown type 'sprin'", "'spring'?"]),
        (["validate", missing], invalid, [f"{missing}: error: scene file does not exist; expected"]),
        (["info", missing], invalid, [f"error: recording not found: {missing}"]),
        (["info", str(deep / "junk.mcap")], invalid, [f"error: cannot read {deep / 'junk.mcap'}: "]),
        (["replay", missing], invalid, [f"error: recording not found: {missing}"]),
        (["replay", bad], invalid, [f"error: {bad}: not a recording; expected a .mcap or .rrd file"]),
        (["replay", str(deep / "junk.mcap"), "--save", str(deep / "x.rdd")], invalid,
         [f"error: --save '{deep / 'x.rdd'}': unknown format (did you mean {deep / 'x.rrd'}?)"]),
        (["replay", str(deep / "junk.mcap"), "--save", str(deep / "junk.mcap" / "y.rrd")], invalid,
         [f"error: --save '{deep / 'junk.mcap' / 'y.rrd'}': '{deep / 'junk.mcap'}' is a file, not a folder"]),
        (["replay", str(deep / "junk.mcap"), "--save", "/proc/rbsim-none/y.rrd"], invalid,
         ["error: --save '/proc/rbsim-none/y.rrd': cannot create files in '/proc'"]),
        (["recover", str(deep / "junk.mcap"), "-o", str(deep / "x.mcp")], invalid,
         [f"(did you mean {deep / 'x.mcap'}?)"]),
        (["recover", str(deep / "junk.mcap"), "-o", out, "--compression", "lz5"], invalid,
         ["error: --compression 'lz5': unknown compression (did you mean 'lz4'?)"]),
        (["sweep", missing], invalid, [f"error: sweep file not found: {missing}"]),
        (["study", missing], invalid, [f"error: scene file not found: {missing}"]),
        (["study", tut, "-i", "rk5", "--quick", "--out", str(deep / "study")], invalid,
         ["error: unknown integrator 'rk5' (did you mean 'rk4'?); known: euler-matrix, "]),
        (["run"], usage, ["error: no scene to run; expected a SCENE, or --resume LOG to continue a stopped run"]),
        (["run", tut, "--resume", out], usage,
         ["error: --resume continues the run as its log recorded it; drop SCENE"]),
        (["validate"], usage, ["error: Missing argument 'FILE'; expected rbsim validate [OPTIONS] {FILE}..."]),
        (["run", tut, "--dt", "abc"], usage, ["error: Invalid value for '--dt'"]),
        (["run", tut, "--bogus"], usage, ["error: No such option: --bogus"]),
        (["rnu"], usage, ["error: No such command 'rnu'", "Did you mean 'run'?"]),
    ]  # fmt: skip


def test_every_error_is_one_plain_unwrapped_line_on_stderr_with_its_exit_status(deep):
    cases = error_cases(deep)
    results = run_cases([args for args, _, _ in cases])
    for (args, status, texts), (code, out, err) in zip(cases, results, strict=True):
        assert code == status, (args, code, err)
        lines = err.splitlines()
        assert lines, args
        for line in lines:  # every line a diagnostic, none a fragment of a wrapped one
            assert DIAGNOSTIC.match(line), (args, line)
        for text in texts:
            assert any(text in line for line in lines), (args, text, err)
        for mark in MARKUP:
            assert mark not in err and mark not in out, (args, mark, err)
        assert "error:" not in out and "Traceback" not in err, (args, out, err)


def test_help_shows_units_defaults_flags_and_exit_codes_and_completion(deep):
    (code, root_help, _), (run_code, run_help, _) = run_cases([["--help"], ["run", "--help"]])
    # the shell named, not detected from the parent processes (which a detached CI job may not show):
    # typer's own switch for that, under which --show-completion takes the shell as its value
    env = child_env(_TYPER_COMPLETE_TEST_DISABLE_SHELL_DETECTION="1")
    shown = subprocess.run([sys.executable, "-m", "rbcli", "--show-completion", "bash"], capture_output=True,
                           text=True, cwd=ROOT, env=env, timeout=300)  # fmt: skip
    assert code == run_code == shown.returncode == ExitCode.OK, shown.stderr
    for line in exit_code_lines():
        assert line in root_help
    assert "--install-completion" in root_help and "_RBSIM_COMPLETE" in shown.stdout
    # every option of run says its unit or default; flags take no value
    assert "--dt SECONDS" in run_help and "Time step [s] [default: the scene's]" in run_help
    assert "[default: the scene's, else zstd]" in " ".join(run_help.split())
    assert "<bool>" not in run_help and "--allow-large " in run_help and "--quiet " in run_help
    for mark in MARKUP:
        assert mark not in root_help + run_help


def test_completion_offers_commands_and_closed_sets():
    env = child_env(_RBSIM_COMPLETE="complete_bash", COMP_WORDS="rbsim run x.yaml --integrator spl", COMP_CWORD="4")
    done = subprocess.run([sys.executable, "-m", "rbcli"], capture_output=True, text=True, env=env, cwd=ROOT)
    assert done.returncode == 0 and done.stdout.split() == ["split2", "split4"], done.stderr


def test_rbsim_alone_prints_help_and_exits_0():
    done = subprocess.run([sys.executable, "-m", "rbcli"], capture_output=True, text=True, env=child_env(), cwd=ROOT)
    assert done.returncode == 0 and done.stdout.startswith("Usage: rbsim ") and done.stderr == ""


def test_integrators_lists_without_importing_a_kernel_and_never_cuts_the_table():
    code = (
        "import sys\nfrom rbcli.cli.app import run_app\nstatus = run_app(['integrators'])\n"
        "print('heavy:', sorted(m for m in ('numba', 'rbcli.runner.study', 'rerun') if m in sys.modules))\n"
        "sys.exit(status)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=child_env(), cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "heavy: []"  # nothing measured, nothing compiled
    from rbcli.api import list_integrators

    rows = {line.split()[0]: line for line in done.stdout.splitlines()[3:-1]}
    for info in list_integrators():  # every cell whole, however wide the line (pipes are not 80 columns)
        assert info.name in rows and info.conserves in rows[info.name]
    assert "…" not in done.stdout and "ns/body-step" not in done.stdout


def test_integrators_measure_times_every_integrator(monkeypatch):
    # the timing itself compiles every kernel (a minute with a cold cache); here: that --measure asks for
    # one timing per integrator and prints it in its own column
    import rbcli.runner.study as study
    from rbcli.api import list_integrators
    from rbcli.cli.app import app

    timed: list[str] = []
    monkeypatch.setattr(study, "measure_cost", lambda name, bodies, steps: timed.append(name) or 1234.0)
    result = CliRunner().invoke(app, ["integrators", "--measure"])
    assert result.exit_code == 0, result.output
    assert timed == [info.name for info in list_integrators()]
    assert "ns/body-step (1000 bodies)" in result.output and result.output.count("1234") == len(timed)


def test_info_json_labels_drift_and_change_and_the_text_says_so(recording, tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    results = tmp_path / "results.parquet"  # a sweep's table: --json too
    pq.write_table(pa.table({"variant": [0, 1], "status": ["completed", "diverged"], "message": ["", "x"]}), results)
    (code, out, err), (text_code, text, _), (sweep_code, sweep, _) = run_cases(
        [["info", "--json", str(recording)], ["info", str(recording)], ["info", "--json", str(results)]]
    )
    assert code == text_code == sweep_code == 0 and err == ""
    assert json.loads(sweep)["status"] == {"completed": 1, "diverged": 1}
    data = json.loads(out)
    kinds = {entry["name"]: entry["kind"] for entry in data["invariants"]}
    # the tutorial: uniform gravity along -z, nothing else
    assert data["force_terms"] == ["gravity"]
    assert kinds["momentum_z"] == kinds["angular_momentum_y"] == kinds["energy_kinetic"] == "change"
    assert kinds["momentum_x"] == kinds["angular_momentum_z"] == kinds["energy_total"] == "drift"
    assert kinds["quaternion_norm_defect"] == "drift" and set(data["kinds"]) == {"drift", "change"}
    assert all(isinstance(entry["max_abs_change"], float) for entry in data["invariants"])
    rows = {line.split()[0]: line.split()[1] for line in text.splitlines() if line.split()[:1] and line[0] != " "}
    assert rows["momentum_z"] == "change" and rows["energy_total"] == "drift"
    assert "change: changed by the scene's forces themselves (not an error)" in text


def test_colour_only_on_a_terminal(tmp_path):
    missing = str(tmp_path / "missing.yaml")
    leader, follower = pty.openpty()
    try:
        proc = subprocess.Popen([sys.executable, "-m", "rbcli", "run", missing], stdout=subprocess.DEVNULL,
                                stderr=follower, env=child_env(), cwd=ROOT)  # fmt: skip
        os.close(follower)
        chunks = []
        while True:
            try:
                chunk = os.read(leader, 4096)
            except OSError:  # the terminal closed: the child is done
                break
            if not chunk:
                break
            chunks.append(chunk)
        assert proc.wait(timeout=60) == ExitCode.INVALID
    finally:
        os.close(leader)
    shown = b"".join(chunks).decode()
    assert "\x1b[1;31merror:\x1b[0m scene file not found: " + missing in shown


def test_no_color_and_dumb_terminals_get_plain_text(monkeypatch):
    from rbcli.cli import messages

    class Terminal:
        def isatty(self) -> bool:
            return True

    monkeypatch.delenv("FORCE_COLOR", raising=False)
    monkeypatch.delenv("NO_COLOR", raising=False)
    monkeypatch.setenv("TERM", "xterm")
    assert messages.use_colour(Terminal())
    monkeypatch.setenv("NO_COLOR", "1")
    assert not messages.use_colour(Terminal())
    monkeypatch.delenv("NO_COLOR")
    monkeypatch.setenv("TERM", "dumb")
    assert not messages.use_colour(Terminal())
    line = messages.format_message("error", "a\nb", expected="c", where="f.yaml:1:2")
    assert line == "f.yaml:1:2: error: a; b; expected c"


def test_the_readme_shows_the_exit_code_table():
    assert exit_code_markdown() in (ROOT / "README.md").read_text(encoding="utf-8")


def test_commands_exit_only_with_the_table_codes():
    """No command passes a bare number to typer.Exit: every status comes from cli/exit_codes.py (ExitCode,
    signal_exit) or a function that returns one, so the table is the whole list."""
    bare = []
    for path in sorted((ROOT / "rbcli" / "cli").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) == "Exit":
                for arg in node.args:
                    if isinstance(arg, ast.Constant):
                        bare.append(f"{path.name}:{node.lineno}")
            if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant) and path.name != "exit_codes.py":
                names = [t.id for t in node.targets if isinstance(t, ast.Name)]
                bare += [f"{path.name}:{node.lineno} {n}" for n in names if n.startswith("EXIT_")]
    assert bare == []
    assert {int(code) for code in ExitCode} >= {0, 1, 2, 3, 129, 130, 143}


def test_python_warnings_print_as_one_warning_line(capsys):
    from rbcli.cli.app import show_warning

    show_warning(RuntimeWarning("overflow encountered\nin multiply"), RuntimeWarning, "/x/y/energy.py", 12)
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["warning: overflow encountered; in multiply (RuntimeWarning, energy.py:12)"]


def test_signal_statuses_are_128_plus_the_signal():
    import signal

    from rbcli.cli.exit_codes import signal_exit

    for name in ("SIGHUP", "SIGINT", "SIGTERM"):
        assert ExitCode[name] == signal_exit(getattr(signal, name)) == 128 + getattr(signal, name)
