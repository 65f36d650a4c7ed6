"""Mesh files travel with a sweep's job (sweeps/meshes.py): which files a sweep ships, a worker that sees
them in place uses them there, one that does not writes the same bytes (checked by hash) into a folder
of its own laid out as around the scene; a log written on another machine is named host:path."""

from __future__ import annotations

import hashlib
import socket
from dataclasses import replace
from pathlib import Path

import pytest
from sweep_cases import spring_sweep_fixture  # noqa: F401 - a fixture

from rbcli.sweeps.execute import run_batch
from rbcli.sweeps.load import load_sweep
from rbcli.sweeps.meshes import local_scene_dir, mesh_names, read_mesh_files
from rbcli.sweeps.run import SweepOutputError, run_sweep, sweep_job


def test_the_shipped_files_are_every_relative_mesh_a_variant_can_name():
    scene = {
        "defaults": {"mesh": {"file": "meshes/a.obj"}},
        "bodies": [{"name": "b", "compound": [{"mesh": {"file": "../shared/b.obj"}}, {"shape": {"type": "box"}}]}],
    }
    axes = [
        (("bodies", 0, "mesh", "file"), ("c.stl", "meshes/a.obj")),
        (("bodies", 1), ({"name": "d", "mesh": {"file": "/abs/d.obj"}}, {"name": "e", "mesh": {"file": "e.ply"}})),
        (("simulation", "dt"), (0.1, 0.2)),
    ]
    # first seen order, each once; absolute paths are not shipped (they must exist on every worker)
    assert mesh_names(scene, axes) == ["meshes/a.obj", "../shared/b.obj", "c.stl", "e.ply"]


def test_a_worker_writes_the_files_it_cannot_see_and_checks_their_hash(tmp_path):
    scene_dir = tmp_path / "project" / "scenes"
    (scene_dir / "meshes").mkdir(parents=True)
    (tmp_path / "project" / "shared").mkdir()
    (scene_dir / "meshes" / "a.obj").write_bytes(b"v 0 0 0\n")
    (tmp_path / "project" / "shared" / "b.obj").write_bytes(b"v 1 1 1\n")
    files = read_mesh_files(["meshes/a.obj", "../shared/b.obj", "missing.obj"], scene_dir)
    assert [(name, digest) for name, digest, _ in files] == [
        ("meshes/a.obj", hashlib.sha256(b"v 0 0 0\n").hexdigest()),
        ("../shared/b.obj", hashlib.sha256(b"v 1 1 1\n").hexdigest()),
    ]  # a missing file is left to the loader: the variant's row says so, on the client and the workers
    assert local_scene_dir(str(scene_dir), files) == str(scene_dir)  # the same bytes in place: used there
    elsewhere = str(tmp_path / "not-on-this-machine")
    local = Path(local_scene_dir(elsewhere, files))
    assert not str(local).startswith(str(tmp_path))
    assert (local / "meshes" / "a.obj").read_bytes() == b"v 0 0 0\n"
    assert (local / "../shared/b.obj").resolve().read_bytes() == b"v 1 1 1\n"
    changed = ((files[0][0], files[0][1], b"v 9 9 9\n"),)  # bytes that do not match their hash
    with pytest.raises(ValueError, match="mesh file meshes/a.obj arrived damaged"):
        local_scene_dir(str(tmp_path / "other"), changed)


def test_a_log_written_on_another_machine_is_named_with_its_host(spring_sweep, tmp_path):
    spec = load_sweep(spring_sweep)
    job = replace(sweep_job(spec, tmp_path / "logs"), client_host="the-client-machine")
    (row,) = run_batch(job, [(0, spec.variant_values(0))])
    assert row["status"] == "completed"
    assert row["log"] == f"{socket.gethostname()}:{(tmp_path / 'logs' / 'variant-000000.mcap').resolve()}"
    (same,) = run_batch(replace(job, client_host=socket.gethostname()), [(0, spec.variant_values(0))])
    assert same["log"] == str((tmp_path / "logs" / "variant-000000.mcap").resolve())


def test_a_folder_of_rows_from_other_mesh_bytes_is_refused(tmp_path):
    """The folder's fingerprint holds the mesh files' hashes: after the mesh changes, resuming would mix
    rows of two different bodies, so the folder is refused (as for a changed scene) unless fresh."""
    root = Path(__file__).resolve().parents[2]
    (tmp_path / "meshes").mkdir()
    cube = (root / "scenes" / "meshes" / "cube.obj").read_bytes()
    (tmp_path / "meshes" / "cube.obj").write_bytes(cube)
    (tmp_path / "crate.yaml").write_text(
        "name: crate\nsimulation: {dt: 0.001, steps: 50, integrator: split2}\nbodies:\n"
        "  - {name: crate, mesh: {file: meshes/cube.obj, scale: 0.5}, spacing: 0.1, density: 500}\n"
    )
    sweep = tmp_path / "crate.sweep.yaml"
    sweep.write_text("scene: crate.yaml\naxes:\n  - path: bodies[0].velocity\n    values: [[0, 0, 1], [1, 0, 0]]\n")
    spec = load_sweep(sweep)
    assert run_sweep(spec, scheduler="serial", output=tmp_path / "out").ran == 2
    assert run_sweep(spec, scheduler="serial", output=tmp_path / "out").ran == 0  # the same bytes: resumes
    (tmp_path / "meshes" / "cube.obj").write_bytes(cube.replace(b"1", b"2", 1))
    with pytest.raises(SweepOutputError, match="mesh files have changed"):
        run_sweep(spec, scheduler="serial", output=tmp_path / "out")
    assert run_sweep(spec, scheduler="serial", output=tmp_path / "out", fresh=True).ran == 2
