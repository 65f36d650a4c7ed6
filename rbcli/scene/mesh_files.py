"""Structural checks of mesh files before a reader parses them, so a damaged file is told what is wrong with
it (truncated, not text, not the format its extension names) instead of a reader's internals: trimesh
answers a truncated binary STL or a random-bytes OBJ with "No module named 'charset_normalizer'" (it tries
to guess a text encoding) and a truncated PLY with "list index out of range".

Only what the formats define is checked: a binary STL is an 80-byte header, a uint32 triangle count and 50
bytes per triangle; an ASCII STL is text from `solid` to `endsolid`; a PLY file is an ASCII header (`ply`
... `end_header`) that declares its elements, then their data (ASCII lines or packed binary); an OBJ file
is UTF-8 text.
"""

from __future__ import annotations

import struct
from pathlib import Path


class MeshError(ValueError):
    """A mesh file that cannot be read or does not describe a closed solid."""


# PLY scalar types and their sizes [bytes] (both spellings the format allows)
PLY_TYPE_SIZE = {
    "char": 1, "uchar": 1, "int8": 1, "uint8": 1,
    "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
    "int": 4, "uint": 4, "int32": 4, "uint32": 4,
    "float": 4, "float32": 4, "double": 8, "float64": 8,
}  # fmt: skip
_PLY_UNSIGNED = {1: "B", 2: "H", 4: "I", 8: "Q"}  # struct codes of the list lengths (the only values read)
STL_HEADER = 84  # 80 bytes of free text and the uint32 triangle count
STL_TRIANGLE = 50  # normal and three corners as 12 float32, and a uint16 attribute


def check_mesh_file(path: Path) -> None:
    """MeshError saying what is wrong with a mesh file's structure; silent for a well-formed file (whose
    geometry the reader and `check_closed` judge next)."""
    name = path.name
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise MeshError(f"cannot read mesh file '{name}': {exc.strerror or exc}") from None
    if not raw:
        raise MeshError(f"mesh file '{name}' is empty")
    suffix = path.suffix.lower()
    if suffix == ".stl":
        _check_stl(raw, name)
    elif suffix == ".ply":
        _check_ply(raw, name)
    elif suffix == ".obj":
        _text(raw, f"OBJ mesh '{name}'")


def _text(raw: bytes, what: str) -> str:
    """The UTF-8 text of a text format, or MeshError naming the first byte that is not text."""
    nul = raw.find(b"\x00")
    if nul >= 0:
        raise MeshError(
            f"{what} is not UTF-8 text (a NUL byte at offset {nul:,}, as in binary files); the format is text"
        )
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise MeshError(
            f"{what} is not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start:,}); the format is text"
        ) from None


def _check_stl(raw: bytes, name: str) -> None:
    count = int.from_bytes(raw[80:84], "little") if len(raw) >= STL_HEADER else None
    expected = STL_HEADER + STL_TRIANGLE * count if count is not None else None
    if len(raw) == expected:
        return  # a complete binary STL (its header may well start with "solid" too)
    if raw.lstrip()[:5].lower() == b"solid" and b"\x00" not in raw:
        text = _text(raw, f"ASCII STL '{name}'")
        facets, ends = text.count("facet normal"), text.count("endfacet")
        if "endsolid" not in text or facets != ends:
            raise MeshError(
                f"ASCII STL '{name}' is truncated: it ends after {ends:,} complete facet(s) without its 'endsolid' line"
            )
        return
    if count is None:
        raise MeshError(
            f"'{name}' is {len(raw):,} bytes: too short for a binary STL (an 84-byte header) and not ASCII STL "
            "text (which starts with 'solid')"
        )
    assert expected is not None
    # a truncated binary STL and a file that is no STL at all look alike here: say what the bytes show
    cut = " (truncated?)" if len(raw) < expected else ""
    raise MeshError(
        f"'{name}' is not a complete STL file: read as binary STL, its header declares {count:,} triangles "
        f"({expected:,} bytes) but the file holds {len(raw):,} bytes{cut}; and it is not ASCII STL text"
    )


def _check_ply(raw: bytes, name: str) -> None:
    if not raw.startswith(b"ply"):
        raise MeshError(f"'{name}' is not a PLY file (it does not start with 'ply')")
    marker = raw.find(b"end_header")
    newline = raw.find(b"\n", marker) if marker >= 0 else -1
    if newline < 0:
        raise MeshError(f"PLY file '{name}' is truncated: its header has no complete 'end_header' line")
    header = _text(raw[:newline], f"the header of PLY file '{name}'")
    fmt, elements = _ply_header(header, name)
    data = raw[newline + 1 :]
    declared = ", ".join(f"{count:,} '{element}'" for element, count, _ in elements) + " elements"
    if fmt == "ascii":
        _check_ply_ascii(data, elements, name, declared)
    else:
        _check_ply_binary(data, elements, fmt, name, declared)


# an element: (name, count, properties); a property: (scalar size, None) or (count size, item size) of a list
_Element = tuple[str, int, list[tuple[int, int | None]]]


def _ply_header(header: str, name: str) -> tuple[str, list[_Element]]:
    fmt = ""
    elements: list[_Element] = []
    for number, line in enumerate(header.splitlines(), 1):
        words = line.split()
        try:
            if words[:1] == ["format"]:
                fmt = words[1]
                if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
                    raise ValueError
            elif words[:1] == ["element"]:
                elements.append((words[1], int(words[2]), []))
            elif words[:2] == ["property", "list"]:
                elements[-1][2].append((PLY_TYPE_SIZE[words[2]], PLY_TYPE_SIZE[words[3]]))
            elif words[:1] == ["property"]:
                elements[-1][2].append((PLY_TYPE_SIZE[words[1]], None))
        except (IndexError, KeyError, ValueError):
            raise MeshError(f"PLY file '{name}' header line {number}: cannot read '{line.strip()}'") from None
    if not fmt:
        raise MeshError(f"PLY file '{name}' has no 'format' line in its header")
    return fmt, elements


def _check_ply_ascii(data: bytes, elements: list[_Element], name: str, declared: str) -> None:
    lines = _text(data, f"ASCII PLY file '{name}'").split("\n")
    row = 0
    for element, count, properties in elements:
        for i in range(count):
            words = lines[row].split() if row < len(lines) else []
            # a list property's first number is its length; the line needs every value it announces
            need, k = 0, 0
            for _, item in properties:
                if item is None:
                    need += 1
                else:
                    k = int(words[need]) if len(words) > need and words[need].lstrip("-").isdigit() else 0
                    need += 1 + k
            if len(words) < need or not words:
                raise MeshError(
                    f"ASCII PLY file '{name}' is truncated: its header declares {declared}; the data ends "
                    f"at {element} {i:,} (data line {row + 1:,})"
                )
            row += 1


def _check_ply_binary(data: bytes, elements: list[_Element], fmt: str, name: str, declared: str) -> None:
    order = "<" if fmt == "binary_little_endian" else ">"
    offset = 0
    for _, count, properties in elements:
        if all(item is None for _, item in properties):
            offset += count * sum(size for size, _ in properties)  # fixed-size rows
        else:
            for _ in range(count):  # rows holding lists: walked by their length fields
                for size, item in properties:
                    if item is not None and offset + size <= len(data):
                        (k,) = struct.unpack_from(order + _PLY_UNSIGNED[size], data, offset)
                        offset += k * item
                    offset += size
                if offset > len(data):
                    break
        if offset > len(data):
            raise MeshError(
                f"binary PLY file '{name}' is truncated: its header declares {declared}, which need at least "
                f"{offset:,} bytes of data; the file holds {len(data):,}"
            )
