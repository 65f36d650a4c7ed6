"""Mesh files that travel with a sweep's job, so its workers need no shared file system.

The client reads every mesh file a variant can name (`mesh: {file: ...}` anywhere in the base scene or
in an axis's values, or an axis on a `...mesh.file` path) relative to the base scene's folder, and the
job carries each file's bytes with their sha256. A worker that finds the same bytes at the same place
(one machine, or a shared file system) loads them from there; any other writes them, checked against
their hash, into a folder of its own (under the system's temporary folder, named by the files' hashes,
so the workers of a machine share it and a changed file never mixes with the old one) laid out as
around the scene, and loads the variants from there. The files are the same bytes either way, so the
rows are too.

Absolute mesh paths are not shipped: they must exist on every worker.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

# (path as the scene writes it, relative to the scene's folder; sha256 hex; the file's bytes)
MeshFile = tuple[str, str, bytes]
LOCAL_FOLDER = "rbsim-sweep-meshes"
# Where a worker found or wrote each job's meshes: the scene folder its variants load from (one check
# per job and process, not one per variant).
_SCENE_DIRS: dict[tuple[str, str], str] = {}


def mesh_names(scene_data: Any, axes: Iterable[tuple[tuple[str | int, ...], tuple[Any, ...]]]) -> list[str]:
    """Every relative mesh path the base scene or an axis value names, in first-seen order. axes:
    (path, values) of each axis."""
    names = list(_mesh_files_in(scene_data))
    for path, values in axes:
        if len(path) >= 2 and path[-2:] == ("mesh", "file"):
            names.extend(v for v in values if isinstance(v, str))
        for value in values:
            names.extend(_mesh_files_in(value))
    return [n for n in dict.fromkeys(names) if not os.path.isabs(n)]


def read_mesh_files(names: Iterable[str], scene_dir: str | Path) -> tuple[MeshFile, ...]:
    """The bytes and hash of each named file that exists beside the scene (one that does not is left to
    the scene loader, which makes the variant's row say so, on the client and the workers alike)."""
    files = []
    for name in names:
        try:
            data = (Path(scene_dir) / name).read_bytes()
        except OSError:
            continue
        files.append((name, hashlib.sha256(data).hexdigest(), data))
    return tuple(files)


def local_scene_dir(scene_dir: str, files: tuple[MeshFile, ...]) -> str:
    """The folder this process loads the variants from: `scene_dir` when every file there has the job's
    bytes, else a folder of this machine where they are written. Raises ValueError for bytes that do
    not match their hash (damaged on the way)."""
    if not files:
        return scene_dir
    token = hashlib.sha256("\n".join(f"{name} {digest}" for name, digest, _ in files).encode()).hexdigest()[:24]
    key = (scene_dir, token)
    if key not in _SCENE_DIRS:
        for name, digest, data in files:
            if hashlib.sha256(data).hexdigest() != digest:
                raise ValueError(f"mesh file {name} arrived damaged (its sha256 is not the client's {digest})")
        if all(_holds(Path(scene_dir) / name, digest) for name, digest, _ in files):
            _SCENE_DIRS[key] = scene_dir
        else:
            _SCENE_DIRS[key] = _write_local(token, files)
    return _SCENE_DIRS[key]


def _mesh_files_in(value: Any) -> Iterator[str]:
    """The `file` of every `mesh:` mapping inside a scene value."""
    if isinstance(value, dict):
        for key, item in value.items():
            if key == "mesh" and isinstance(item, dict) and isinstance(item.get("file"), str):
                yield item["file"]
            yield from _mesh_files_in(item)
    elif isinstance(value, list):
        for item in value:
            yield from _mesh_files_in(item)


def _holds(path: Path, digest: str) -> bool:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest() == digest
    except OSError:
        return False


def _write_local(token: str, files: tuple[MeshFile, ...]) -> str:
    """Write the files around a scene folder of this machine; its path. A name may climb out of the
    scene's folder (`../meshes/a.obj`): the scene folder is nested as deep as the deepest climb, so every
    file lands inside the job's own folder."""
    root = Path(tempfile.gettempdir()) / LOCAL_FOLDER / token
    depth = max(_climb(name) for name, _, _ in files)
    scene_dir = root.joinpath("scene", *["up"] * depth)
    for name, digest, data in files:
        target = Path(os.path.normpath(scene_dir / name))
        if _holds(target, digest):
            continue
        target.parent.mkdir(parents=True, exist_ok=True)
        temporary = target.with_name(f".{target.name}.{os.getpid()}.tmp")
        temporary.write_bytes(data)
        os.replace(temporary, target)  # whole or absent: another worker of this machine may read it now
    return str(scene_dir)


def _climb(name: str) -> int:
    """How many folders above the scene's a relative path reaches (`../../a.obj`: 2)."""
    climbs = 0
    for part in Path(os.path.normpath(name)).parts:
        if part != "..":
            break
        climbs += 1
    return climbs
