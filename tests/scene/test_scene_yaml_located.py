"""Safe YAML with locations: values, exact line:col of keys and values, and every input we refuse."""

from __future__ import annotations

import time

import pytest

from rbcli.scene.spec import SceneError, SourceLocation
from rbcli.scene.yaml_located import MAX_SCENE_BYTES, parse_located_yaml, read_located_yaml


def only_issue(source) -> tuple[int, int, str]:
    """(line, column, message) of the single issue a bad input raises."""
    with pytest.raises(SceneError) as info:
        parse_located_yaml(source, "s.yaml")
    assert len(info.value.issues) == 1, info.value.issues
    issue = info.value.issues[0]
    return issue.location.line, issue.location.column, issue.message


def test_values_and_locations_of_keys_and_values():
    doc = parse_located_yaml("a: 1\nb:\n  - x\n  - {c: 2.5}\n", "s.yaml")
    assert doc.value == {"a": 1, "b": ["x", {"c": 2.5}]}
    assert doc.key_locations[("b",)] == SourceLocation("s.yaml", 2, 1)
    assert doc.value_locations[("a",)] == SourceLocation("s.yaml", 1, 4)
    assert doc.value_locations[("b", 0)] == SourceLocation("s.yaml", 3, 5)
    assert doc.key_locations[("b", 1, "c")] == SourceLocation("s.yaml", 4, 6)
    assert doc.value_locations[("b", 1, "c")] == SourceLocation("s.yaml", 4, 9)
    # a path that does not exist falls back to its nearest ancestor
    assert doc.locate(("b", 1, "missing")) == SourceLocation("s.yaml", 4, 5)


def test_yaml_1_2_floats_and_plain_scalars():
    doc = parse_located_yaml("a: 1e-3\nb: 2E5\nc: -1.5e+3\nd: 1_000\ne: .inf\nf: 2024-01-02\ng: '1.0'\n")
    v = doc.value
    assert v["a"] == 0.001 and v["b"] == 2e5 and v["c"] == -1500.0 and v["d"] == 1000
    assert v["e"] == float("inf")
    assert v["f"] == "2024-01-02"  # a date-like value stays text (no datetime objects)
    assert v["g"] == "1.0"


def test_anchors_aliases_and_merge_keys():
    text = """\
base: &base {mass: 1.0, radius: 0.1}
other: &other {mass: 9.0, colour: red}
body:
  <<: [*base, *other]
  radius: 0.2
copy: *base
"""
    doc = parse_located_yaml(text, "s.yaml")
    # explicit keys win over merged ones; among merge sources the first wins (YAML merge rules)
    assert doc.value["body"] == {"mass": 1.0, "colour": "red", "radius": 0.2}
    assert doc.value["copy"] == {"mass": 1.0, "radius": 0.1}
    # a merged value is located where its text is (in the anchored mapping); the alias where it is used
    assert doc.value_locations[("body", "mass")] == SourceLocation("s.yaml", 1, 20)
    assert doc.value_locations[("body", "radius")] == SourceLocation("s.yaml", 5, 11)
    assert doc.value_locations[("copy",)] == SourceLocation("s.yaml", 6, 7)


def test_duplicate_key_is_an_error_at_the_second_key():
    assert only_issue("a: 1\nb:\n  c: 1\n  c: 2\n")[:2] == (4, 3)
    line, column, message = only_issue("{x: 1, y: 2, x: 3}")
    assert (line, column) == (1, 14) and "duplicate key 'x'" in message and "line 1" in message


def test_duplicate_keys_all_reported():
    with pytest.raises(SceneError) as info:
        parse_located_yaml("a: 1\na: 2\nb: 1\nb: 2\n", "s.yaml")
    assert [(i.location.line, i.location.column) for i in info.value.issues] == [(2, 1), (4, 1)]


@pytest.mark.parametrize(
    "text, line, column",
    [
        ("a: !!python/object:os.system {x: 1}\n", 1, 4),
        ("a:\n  - !!python/object/apply:os.system ['ls']\n", 2, 5),
        ("a: !!python/name:os.system ''\n", 1, 4),
        ("a: !custom 3\n", 1, 4),
        ("a: !!binary aGVsbG8=\n", 1, 4),
        ("a: !!set {x, y}\n", 1, 4),
    ],
)
def test_python_and_other_tags_are_errors_at_their_location(text, line, column):
    got_line, got_column, message = only_issue(text)
    assert (got_line, got_column) == (line, column)
    assert "is not allowed" in message


def test_alias_bomb_fails_fast_with_a_clear_error():
    # "billion laughs": 9 levels of 9 aliases expand to 9^9 ~ 4e8 strings from ~800 bytes
    lines = ['l0: &l0 ["lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol", "lol"]']
    lines += [f"l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]" for i in range(1, 10)]
    start = time.perf_counter()
    line, column, message = only_issue("\n".join(lines) + "\n")
    assert time.perf_counter() - start < 2.0
    assert "alias" in message and "bomb" in message
    assert line >= 2 and column > 1  # at an alias, not at the start of the file


def test_recursive_alias_is_an_error():
    line, column, message = only_issue("a: &a [1, *a]\n")
    assert (line, column) == (1, 11) and "cycle" in message


def test_moderate_alias_reuse_is_fine():
    template = "tpl: &tpl {shape: {type: sphere, radius: 0.1}, spacing: 0.05, density: 1000}\n"
    bodies = "bodies:\n" + "".join(f"  - {{<<: *tpl, name: b{i}}}\n" for i in range(2000))
    doc = parse_located_yaml(template + bodies)
    assert len(doc.value["bodies"]) == 2000 and doc.value["bodies"][1999]["name"] == "b1999"


def test_empty_and_comment_only_files():
    for text in ("", "   \n\n", "# just a comment\n", b"", "---\n", "--- # nothing\n...\n"):
        line, column, message = only_issue(text)
        assert (line, column) == (1, 1) and "empty" in message


def test_non_utf8_input_located_at_the_bad_byte():
    line, column, message = only_issue(b"name: ok\nnote: caf\xe9 au lait\n")
    assert (line, column) == (2, 10)
    assert "UTF-8" in message and "0xe9" in message


def test_non_utf8_after_multibyte_characters_counts_characters():
    line, column, _ = only_issue("a: ü\nb: ".encode() + "ää".encode() + b"\xff\n")
    assert (line, column) == (2, 6)


def test_binary_input():
    line, column, message = only_issue(b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR")
    assert "binary" in message
    line, column, message = only_issue(bytes(range(256)))
    assert "binary" in message and (line, column) == (1, 1)


def test_utf16_is_refused_with_a_hint():
    _, _, message = only_issue("a: 1\n".encode("utf-16"))
    assert "UTF-16" in message


def test_utf8_bom_is_accepted():
    assert parse_located_yaml("\ufeffa: 1\n".encode()).value == {"a": 1}


def test_control_character_is_an_error():
    line, column, message = only_issue("a: 1\nb: x\x07y\n")
    assert (line, column) == (2, 5) and "U+0007" in message


def test_size_limit():
    big = b"a: 1\n" + b"#" * MAX_SCENE_BYTES
    _, _, message = only_issue(big)
    assert f"file is {len(big):,} bytes" in message and f"the {MAX_SCENE_BYTES:,}-byte (10.0 MiB) limit" in message


@pytest.mark.parametrize("megabytes", [11, 50])
def test_size_limit_gives_the_real_size_of_a_file(tmp_path, megabytes):
    """The readers stop after the limit; the message still gives the file's own size, not what was read."""
    from rbcli.scene.load import check_scene
    from rbcli.scene.yaml_located import read_located_yaml

    path = tmp_path / "big.yaml"
    size = megabytes * 1_000_000
    with open(path, "wb") as f:
        f.write(b"a: 1\n")
        f.truncate(size)  # a sparse file: no 50 MB written
    (issue,) = check_scene(path)
    with pytest.raises(SceneError) as caught:
        read_located_yaml(path)
    for message in (issue.message, caught.value.issues[0].message):
        assert f"file is {size:,} bytes ({size / 2**20:.1f} MiB), over the 10,485,760-byte" in message


def test_deep_nesting_is_refused_not_a_crash():
    _, _, message = only_issue("[" * 5000 + "]" * 5000)
    assert "nesting" in message


@pytest.mark.parametrize(
    "text, line, column, fragment",
    [
        ("a: [1, 2\nb: 3\n", 2, 2, "YAML syntax error"),
        ("a:\n\t- 1\n", 2, 1, "tab"),
        ("a: 1\n---\nb: 2\n", 2, 1, "YAML syntax error"),
        ("a: *nowhere\n", 1, 4, "undefined alias"),
        ("a: 1\n b: 2\n", 2, 3, "YAML syntax error"),
    ],
)
def test_syntax_errors_are_located(text, line, column, fragment):
    got_line, got_column, message = only_issue(text)
    assert (got_line, got_column) == (line, column)
    assert fragment in message


def test_non_scalar_key_is_an_error():
    line, column, message = only_issue("? [1, 2]\n: x\n")
    assert (line, column) == (1, 3) and "key" in message


def test_huge_integer_literal_is_an_error_not_a_crash():
    _, _, message = only_issue("a: " + "9" * 6000 + "\n")
    assert "cannot read int" in message


def test_keys_are_text_as_written():
    # YAML 1.1 would make `on`/`yes`/`1` booleans and ints; as keys they stay names (then fail the schema)
    assert set(parse_located_yaml("on: 1\nyes: 2\n1: 3\n").value) == {"on", "yes", "1"}


def test_missing_file(tmp_path):
    with pytest.raises(SceneError) as info:
        read_located_yaml(tmp_path / "nope.yaml")
    assert info.value.issues[0].location is None
    assert "nope.yaml" in info.value.issues[0].message


def test_top_level_keys_without_building_values():
    from rbcli.scene.yaml_located import top_level_keys

    text = "a: 1\nb: [1, {c: 2}]\nd: {x: [1]}\n? [1]\n: 3\nf: &v 4\ng: *v\n"
    assert top_level_keys(text) == {"a", "b", "d", "f", "g"}
    assert top_level_keys("[1, 2]\n") == set() and top_level_keys("") == set()
    # the scan stops at a stop key: what follows is never read (here: text that is not YAML at all)
    assert top_level_keys("axes: []\nbodies: [1]\nrest: [unclosed\n", frozenset({"bodies"})) == {"axes", "bodies"}
