"""The sweep tests' fixture: a sweep file and its scene in a fresh folder (sweep_cases.py has both texts)."""

from __future__ import annotations

from pathlib import Path

import pytest
from sweep_cases import SPRING_SCENE, SPRING_SWEEP


@pytest.fixture
def spring_sweep(tmp_path: Path) -> Path:
    """A sweep file (and its scene) in a fresh folder: 3 stiffnesses x 2 integrators, one stiffness diverging."""
    (tmp_path / "spring.yaml").write_text(SPRING_SCENE)
    path = tmp_path / "spring.sweep.yaml"
    path.write_text(SPRING_SWEEP)
    return path
