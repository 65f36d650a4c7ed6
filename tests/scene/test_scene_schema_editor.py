"""The published schema as an editor uses it: `jsonschema` alone, on the YAML as written (yaml.safe_load),
with the validator the file declares (`$schema`) and its `$ref`s resolved within the file.

It must accept every shipped scene (bodies that take their particles from `defaults` included: rbsim merges
`defaults` before validating, an editor cannot), and reject exactly the scenes of the bad-scene corpus
(tests/scene/test_scene_load_errors.py) that rbsim's own JSON Schema stage rejects: what JSON Schema can
express (types, ranges, required keys, enums). The corpus's semantic errors (inertia, meshes, names) stay
rbsim's, and the editor must not reject the scenes rbsim's schema stage accepts.
"""

from __future__ import annotations

import inspect
import json
import textwrap
from functools import cache
from pathlib import Path

import pytest
import yaml
from jsonschema import validators

import rbcli.scene.load as scene_load
from rbcli.scene.spec import SCENE_FORMAT_VERSION, SceneError
from rbcli.scene.yaml_located import parse_located_yaml

REPO = Path(__file__).resolve().parents[2]
SCHEMA_FILE = REPO / "schemas" / "scene.schema.json"
SCENE_FILES = sorted(p for p in (REPO / "scenes").rglob("*.yaml") if not p.name.endswith(".sweep.yaml"))


@cache
def editor_validator():
    """What an editor builds from the file: the validator class its `$schema` names, refs resolved in it."""
    schema = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    cls = validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def editor_errors(text: str) -> list[str]:
    return [f"{list(e.absolute_path)}: {e.message}" for e in editor_validator().iter_errors(yaml.safe_load(text))]


@pytest.mark.parametrize("path", SCENE_FILES, ids=[str(p.relative_to(REPO)) for p in SCENE_FILES])
def test_editor_accepts_every_shipped_scene(path):
    assert editor_errors(path.read_text(encoding="utf-8")) == []


def test_the_shipped_scenes_include_bodies_that_take_their_particles_from_defaults():
    """The case the schema's root `if` exists for is really covered by the scenes above."""
    sources = ("particles", "shape", "mesh", "compound")

    def uses_defaults(data):
        defaults = data.get("defaults") or {}
        return any(k in defaults for k in sources) and any(
            isinstance(b, dict) and "name" in b and not any(k in b for k in sources) for b in data["bodies"]
        )

    users = [p.name for p in SCENE_FILES if uses_defaults(yaml.safe_load(p.read_text(encoding="utf-8")))]
    assert {"spring_chain.yaml", "projectile_drag.yaml"} <= set(users)


def test_schema_version_bound_is_the_format_version():
    schema = json.loads(SCHEMA_FILE.read_text(encoding="utf-8"))
    assert schema["properties"]["version"]["maximum"] == SCENE_FORMAT_VERSION


# ---- the bad-scene corpus ------------------------------------------------------------------------------
def bad_corpus(tmp_path: Path) -> list[tuple[str, str]]:
    """(test name, scene text) of every scene the load-error tests feed rbsim, captured by running them
    (their parametrized cases too) with the loader's entry point wrapped."""
    import test_scene_load_errors as corpus

    captured: list[tuple[str, str]] = []
    current = [""]
    real = scene_load.analyse_scene_text

    def spy(text, file="<string>", base_dir=None):
        captured.append((current[0], text.decode("utf-8", "replace") if isinstance(text, bytes) else text))
        return real(text, file, base_dir)

    saved = corpus.analyse_scene_text
    corpus.analyse_scene_text = spy
    scene_load.analyse_scene_text = spy  # check_scene / load_scene_text go through it too
    try:
        for name, test in vars(corpus).items():
            if not name.startswith("test_") or not callable(test):
                continue
            cases: list[dict] = [{}]
            for mark in getattr(test, "pytestmark", []):
                if mark.name == "parametrize":
                    names = [n.strip() for n in mark.args[0].split(",")]
                    cases = [dict(zip(names, v if len(names) > 1 else (v,), strict=True)) for v in mark.args[1]]
            for i, kwargs in enumerate(cases):
                if "tmp_path" in inspect.signature(test).parameters:
                    kwargs = {**kwargs, "tmp_path": tmp_path / f"{name}_{i}"}
                    kwargs["tmp_path"].mkdir()
                current[0] = f"{name}[{i}]"
                test(**kwargs)  # the corpus's own assertions hold too (they are its tests)
    finally:
        corpus.analyse_scene_text = saved
        scene_load.analyse_scene_text = real
    return [(name, textwrap.dedent(text)) for name, text in captured]


def rbsim_schema_stage_rejects(text: str) -> bool | None:
    """Whether rbsim's JSON Schema stage (on the scene with `defaults` merged) finds errors; None when rbsim
    stops before it (a YAML error, a file in a newer format) or when rbsim's YAML reader and PyYAML's read
    the text differently (`1e999` is a float to YAML 1.2 and rbsim, a string to PyYAML's YAML 1.1; `.nan`
    never equals itself): then the two schema checks would not judge the same data."""
    try:
        doc = parse_located_yaml(text, "s.yaml")
    except SceneError:
        return None
    if doc.value != yaml.safe_load(text):
        return None
    if not isinstance(doc.value, dict):
        return True
    version = doc.value.get("version", SCENE_FORMAT_VERSION)
    if isinstance(version, int) and version > SCENE_FORMAT_VERSION:
        return None
    merged = scene_load._merge_defaults(doc, doc.value)
    return any(True for _ in scene_load._validator().iter_errors(merged))


def test_editor_rejects_exactly_what_rbsims_schema_stage_rejects_in_the_bad_corpus(tmp_path):
    corpus = bad_corpus(tmp_path)
    judged = [(name, text, rbsim_schema_stage_rejects(text)) for name, text in corpus]
    judged = [(name, text, rejects) for name, text, rejects in judged if rejects is not None]
    assert len(corpus) - len(judged) <= 10  # YAML errors, newer formats, non-finite literals
    disagree = []
    for name, text, rejects in judged:
        got = editor_errors(text)
        if bool(got) != rejects:
            disagree.append(f"{name}: rbsim's schema stage {'rejects' if rejects else 'accepts'}; editor says {got}")
    assert disagree == []
    # a corpus that really exercises both sides (types, ranges, required keys, enums, unknown keys ...)
    assert sum(rejects for _, _, rejects in judged) >= 25
    assert sum(not rejects for _, _, rejects in judged) >= 10
