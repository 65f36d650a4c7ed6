"""Sweep files to `SweepSpec`, with every problem located at file:line:col as scene files are.

    read (yaml_located) ─▶ JSON Schema (schemas/sweep.schema.json) ─▶ base scene (scene loader)
        ─▶ per axis: path against the scene schema and the base data ─▶ values (grid, draws)
        ─▶ probe variants through the scene loader ─▶ SweepSpec

A variant is only as valid as the scene it makes, so each axis is tried: the base scene with that one
axis set to a probe value is loaded by the normal scene loader, and every issue the base scene does not
have is reported at the axis value in the sweep file ("axes[1].values[2]: ... gives an invalid scene:
simulation.integrator: unknown integrator 'rk5'"). Probes: every value of a list axis that is not a
plain number (strings, mappings, lists of other things); for numbers and numeric vectors, the values
holding each component's minimum and maximum (the scene's limits are ranges and types) and the first
value of each type; the ends of a grid; each component's extreme draws of a random axis. Combinations of
axes are not probed (their count multiplies); a combination the loader rejects becomes a failed row with
the loader's message when the sweep runs.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from rbcli.scene.issues import IssueCollector
from rbcli.scene.schema_errors import SchemaErrorFormatter
from rbcli.scene.schema_path import scene_schema, scene_schema_path
from rbcli.scene.spec import SceneError, SceneIssue
from rbcli.scene.yaml_located import (
    MAX_SCENE_BYTES,
    LocatedDocument,
    YamlPath,
    decode_scene_bytes,
    parse_located_yaml,
    top_level_keys,
)
from rbcli.sweeps.paths import (
    PathError,
    check_in_data,
    known_in_schema,
    overlapping,
    parse_path,
    variant_text,
)
from rbcli.sweeps.spec import MAX_VARIANTS, Axis, SweepSpec, grid_values, random_values

SWEEP_SCHEMA_FILE_NAME = "sweep.schema.json"
SWEEP_SUFFIXES = (".sweep.yaml", ".sweep.yml")
DEFAULT_FRAMES = 101


def sweep_schema_path() -> Path:
    """`sweep.schema.json`, beside the scene schema (in a wheel's rbcli/_schemas or the checkout's schemas/)."""
    return scene_schema_path().parent / SWEEP_SCHEMA_FILE_NAME


@cache
def sweep_schema() -> dict[str, Any]:
    return json.loads(sweep_schema_path().read_text(encoding="utf-8"))


@cache
def _validator() -> Any:
    from jsonschema import Draft202012Validator

    return Draft202012Validator(sweep_schema())


def is_sweep_file(path: str | Path) -> bool:
    """A sweep file is named *.sweep.yaml (or .yml), or is a YAML mapping with `axes` and no `bodies`."""
    name = str(path).lower()
    if name.endswith(SWEEP_SUFFIXES):
        return True
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_SCENE_BYTES + 1)
        # the top-level keys only, up to `bodies`: a large scene is not read twice to learn it is a scene
        keys = top_level_keys(decode_scene_bytes(raw, str(path)), frozenset({"bodies"}))
    except (OSError, SceneError, yaml.YAMLError):
        return False
    return "axes" in keys and "bodies" not in keys


def load_sweep(path: str | Path) -> SweepSpec:
    """Read and validate a sweep file; SceneError with every located issue when it has errors."""
    spec, issues = analyse_sweep(path)
    if spec is None:
        raise SceneError(issues)
    return spec


def analyse_sweep(path: str | Path) -> tuple[SweepSpec | None, list[SceneIssue]]:
    """(spec or None when there are errors, every issue) for a sweep file."""
    file = str(path)
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_SCENE_BYTES + 1)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        return None, [SceneIssue(None, f"cannot read sweep file '{file}': {reason}", "a readable YAML file")]
    return analyse_sweep_text(raw, file, Path(path).parent)


def analyse_sweep_text(
    text: str | bytes, file: str = "<sweep>", base_dir: str | Path | None = None
) -> tuple[SweepSpec | None, list[SceneIssue]]:
    """(spec or None, issues) for sweep text; the scene path resolves against `base_dir` (default: the
    current folder)."""
    try:
        doc = parse_located_yaml(decode_scene_bytes(text, file) if isinstance(text, bytes) else text, file)
    except SceneError as exc:
        return None, exc.issues
    return _Analysis(doc, file, Path(base_dir) if base_dir is not None else Path.cwd()).run()


def sweep_definition_text(definition: dict[str, Any]) -> str:
    """A sweep given as a Python mapping (`rbcli.sweep`), as the YAML text of a sweep file."""
    return yaml.safe_dump(definition, sort_keys=False, allow_unicode=True)


@dataclass
class _Probe:
    value: Any
    location: YamlPath


class _Analysis:
    """One sweep document through every stage (see the module docstring); issues collect as they are found."""

    def __init__(self, doc: LocatedDocument, file: str, base_dir: Path) -> None:
        self.doc, self.file, self.base_dir = doc, file, base_dir
        self.issues = IssueCollector(doc, file)
        self.scene_issues: list[SceneIssue] = []  # located in the base scene's file

    def result(self, spec: SweepSpec | None) -> tuple[SweepSpec | None, list[SceneIssue]]:
        issues = [*self.issues.sorted(), *self.scene_issues]
        return (spec if self.issues.error_count == 0 else None), issues

    def run(self) -> tuple[SweepSpec | None, list[SceneIssue]]:
        data = self.doc.value
        if not isinstance(data, dict):
            self.issues.error((), "a sweep must be a mapping", "keys such as scene and axes")
            return self.result(None)
        bad = self._check_finite(data)
        errors = sorted(_validator().iter_errors(data), key=lambda e: list(map(str, e.absolute_path)))
        bad |= SchemaErrorFormatter(sweep_schema(), self.issues).report(errors, skip_paths=bad)

        def clean(prefix: YamlPath) -> bool:  # no schema error in or around this part of the file
            return not any(p[: len(prefix)] == prefix or prefix[: len(p)] == p for p in bad)

        if not clean(("scene",)) or not isinstance(data.get("axes"), list) or not clean(("samples",)):
            return self.result(None)
        scene = self._base_scene(data["scene"])
        if scene is None:
            return self.result(None)
        scene_path, scene_text, scene_doc, base_issues = scene
        # every axis the schema found sound is checked further, so one run shows all the file's errors
        entries = [(k, entry) for k, entry in enumerate(data["axes"]) if clean(("axes", k))]
        axes = [axis for k, entry in entries if (axis := self._axis(k, entry, data, scene_doc))]
        self._check_columns(axes)
        known = {_issue_key(i) for i in base_issues}
        for axis in axes:
            for probe in self._probes(axis):
                self._try(axis, probe, scene_doc.value, scene_path, known)
        if self.issues.error_count:
            return self.result(None)
        self._check_lengths(data, axes)
        frames = data.get("record", {}).get("frames", DEFAULT_FRAMES)
        name = data.get("name") or _stem(self.file)
        spec = SweepSpec(
            name=str(name),
            source_path=self.file,
            scene_path=str(scene_path),
            scene_text=scene_text,
            axes=tuple(axes),
            combine=data.get("combine", "product"),
            samples=data.get("samples"),
            seed=int(data.get("seed", 0)),
            batch=data.get("batch"),
            frames=None if frames == "scene" else int(frames),
            logs=bool(data.get("record", {}).get("logs", False)),
            output=data.get("output"),
            definition=data,
        )
        if spec.variant_count > MAX_VARIANTS:
            self.issues.error(
                ("axes",),
                f"{spec.variant_count} variants is too many",
                f"at most {MAX_VARIANTS} (fewer values or samples)",
            )
        return self.result(spec)

    # ---- stages ---------------------------------------------------------------------------------------
    def _check_finite(self, data: Any) -> set[YamlPath]:
        bad: set[YamlPath] = set()
        stack: list[tuple[Any, YamlPath]] = [(data, ())]
        while stack:
            item, where = stack.pop()
            if isinstance(item, dict):
                stack.extend((v, (*where, k)) for k, v in item.items())
            elif isinstance(item, list):
                stack.extend((v, (*where, i)) for i, v in enumerate(item))
            elif isinstance(item, float) and not math.isfinite(item):
                self.issues.error(where, f"{item} is not a finite number", "a finite number")
                bad.add(where)
        return bad

    def _base_scene(self, name: str) -> tuple[Path, str, LocatedDocument, list[SceneIssue]] | None:
        """The base scene: read, parsed with locations, and loaded once (its own errors end the analysis)."""
        from rbcli.scene.load import analyse_scene_text

        path = Path(os.path.normpath(self.base_dir / name))  # as the user would write it from here
        try:
            text = decode_scene_bytes(path.read_bytes()[: MAX_SCENE_BYTES + 1], str(path))
            scene_doc = parse_located_yaml(text, str(path))
        except OSError as exc:
            self.issues.error(("scene",), f"cannot read the base scene '{path}': {exc.strerror or exc}", "a scene file")
            return None
        except SceneError as exc:
            self.issues.error(("scene",), "the base scene is not valid YAML", "a valid scene file (see below)")
            self.scene_issues.extend(exc.issues)
            return None
        spec, issues = analyse_scene_text(text, str(path), path.resolve().parent)
        if spec is None:
            errors = sum(1 for i in issues if i.severity == "error")
            self.issues.error(("scene",), f"the base scene has {errors} error{'s' * (errors != 1)}", "a valid scene")
            self.scene_issues.extend(issues)
            return None
        if not isinstance(scene_doc.value, dict):
            return None
        return path, text, scene_doc, issues

    def _axis(self, k: int, entry: dict[str, Any], data: dict[str, Any], scene: LocatedDocument) -> Axis | None:
        where: YamlPath = ("axes", k)
        try:
            path = parse_path(entry["path"])
            known_in_schema(scene_schema(), path)
            check_in_data(scene.value, path)
        except PathError as exc:
            self.issues.error((*where, "path"), str(exc), exc.expected)
            return None
        for j, other in enumerate(data["axes"][:k]):
            try:
                if overlapping(parse_path(other["path"]), path):
                    self.issues.error(
                        (*where, "path"),
                        f"overlaps axes[{j}] ('{other['path']}'): two axes would set the same value",
                        "each scene value varied by one axis",
                    )
                    return None
            except PathError:
                continue
        name = str(entry.get("name", ""))
        if "values" in entry:
            return Axis(path, "values", tuple(entry["values"]), where, name)
        if "grid" in entry:
            grid = entry["grid"]
            spacing = grid.get("spacing", "linear")
            if not self._same_shape((*where, "grid"), grid["start"], grid["stop"], ("start", "stop")):
                return None
            if spacing == "log" and not (
                np.all(np.asarray(grid["start"]) > 0) and np.all(np.asarray(grid["stop"]) > 0)
            ):
                self.issues.error((*where, "grid"), "a log grid needs start > 0 and stop > 0", "positive ends")
                return None
            return Axis(path, "grid", grid_values(grid["start"], grid["stop"], grid["num"], spacing), where, name)
        dist = entry["random"]
        if "samples" not in data:
            self.issues.error(
                (*where, "random"), "a random axis needs `samples` (how many draws)", "samples: N at the top level"
            )
            return None
        names = ("mean", "std") if dist["distribution"] == "normal" else ("low", "high")
        if not self._same_shape((*where, "random"), dist[names[0]], dist[names[1]], names):
            return None
        a, b = np.asarray(dist[names[0]], float), np.asarray(dist[names[1]], float)
        if dist["distribution"] == "normal" and np.any(b < 0):
            self.issues.error((*where, "random", "std"), "a standard deviation must be >= 0", "std >= 0")
            return None
        if dist["distribution"] != "normal" and np.any(b < a):
            self.issues.error((*where, "random"), "high is below low", "low <= high")
            return None
        if dist["distribution"] == "loguniform" and np.any(a <= 0):
            self.issues.error((*where, "random", "low"), "a loguniform distribution needs low > 0", "low > 0")
            return None
        samples = int(data["samples"])
        if samples > MAX_VARIANTS:
            self.issues.error(("samples",), f"{samples} samples is too many", f"at most {MAX_VARIANTS}")
            return None
        return Axis(path, "random", random_values(dist, samples, int(data.get("seed", 0)), k), where, name)

    def _check_columns(self, axes: list[Axis]) -> None:
        """Each axis's results column must be new: not a result column, not another axis's."""
        from rbcli.sweeps.execute import RESULT_COLUMNS

        taken = {name for name, _ in RESULT_COLUMNS}
        for axis in axes:
            if axis.column in taken:
                where = (*axis.location, "name" if axis.name else "path")
                self.issues.error(where, f"the results already have a column '{axis.column}'", "another axis name")
            taken.add(axis.column)

    def _same_shape(self, where: YamlPath, a: Any, b: Any, names: tuple[str, str]) -> bool:
        if isinstance(a, list) and isinstance(b, list) and len(a) != len(b):
            self.issues.error(
                (*where, names[1]),
                f"{names[1]} has {len(b)} components and {names[0]} {len(a)}",
                "vectors of one length (or a number, used for every component)",
            )
            return False
        return True

    def _check_lengths(self, data: dict[str, Any], axes: list[Axis]) -> None:
        if data.get("combine", "product") != "zip":
            if "samples" in data and not any(a.kind == "random" for a in axes):
                self.issues.warning(("samples",), "no axis is random, so samples changes nothing", "a random axis")
            return
        first = axes[0]
        for axis in axes[1:]:
            if len(axis.values) != len(first.values):
                self.issues.error(
                    axis.location,
                    f"combine: zip needs axes of one length: this one has {len(axis.values)} values, "
                    f"axes[0] has {len(first.values)}",
                    "as many values (or samples) on every axis",
                )

    def _probes(self, axis: Axis) -> Iterator[_Probe]:
        where = axis.location
        if axis.kind == "grid":
            ends = {0, len(axis.values) - 1}
            yield from (_Probe(axis.values[i], (*where, "grid")) for i in sorted(ends))
            return
        if axis.kind == "random":
            draws = np.asarray(axis.values, dtype=np.float64)
            for pick in (np.argmin, np.argmax):
                chosen = sorted({int(i) for i in np.atleast_1d(pick(draws, axis=0)).ravel()})
                yield from (_Probe(axis.values[i], (*where, "random")) for i in chosen)
            return
        chosen = _value_probes(axis.values)
        yield from (_Probe(axis.values[i], (*where, "values", i)) for i in chosen)

    def _try(self, axis: Axis, probe: _Probe, base: dict[str, Any], scene_path: Path, known: set[Any]) -> None:
        """Load the base scene with this axis at the probe's value; report the issues the base scene lacks."""
        from rbcli.scene.load import analyse_scene_text

        text = variant_text(base, ((axis.path, probe.value),))
        _, issues = analyse_scene_text(text, str(scene_path), scene_path.resolve().parent)
        shown = _short(probe.value)
        for issue in issues:
            if _issue_key(issue) in known:
                continue
            message = f"{shown} at {axis.column} gives an invalid scene: {issue.message}"
            if issue.severity == "error":
                self.issues.error(probe.location, message, issue.expected)
            else:
                self.issues.warning(probe.location, f"{shown} at {axis.column}: {issue.message}", issue.expected)


def _value_probes(values: tuple[Any, ...]) -> list[int]:
    """Indices of the list values to try (see the module docstring)."""
    numeric = [i for i, v in enumerate(values) if _numbers(v) is not None]
    chosen = {i for i, v in enumerate(values) if _numbers(v) is None}
    by_shape: dict[Any, list[int]] = {}
    for i in numeric:
        array = _numbers(values[i])
        assert array is not None
        by_shape.setdefault((array.shape, _kinds(values[i])), []).append(i)
    for members in by_shape.values():
        stacked = np.stack([np.asarray(_numbers(values[i])).reshape(-1) for i in members])
        chosen.add(members[0])
        chosen.update(members[int(j)] for j in np.argmin(stacked, axis=0))
        chosen.update(members[int(j)] for j in np.argmax(stacked, axis=0))
    return sorted(chosen)


def _numbers(value: Any) -> np.ndarray | None:
    """The value as a float array when it is a number or a (nested) list of numbers, else None."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, list):
            stack.extend(item)
        elif isinstance(item, bool) or not isinstance(item, int | float):
            return None
    try:
        return np.asarray(value, dtype=np.float64)
    except ValueError:  # ragged lists
        return None


def _kinds(value: Any) -> tuple[str, ...]:
    items = value if isinstance(value, list) else [value]
    return tuple(sorted({type(v).__name__ for v in np.asarray(items, dtype=object).ravel()}))


def _short(value: Any) -> str:
    text = json.dumps(value) if not isinstance(value, str) else repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _issue_key(issue: SceneIssue) -> tuple[str, str, str]:
    return (issue.message, issue.expected, issue.severity)


def _stem(file: str) -> str:
    name = Path(file).name
    for suffix in (*SWEEP_SUFFIXES, ".yaml", ".yml"):
        if name.lower().endswith(suffix):
            return name[: -len(suffix)] or "sweep"
    return name or "sweep"
