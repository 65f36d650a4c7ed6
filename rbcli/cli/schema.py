"""`rbsim schema`: print the scene JSON Schema (for editors: `rbsim schema > scene.schema.json`)."""

from __future__ import annotations

import typer


def schema() -> None:
    """Print the JSON Schema (2020-12) that scene files follow."""
    from rbcli.scene.schema_path import scene_schema_path

    typer.echo(scene_schema_path().read_text(encoding="utf-8"), nl=False)
