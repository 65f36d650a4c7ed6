"""Where the scene schema lives: packaged in the wheel, or in a source checkout's `schemas/`."""

from __future__ import annotations

import json
from functools import cache
from pathlib import Path
from typing import Any

SCHEMA_FILE_NAME = "scene.schema.json"


def scene_schema_path() -> Path:
    """Path of `scene.schema.json`: `rbcli/_schemas/` in an installed wheel (pyproject's force-include),
    else `<repo>/schemas/` next to the `rbcli` package in a source checkout."""
    package = Path(__file__).resolve().parent.parent
    candidates = (package / "_schemas" / SCHEMA_FILE_NAME, package.parent / "schemas" / SCHEMA_FILE_NAME)
    for candidate in candidates:
        if candidate.is_file():
            return candidate
    raise FileNotFoundError(f"cannot find {SCHEMA_FILE_NAME}; looked in " + ", ".join(str(c) for c in candidates))


@cache
def scene_schema() -> dict[str, Any]:
    """The scene schema as a dict (read once per process)."""
    return json.loads(scene_schema_path().read_text(encoding="utf-8"))
