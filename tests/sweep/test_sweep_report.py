"""The results table in words (sweeps/report.py) on a table that never touched Parquet: `pyarrow.compute`
is a submodule that `import pyarrow` does not load, so the report must import it itself (run in a fresh
interpreter: in this one another test may have loaded it already)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_failures_and_describe_work_on_an_in_memory_table_in_a_fresh_process():
    code = (
        "import sys\n"
        "from rbcli.sweeps.report import describe, failures\n"
        "from rbcli.sweeps.table import rows_table\n"
        "assert 'pyarrow.parquet' in sys.modules\n"
        "rows = [{'variant': 0, 'status': 'completed', 'message': '', 'wall_s': 0.5},\n"
        "        {'variant': 1, 'status': 'diverged', 'message': 'diverged at step 7'}]\n"
        "table = rows_table(rows)\n"
        "print(failures(table))\n"
        "print(describe(table))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "['variant 1 (): diverged: diverged at step 7']" in out.stdout
    assert "status:     1 completed, 1 diverged" in out.stdout
