"""Collecting located scene issues: every check reports here instead of raising, so a scene gets them all."""

from __future__ import annotations

import difflib
from collections.abc import Iterable

from rbcli.scene.spec import SceneIssue, SourceLocation
from rbcli.scene.yaml_located import LocatedDocument, YamlPath


def format_path(path: Iterable[str | int]) -> str:
    """`("bodies", 0, "particles", "masses", 1)` -> `bodies[0].particles.masses[1]`."""
    text = ""
    for part in path:
        text += f"[{part}]" if isinstance(part, int) else (f".{part}" if text else str(part))
    return text


def did_you_mean(word: str, choices: Iterable[str]) -> str | None:
    """The closest of `choices` to `word`, if any is close enough to be a likely typo."""
    matches = difflib.get_close_matches(str(word), sorted(set(choices)), n=1, cutoff=0.6)
    return matches[0] if matches else None


def quoted_list(words: Iterable[str]) -> str:
    return ", ".join(f"'{w}'" for w in words)


class IssueCollector:
    """Issues for one scene document, located by YAML path; keeps the first of identical issues.

    Values copied into several places (a `defaults` entry merged into every body, a generator template
    shared by many bodies) can raise the same issue many times at one location; it is reported once.
    """

    def __init__(self, doc: LocatedDocument | None, file: str):
        self.doc = doc
        self.file = file
        self.issues: list[SceneIssue] = []
        self._seen: set[tuple[SourceLocation | None, str, str]] = set()

    def locate(self, path: YamlPath, *, key: bool = False) -> SourceLocation:
        if self.doc is None:
            return SourceLocation(self.file, 1, 1)
        return self.doc.locate(path, key=key)

    def add(
        self,
        path: YamlPath,
        message: str,
        expected: str = "",
        *,
        key: bool = False,
        severity: str = "error",
        dedupe_key: str | None = None,
    ) -> None:
        """Record an issue at `path` (its key when `key`); `message` is prefixed with the dotted path."""
        location = self.locate(path, key=key)
        seen = (location, dedupe_key if dedupe_key is not None else message, severity)
        if seen in self._seen:
            return
        self._seen.add(seen)
        where = format_path(path)
        text = f"{where}: {message}" if where else message
        self.issues.append(SceneIssue(location, text, expected, severity))

    def error(self, path: YamlPath, message: str, expected: str = "", *, key: bool = False) -> None:
        self.add(path, message, expected, key=key)

    def warning(self, path: YamlPath, message: str, expected: str = "", *, key: bool = False) -> None:
        self.add(path, message, expected, key=key, severity="warning")

    @property
    def error_count(self) -> int:
        return sum(1 for issue in self.issues if issue.severity == "error")

    def sorted(self) -> list[SceneIssue]:
        """Issues in file order (errors and warnings interleaved by location)."""

        def order(issue: SceneIssue) -> tuple[int, int]:
            loc = issue.location
            return (loc.line, loc.column) if loc else (0, 0)

        return sorted(self.issues, key=order)
