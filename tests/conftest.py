"""Shared test helpers: build scenes in Python without YAML."""

from __future__ import annotations

import numpy as np
import pytest

from rbcli.scene.spec import BodySpec, RecordSpec, SceneSpec, SimulationSpec

# a small asymmetric particle cloud (the tutorial's "T-handle"-like body), body frame [m] / [kg]
HANDLE_POSITIONS = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]])
HANDLE_MASSES = np.array([1.0, 0.5, 0.5, 0.25])


# Test files that compile the same heavy kernels run on one xdist worker (pyproject's `--dist loadgroup`):
# the joint solver's stack (~40 s of numba compile) and the contact search's (~25 s) are compiled once and
# then loaded from numba's cache, where two workers starting them at once both compiled them (the joint
# files alone: 229 CPU-s on two workers against 195 s on one, measured). Every other file is a group of its
# own, as `--dist loadfile` made it.
KERNEL_FAMILIES = ("joint", "contact")


@pytest.hookimpl(tryfirst=True)  # before xdist's own hook, which reads the marks into the node ids
def pytest_collection_modifyitems(config, items):  # noqa: ANN001, ANN201
    for item in items:
        name = item.path.name
        family = next((f for f in KERNEL_FAMILIES if f in name), None)
        item.add_marker(pytest.mark.xdist_group(f"kernels-{family}" if family else str(item.path)))


def make_body(name: str = "b", **overrides) -> BodySpec:
    fields = dict(
        name=name,
        particle_position=HANDLE_POSITIONS,
        particle_mass=HANDLE_MASSES,
        position=np.zeros(3),
        orientation_wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
    )
    fields.update(overrides)
    return BodySpec(**fields)


def make_scene(bodies, *, dt=1e-3, duration=1.0, integrator="euler-matrix", gravity=None, every=1,
               streams=("bodies", "invariants")) -> SceneSpec:  # fmt: skip
    sim = SimulationSpec(dt=dt, duration=duration, integrator=integrator, record=RecordSpec(every, tuple(streams)))
    return SceneSpec(name="test", simulation=sim, bodies=tuple(bodies), gravity=gravity, source_text="name: test\n")


def random_bodies(count: int, seed: int = 0, **overrides) -> list[BodySpec]:
    """Bodies with random clouds, orientations, momenta (reproducible)."""
    rng = np.random.default_rng(seed)
    bodies = []
    for i in range(count):
        q = rng.normal(size=4)
        bodies.append(
            make_body(
                f"b{i}",
                particle_position=rng.normal(size=(5, 3)),
                particle_mass=rng.uniform(0.5, 2.0, size=5),
                position=rng.normal(size=3),
                orientation_wxyz=q / np.linalg.norm(q),
                velocity=rng.normal(size=3),
                angular_momentum=rng.normal(size=3),
                **overrides,
            )
        )
    return bodies


@pytest.fixture
def handle_scene():
    return make_scene([make_body("handle", angular_momentum=np.array([0.01, 0.02, 0.03]))])
