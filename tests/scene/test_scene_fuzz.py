"""Property-based fuzzing of the loader: mutated valid scenes give a SceneSpec or a SceneError, nothing else.

Mutations act on the parsed data (delete a key, change a value's type, insert junk keys and values, swap
scalars and lists, duplicate list entries, absurd numbers) and on the text itself (insert, delete or
replace characters), so both the YAML layer and the schema/semantic layers see hostile input. Every
issue must carry a location inside the file.
"""

from __future__ import annotations

import copy
import math

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rbcli.scene.load import analyse_scene_text
from rbcli.scene.spec import SceneSpec

SEEDS = [
    {
        "name": "t-handle",
        "simulation": {"dt": 0.001, "duration": 20.0, "integrator": "euler-matrix"},
        "gravity": [0, 0, -9.81],
        "bodies": [
            {
                "name": "handle",
                "particles": {
                    "positions": [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]],
                    "masses": [1.0, 0.5, 0.5, 0.25],
                },
                "position": [0, 0, 1],
                "velocity": [0, 0, 0],
                "orientation": {"wxyz": [1, 0, 0, 0]},
                "angular_momentum": [0, 0, 0],
            }
        ],
    },
    {
        "simulation": {"dt": 0.01, "steps": 10, "record": {"rate": 10, "streams": ["bodies", "particles"]}},
        "defaults": {"spacing": 0.1, "density": 100.0},
        "bodies": [
            {"name": "b", "shape": {"type": "box", "size": [0.4, 0.3, 0.2]}, "angular_velocity": {"body": [0, 0, 1]}},
            {"name": "s", "shape": {"type": "sphere", "radius": 0.2}, "orientation": {"xyzw": [0, 0, 0, 1]}},
            {
                "name": "c",
                "shape": {"type": "capsule", "radius": 0.1, "height": 0.3, "axis": "x"},
                "orientation": {"euler": {"angles": [10, 20, 30], "convention": "ZYX", "degrees": True}},
                "mass": 2.0,
            },
            {"name": "e", "shape": {"type": "ellipsoid", "radii": [0.2, 0.3, 0.4]}, "count": 50},
        ],
        "forces": [{"type": "spring", "stiffness": 1.0}],
        "contact": {"restitution": 0.5},
    },
    {
        "simulation": {"dt": 0.01, "duration": 1.0, "integrator": "dopri5", "tolerance": 1e-6, "seed": 3},
        "bodies": [
            {
                "name": "h",
                "spacing": 0.05,
                "compound": [
                    {"shape": {"type": "cylinder", "radius": 0.03, "height": 0.3}, "density": 700},
                    {
                        "particles": {"positions": [[0, 0, 0]], "masses": 1.0, "radius": 0.05},
                        "offset": [0, 0, 0.2],
                        "orientation": {"axis_angle": {"axis": [1, 0, 0], "angle": 0.3}},
                    },
                ],
                "orientation": {"matrix": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
            },
            {
                "grid": {
                    "name": "g",
                    "count": [2, 2, 1],
                    "spacing": 1.0,
                    "template": {"shape": {"type": "sphere", "radius": 0.2}, "spacing": 0.1, "density": 1.0},
                }
            },
            {
                "random": {
                    "name": "r",
                    "count": 3,
                    "seed": 1,
                    "box": {"min": [0, 0, 0], "max": [1, 1, 1]},
                    "velocity_sigma": 0.1,
                    "template": {"particles": {"positions": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "masses": 1}},
                }
            },
        ],
    },
]

JUNK = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, 1e-300, 1e300, 1e308, -0.0, 2**63, 10**6]),
    st.text(max_size=8),
    st.sampled_from(["box", "sphere", "world", "body", "xyz", "ZZZ", "euler-matrix", "a.mcap", "", "rk5"]),
    st.lists(st.floats(allow_nan=False, min_value=-1e3, max_value=1e3), max_size=5),
    st.lists(st.lists(st.integers(-3, 3), min_size=3, max_size=3), max_size=4),
    st.dictionaries(st.sampled_from(["type", "wxyz", "body", "size", "x", "radius"]), st.integers(-2, 2), max_size=2),
)


def paths(value, prefix=()):
    """Every path into a nested value (the root included)."""
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from paths(v, (*prefix, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from paths(v, (*prefix, i))


def get(value, path):
    for p in path:
        value = value[p]
    return value


@st.composite
def mutated_scene(draw):
    data = copy.deepcopy(draw(st.sampled_from(SEEDS)))
    for _ in range(draw(st.integers(1, 4))):
        all_paths = list(paths(data))
        path = draw(st.sampled_from(all_paths))
        op = draw(st.sampled_from(["delete", "replace", "insert", "swap", "duplicate", "scale"]))
        if not path:
            if op == "replace":
                data = draw(JUNK)
            continue
        parent, key = get(data, path[:-1]), path[-1]
        target = parent[key]
        if op == "delete":
            del parent[key]
        elif op == "replace":
            parent[key] = draw(JUNK)
        elif op == "insert" and isinstance(target, dict):
            target[draw(st.sampled_from(["junk", "mass", "spacing", "grid", "<<", "velocity", "orientation"]))] = draw(
                JUNK
            )
        elif op == "insert" and isinstance(target, list):
            target.insert(draw(st.integers(0, len(target))), draw(JUNK))
        elif op == "swap":
            parent[key] = [target] if not isinstance(target, list) else (target[0] if target else None)
        elif op == "duplicate" and isinstance(target, list) and target:
            target.append(copy.deepcopy(target[0]))
        elif op == "scale" and isinstance(target, int | float) and not isinstance(target, bool):
            parent[key] = target * draw(st.sampled_from([-1, 0, 1e-9, 1e9, 1e300]))
    return data


# numpy warnings (overflow, invalid) mean a number slipped past the checks: fail on them too
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


def check(text: str | bytes) -> None:
    spec, issues = analyse_scene_text(text, "fuzz.yaml")
    assert spec is None or isinstance(spec, SceneSpec)
    if spec is None:
        assert any(i.severity == "error" for i in issues)
    for issue in issues:
        assert issue.message
        if issue.location is not None:
            assert issue.location.line >= 1 and issue.location.column >= 1
    if spec is not None:
        for body in spec.bodies:
            assert math.isclose(float((body.orientation_wxyz**2).sum()), 1.0, rel_tol=1e-9)
            assert body.particle_mass.min() > 0 and len(body.particle_mass) == len(body.particle_position)


def dump(data) -> str:
    return yaml.dump(data, Dumper=DUMPER, sort_keys=False, default_flow_style=None)


DUMPER = getattr(yaml, "CSafeDumper", yaml.SafeDumper)

# ~3300 loader runs in all, ~20 s: 1200 data mutations, 800 text mutations (each as str and bytes), 500 blobs
QUICK = dict(deadline=None, database=None, suppress_health_check=list(HealthCheck))


@settings(max_examples=1200, **QUICK)
@given(mutated_scene())
def test_mutated_data_never_crashes_the_loader(data):
    check(dump(data))


@settings(max_examples=800, **QUICK)
@given(
    st.sampled_from(SEEDS),
    st.lists(
        st.tuples(st.integers(0, 10_000), st.integers(0, 3), st.text(max_size=3)),
        min_size=1,
        max_size=3,
    ),
)
def test_mutated_text_never_crashes_the_loader(data, edits):
    text = dump(data)
    for position, delete, insert in edits:
        position %= len(text) + 1
        text = text[:position] + insert + text[position + delete :]
    check(text)
    check(text.encode("utf-8", errors="surrogatepass"))


@settings(max_examples=500, **QUICK)
@given(st.binary(max_size=200))
def test_random_bytes_never_crash_the_loader(raw):
    check(raw)
