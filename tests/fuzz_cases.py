"""Hypothesis strategies and checks shared by the fuzz tests (tests/*/test_*fuzz*.py) and by
benchmarks/fuzz_long.py, which runs the same properties with >= 10^4 examples.

What is generated:
- `valid_scene()`: a small scene that is valid by construction (every body form, orientation form,
  initial-motion form, generator, force type, contact), as a dict; `dump` writes it as YAML.
- `broken_scene()`: a valid scene with one or more targeted defects (a wrong type, a value out of
  range, NaN or inf, a huge array or count, degenerate inertia, a duplicate name, an unknown key, deep
  nesting), as YAML text.
- `run_arguments()`: command-line options of `rbsim run` (dt, duration, integrator, record-every,
  tolerance, compression, output path and format), valid and hostile.
- `damaged()`: a file's bytes truncated, with flipped bytes, overwritten or spliced.

The properties (`check_*`): the loader gives a scene or errors that are all located inside the file; a
command exits with a code of the documented set (0 ok, 1 invalid input, 2 usage, 3 diverged) and never
lets a traceback or an exception out.
"""

from __future__ import annotations

import copy
import math
import re
from pathlib import Path

import numpy as np
import yaml
from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

INTEGRATORS = (
    "euler-matrix",
    "euler-quat",
    "semi-implicit",
    "semi-implicit-gyro",
    "rk4",
    "split2",
    "split4",
    "exact",
    "exact4",
    "dopri5",
)
EXIT_CODES = {0, 1, 2, 3}  # ok, invalid input, usage error (Typer), diverged: docs/robustness.md


class Dumper(getattr(yaml, "CSafeDumper", yaml.SafeDumper)):  # type: ignore[misc]
    """PyYAML writes YAML 1.1, whose floats need a dot: it leaves the string '1e100' unquoted, which
    rbsim reads (YAML 1.2) as a number. Quote such strings."""


def _string(dumper, value: str):  # noqa: ANN001, ANN202
    looks_numeric = re.fullmatch(r"[-+]?(\.[0-9]+|[0-9]+(\.[0-9]*)?)([eE][-+]?[0-9]+)?", value.strip())
    return dumper.represent_scalar("tag:yaml.org,2002:str", value, style='"' if looks_numeric else None)


Dumper.add_representer(str, _string)
DUMPER = Dumper


def ci_settings(examples: int) -> settings:
    """Settings of the fuzz tests in the suite: a fixed example count, the same examples in every run
    (derandomize: CI is reproducible; benchmarks/fuzz_long.py draws fresh ones), no per-example deadline
    (a first run compiles kernels)."""
    return settings(
        max_examples=examples,
        derandomize=True,
        deadline=None,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )


def dump(data) -> str:
    return yaml.dump(data, Dumper=DUMPER, sort_keys=False, default_flow_style=None, width=200)


# -- valid scenes ---------------------------------------------------------------------------------------

small = st.floats(min_value=-2.0, max_value=2.0, allow_nan=False).map(lambda v: round(v, 4))
positive = st.floats(min_value=0.1, max_value=3.0).map(lambda v: round(v, 4))
vector3 = st.lists(small, min_size=3, max_size=3)


@st.composite
def orientation(draw) -> dict:
    q = np.array(draw(st.lists(st.floats(-1, 1), min_size=4, max_size=4)))
    q = q / np.linalg.norm(q) if np.linalg.norm(q) > 0.1 else np.array([1.0, 0, 0, 0])
    form = draw(st.sampled_from(["wxyz", "xyzw", "matrix", "axis_angle", "euler"]))
    if form == "wxyz":
        return {"wxyz": [float(v) for v in q]}
    if form == "xyzw":
        return {"xyzw": [float(q[1]), float(q[2]), float(q[3]), float(q[0])]}
    if form == "matrix":
        w, x, y, z = q
        m = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
        return {"matrix": [[float(v) for v in row] for row in m]}
    if form == "axis_angle":
        degrees = draw(st.booleans())
        angle = draw(st.floats(-360, 360) if degrees else st.floats(-7, 7))
        axis = q[1:] if np.linalg.norm(q[1:]) > 0.1 else np.array([1.0, 0.0, 0.0])
        return {"axis_angle": {"axis": [float(v) for v in axis], "angle": angle, "degrees": degrees}}
    convention = draw(st.sampled_from(["xyz", "ZYX", "zyz", "XYZ"]))
    return {
        "euler": {
            "angles": draw(st.lists(st.floats(-180, 180), min_size=3, max_size=3)),
            "convention": convention,
            "degrees": True,
        }
    }


@st.composite
def motion(draw) -> dict:
    """Optional initial motion keys (at most one of each alternative pair)."""
    keys: dict = {}
    linear = draw(st.sampled_from([None, "velocity", "momentum"]))
    if linear:
        keys[linear] = draw(vector3)
    angular = draw(st.sampled_from([None, "angular_momentum", "angular_velocity"]))
    if angular:
        value = draw(vector3)
        keys[angular] = draw(st.sampled_from([value, {"body": value}, {"world": value}]))
    if draw(st.booleans()):
        keys["orientation"] = draw(orientation())
    return keys


@st.composite
def particles(draw, radius: bool = False) -> dict:
    """A cloud that has inertia about every axis: a scaled tetrahedron plus up to 4 random points."""
    s = draw(positive)
    points = [[0.0, 0.0, 0.0], [s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]]
    points += draw(st.lists(vector3, max_size=4))
    masses = draw(st.one_of(positive, st.lists(positive, min_size=len(points), max_size=len(points))))
    cloud: dict = {"positions": points, "masses": masses}
    if radius or draw(st.booleans()):
        cloud["radius"] = draw(st.floats(0.01, 0.1).map(lambda v: round(v, 4)))
    return cloud


@st.composite
def shaped(draw) -> dict:
    """A primitive shape with a lattice of at most ~200 points."""
    kind = draw(st.sampled_from(["box", "sphere", "cylinder", "capsule", "ellipsoid"]))
    size = draw(st.floats(0.1, 0.5).map(lambda v: round(v, 3)))
    shape: dict = {"type": kind}
    if kind == "box":
        shape["size"] = [size, round(size * 0.7, 3), round(size * 0.5, 3)]
    elif kind == "sphere":
        shape["radius"] = size
    elif kind in ("cylinder", "capsule"):
        shape |= {"radius": round(size / 2, 3), "height": size, "axis": draw(st.sampled_from(["x", "y", "z"]))}
    else:
        shape["radii"] = [size, round(size * 0.8, 3), round(size * 0.6, 3)]
    body = {"shape": shape, "spacing": round(size / draw(st.integers(3, 5)), 4)}
    body |= draw(st.sampled_from([{"density": 500.0}, {"mass": 2.0}]))
    return body


@st.composite
def body_source(draw, contact: bool) -> dict:
    """The particles of one body: explicit, a shape, or a compound of both."""
    form = draw(st.sampled_from(["particles", "shape", "compound"]))
    if form == "particles":
        return {"particles": draw(particles(radius=contact))}
    if form == "shape":
        return draw(shaped())
    part = draw(shaped())
    return {
        "spacing": part.pop("spacing"),
        "density": 300.0,
        "compound": [
            part,
            {"particles": draw(particles(radius=True)), "offset": draw(vector3)},
        ],
    }


@st.composite
def valid_scene(draw, *, forces: bool = True, contact: bool | None = None, integrators=INTEGRATORS) -> dict:
    """A small scene (at most ~2,000 particles, 1-20 steps) that loads without errors."""
    with_contact = draw(st.booleans()) if contact is None else contact
    integrator = draw(st.sampled_from(integrators))
    dt = draw(st.sampled_from([1e-4, 1e-3, 2e-3, 0.01]))
    steps = draw(st.integers(1, 20))
    sim: dict = {"dt": dt, "integrator": integrator}
    sim |= {"steps": steps} if draw(st.booleans()) else {"duration": steps * dt}
    if integrator == "dopri5" and not with_contact and draw(st.booleans()):  # contact runs at a fixed dt
        sim["tolerance"] = draw(st.sampled_from([1e-3, 1e-6, 1e-9]))
    if draw(st.booleans()):
        sim["record"] = {
            "every": draw(st.integers(1, 3)),
            "streams": draw(
                st.sampled_from(
                    [
                        ["bodies"],
                        ["bodies", "invariants"],
                        ["bodies", "invariants", "particles"],
                        ["bodies", "contacts"],
                    ]
                )
            ),
        }
    scene: dict = {"name": draw(st.text(max_size=12)), "simulation": sim}
    if draw(st.booleans()):
        scene["gravity"] = [0.0, 0.0, -9.81]
    bodies: list = []
    names: list[str] = []
    for i in range(draw(st.integers(1, 4))):
        kind = draw(st.sampled_from(["body", "body", "grid", "random"]))
        template = draw(body_source(with_contact)) | draw(motion())
        if kind == "body":
            body = {"name": f"b{i}", **template, "position": [3.0 * i, 0.0, 1.0]}
            bodies.append(body)
            names.append(body["name"])
        elif kind == "grid":
            template.pop("orientation", None) if draw(st.booleans()) else None
            count = draw(st.lists(st.integers(1, 2), min_size=3, max_size=3))
            bodies.append(
                {
                    "grid": {
                        "name": f"g{i}",
                        "count": count,
                        "spacing": 1.5,
                        "origin": [3.0 * i, 5.0, 1.0],
                        "template": template,
                    }
                }
            )
        else:
            bodies.append(
                {
                    "random": {
                        "name": f"r{i}",
                        "count": draw(st.integers(1, 3)),
                        "seed": draw(st.integers(0, 9)),
                        "box": {"min": [3.0 * i, 10.0, 1.0], "max": [3.0 * i + 1, 11.0, 2.0]},
                        "template": template,
                    }
                }
            )
    scene["bodies"] = bodies
    if forces and draw(st.booleans()):
        terms = [{"type": "drag", "bodies": "all", "linear": 0.1}]
        if names:
            terms.append(
                {
                    "type": "spring",
                    "body": names[0],
                    "point": [0.0, 0.0, 0.0],
                    "anchor": [0.0, 0.0, 2.0],
                    "stiffness": draw(st.sampled_from([1.0, 100.0])),
                    "damping": 0.1,
                }
            )
            terms.append({"type": "impulse", "body": names[0], "time": 0.0, "vector": [0.0, 1.0, 0.0]})
            terms.append({"type": "torque", "body": names[0], "vector": [0.0, 0.0, 0.1]})
        terms.append({"type": "field", "per": "mass", "bodies": "all", "value": [0.0, 0.0, -1.0]})
        scene["forces"] = draw(st.lists(st.sampled_from(terms), min_size=1, max_size=3, unique_by=lambda t: t["type"]))
    if with_contact:
        scene["contact"] = {"ground": -10.0, "material": {"restitution": 0.5, "friction": 0.3}}
    return scene


# -- broken scenes --------------------------------------------------------------------------------------

JUNK = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0, -1, -0.0, 1e-320, 1e-300, 1e300, 1.7e308, 2**63, 10**6]),
    st.text(max_size=6),
    st.lists(st.floats(allow_nan=False, allow_infinity=False), max_size=4),
    st.lists(st.lists(st.integers(-3, 3), max_size=4), max_size=3),
    st.dictionaries(st.sampled_from(["type", "wxyz", "body", "x", "radius"]), st.integers(-2, 2), max_size=2),
)
DEFECTS = ("type", "range", "nonfinite", "huge", "degenerate", "duplicate", "unknown_key", "nesting")


def paths(value, prefix=()):
    """Every path into a nested value (not the root)."""
    if isinstance(value, dict):
        items = list(value.items())
    elif isinstance(value, list):
        items = list(enumerate(value))
    else:
        return
    for k, v in items:
        yield (*prefix, k)
        yield from paths(v, (*prefix, k))


def _get(value, path):
    for p in path:
        value = value[p]
    return value


def _numbers(data) -> list[tuple]:
    return [p for p in paths(data) if isinstance(_get(data, p), int | float) and not isinstance(_get(data, p), bool)]


def _first_cloud(scene: dict) -> dict | None:
    for path in paths(scene):
        if path[-1] == "particles" and isinstance(_get(scene, path), dict):
            return _get(scene, path)
    return None


@st.composite
def broken_scene(draw, huge_sizes=(1000, 5000), **valid_options) -> str:
    """YAML text of a valid scene with 1-3 defects (`DEFECTS`); some defects exist only as text (.nan, deep
    nesting) and are applied to the dumped text. huge_sizes: lengths of the huge explicit arrays (20,000
    entries take ~2 s to validate: the long fuzz run has them, CI does not)."""
    scene = copy.deepcopy(draw(valid_scene(**valid_options)))
    text_edits: list[tuple[str, str]] = []
    for _ in range(draw(st.integers(1, 3))):
        defect = draw(st.sampled_from(DEFECTS))
        all_paths = list(paths(scene))
        path = draw(st.sampled_from(all_paths))
        parent, key = _get(scene, path[:-1]), path[-1]
        numbers = _numbers(scene)
        if defect == "type":
            parent[key] = draw(JUNK)
        elif defect == "range" and numbers:
            p = draw(st.sampled_from(numbers))
            factor = draw(st.sampled_from([-1, 0, 1e-12, 1e12, 1e300, -1e300]))
            _get(scene, p[:-1])[p[-1]] = _get(scene, p) * factor
        elif defect == "nonfinite" and numbers:
            p = draw(st.sampled_from(numbers))
            marker = f"9.87654321e-{draw(st.integers(100, 199))}"
            _get(scene, p[:-1])[p[-1]] = float(marker)
            text_edits.append((repr(float(marker)), draw(st.sampled_from([".nan", ".inf", "-.inf", ".NaN", ".Inf"]))))
        elif defect == "huge":
            one = {"particles": {"positions": [[0, 0, 0]], "masses": 1, "radius": 0.1}}
            big = draw(st.sampled_from(["positions", "masses", "count", "grid", "random", "chain", "spacing", "steps"]))
            n = draw(st.sampled_from(huge_sizes))
            cloud = _first_cloud(scene)
            if big == "positions" and cloud is not None:
                cloud["positions"] = [[float(i % 7), float(i % 11), float(i % 13)] for i in range(n)]
            elif big == "masses" and cloud is not None:
                cloud["masses"] = [1.0] * n
            elif big == "count":
                scene["bodies"].append(
                    {
                        "name": "many",
                        "shape": {"type": "sphere", "radius": 0.1},
                        "count": draw(st.sampled_from([10**7, 10**9, 2**62])),
                    }
                )
            elif big == "grid":
                scene["bodies"].append(
                    {
                        "grid": {
                            "name": "huge",
                            "count": draw(st.sampled_from([[10**5, 10**5, 1], [100001, 1, 1], [2**40, 1, 1]])),
                            "spacing": 1.0,
                            "template": one,
                        }
                    }
                )
            elif big == "random":
                scene["bodies"].append(
                    {
                        "random": {
                            "name": "huge",
                            "count": 10**8,
                            "box": {"min": [0, 0, 0], "max": [1, 1, 1]},
                            "template": one,
                        }
                    }
                )
            elif big == "chain":
                scene["bodies"].append(
                    {
                        "chain": {
                            "name": "huge",
                            "count": draw(st.sampled_from([100001, 10**8, 2**40])),
                            "direction": [1.0, 0.0, 0.0],
                            "spacing": 0.1,
                            "joint": {"type": "ball"},
                            "template": one,
                        }
                    }
                )
            elif big == "spacing":
                scene["bodies"].append(
                    {
                        "name": "fine",
                        "shape": {"type": "box", "size": [1, 1, 1]},
                        "spacing": draw(st.sampled_from([1e-3, 1e-6, 1e-300])),
                    }
                )
            else:
                scene["simulation"].pop("duration", None)
                scene["simulation"]["steps"] = draw(st.sampled_from([10**13, 2**63 - 1, 10**30]))
        elif defect == "degenerate":
            s = draw(st.sampled_from([1.0, 1e-6, 1e-12, 1e6]))
            kind = draw(st.sampled_from(["line", "point", "single", "nearly-line", "plane-zero-mass"]))
            cloud: dict
            if kind == "line":
                cloud = {"positions": [[0, 0, 0], [s, s, 0], [2 * s, 2 * s, 0]], "masses": 1.0}
            elif kind == "point":
                cloud = {"positions": [[s, s, s]] * 3, "masses": [1.0, 2.0, 3.0]}
            elif kind == "single":
                cloud = {"positions": [[0, 0, 0]], "masses": 1.0}
            elif kind == "nearly-line":
                cloud = {"positions": [[0, 0, 0], [1, 0, 0], [2, s * 1e-9, 0]], "masses": 1.0}
            else:
                cloud = {"positions": [[0, 0, 0], [1, 0, 0], [0, 1, 0]], "masses": [1.0, 1e-320, 1e-320]}
            scene["bodies"].append({"name": "flat", "particles": cloud})
        elif defect == "duplicate":
            if draw(st.booleans()):
                scene["bodies"].append(copy.deepcopy(scene["bodies"][0]))
            else:
                text_edits.append(("simulation:", "simulation: {dt: 0.5}\nsimulation:"))
        elif defect == "unknown_key":
            target = draw(st.sampled_from([p for p in all_paths if isinstance(_get(scene, p), dict)] or [()]))
            holder = _get(scene, target)
            holder[draw(st.sampled_from(["junk", "masss", "rotation", "velocty", "Name", "<<"]))] = draw(JUNK)
        elif defect == "nesting":
            depth = draw(st.sampled_from([50, 150, 1000, 5000]))
            opener, closer = draw(st.sampled_from([("[", "]"), ("{a: ", "}")]))
            marker = "nested-marker-0"
            parent[key] = marker
            text_edits.append((marker, opener * depth + "1" + closer * depth))
    text = dump(scene)
    for old, new in text_edits:
        text = text.replace(old, new, 1)
    return text


# -- command-line options of `rbsim run` ----------------------------------------------------------------

NUMBER_TEXT = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(
        [
            "nan",
            "inf",
            "-inf",
            "0",
            "-0",
            "-1",
            "1e-300",
            "1e300",
            "1e-9",
            "5e-324",
            "1e",
            "abc",
            "",
            "0x10",
            "1_000",
            " 1",
            "1e-3",
            "0.01",
            "0.001",
            "2",
        ]
    ),
)
OUTPUT_NAMES = st.one_of(
    st.sampled_from(
        [
            "out.mcap",
            "out.rrd",
            "out.MCAP",
            "out.csv",
            "out",
            "sub/dir/out.mcap",
            ".mcap",
            "dir/",
            "out.partial.mcap",
            "a b.rrd",
            "file.txt/x.mcap",
            "",
            "/proc/x.mcap",
            "existing_dir",
        ]
    ),
    st.text(
        alphabet=st.characters(blacklist_categories=["Cs"], blacklist_characters="\x00/"), min_size=1, max_size=10
    ).map(lambda s: s + ".mcap"),
)


@st.composite
def run_arguments(draw) -> list[str]:
    """Options for `rbsim run SCENE`: each present or not, valid or hostile; `-o` names a file under the
    example's folder (the folder holds a file `file.txt` and a folder `existing_dir`)."""
    args: list[str] = []
    if draw(st.booleans()):
        args += ["--dt", draw(st.one_of(NUMBER_TEXT, st.sampled_from(["0.001", "0.01", "1e-4"])))]
    if draw(st.booleans()):
        args += ["--duration", draw(st.one_of(NUMBER_TEXT, st.sampled_from(["0.01", "0.005", "0.1"])))]
    if draw(st.booleans()):
        args += ["--integrator", draw(st.one_of(st.sampled_from(INTEGRATORS), st.text(max_size=8)))]
    if draw(st.booleans()):
        every = st.one_of(st.integers(-(2**70), 2**70).map(str), st.sampled_from(["0", "1", "2", "-1", "1.5", "x"]))
        args += ["--record-every", draw(every)]
    if draw(st.booleans()):
        args += ["--tolerance", draw(st.one_of(NUMBER_TEXT, st.sampled_from(["1e-6", "1e-3"])))]
    if draw(st.booleans()):
        args += ["--compression", draw(st.sampled_from(["zstd", "lz4", "none", "gzip", "", "ZSTD"]))]
    args += ["-o", draw(OUTPUT_NAMES)]
    if draw(st.booleans()):
        args.append("--allow-large")
    return args


def planned_steps(args: list[str], dt: float, duration: float) -> float:
    """Steps the options would plan (inf when unparsable: such a run is refused before any work)."""
    values = dict(zip(args[::2], args[1::2], strict=False))
    try:
        dt = float(values.get("--dt", dt))
        duration = float(values.get("--duration", duration))
        return duration / dt
    except (ValueError, ZeroDivisionError, OverflowError):
        return math.inf


# -- damaged files ------------------------------------------------------------------------------------


@st.composite
def damaged(draw, raw: bytes) -> bytes:
    """`raw` truncated, with flipped bytes, a slice overwritten or removed, or random bytes after its start."""
    kind = draw(st.sampled_from(["truncate", "flip", "overwrite", "splice", "random-tail", "random", "empty"]))
    n = len(raw)
    if kind == "truncate":
        return raw[: draw(st.integers(0, max(n - 1, 0)))]
    if kind == "flip":
        data = bytearray(raw)
        for _ in range(draw(st.integers(1, 8))):
            i = draw(st.integers(0, n - 1))
            data[i] ^= 1 << draw(st.integers(0, 7))
        return bytes(data)
    if kind == "overwrite":
        i = draw(st.integers(0, n - 1))
        return raw[:i] + draw(st.binary(min_size=1, max_size=64)) + raw[i + 64 :]
    if kind == "splice":
        i = draw(st.integers(0, n - 1))
        j = draw(st.integers(i, n))
        return raw[:i] + raw[j:]
    if kind == "random-tail":
        return raw[: draw(st.integers(0, min(n, 64)))] + draw(st.binary(max_size=256))
    if kind == "random":
        return draw(st.binary(max_size=512))
    return b""


# -- the properties ------------------------------------------------------------------------------------

LOCATED = re.compile(r"^(?P<file>.+):(?P<line>\d+):(?P<col>\d+): error: \S")


def check_analysis(spec, issues, text: str | bytes) -> None:
    """The loader's contract: a spec, or at least one error; every error located at a line and column
    inside the file (the line after the last, for an error at the end of the text)."""
    from rbcli.scene.spec import SceneSpec

    assert spec is None or isinstance(spec, SceneSpec)
    errors = [i for i in issues if i.severity == "error"]
    if spec is None:
        assert errors, "rejected without an error"
    lines = (text.decode("utf-8", "replace") if isinstance(text, bytes) else text).count("\n") + 2
    for issue in issues:
        assert issue.message
        assert issue.location is not None, f"unlocated: {issue}"
        assert 1 <= issue.location.line <= lines and issue.location.column >= 1, f"outside the file: {issue}"
    if spec is not None:
        for body in spec.bodies:
            assert math.isclose(float((body.orientation_wxyz**2).sum()), 1.0, rel_tol=1e-9)
            assert np.all(body.particle_mass > 0) and np.all(np.isfinite(body.particle_position))


def check_command(result, *, codes=EXIT_CODES, message_on: str = "stderr") -> None:
    """A CliRunner result: no exception escaped (only typer's exit), a documented exit code, no traceback
    printed, and a failure says something (`message_on`: where the command prints its errors)."""
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        import traceback

        trace = "".join(traceback.format_exception(result.exception))
        raise AssertionError(f"exception escaped: {trace}\nstderr: {result.stderr}")
    out, err = result.stdout, result.stderr
    assert result.exit_code in codes, f"exit {result.exit_code}\nstdout: {out}\nstderr: {err}"
    assert "Traceback" not in out + err, out + err
    if result.exit_code != 0:
        said = err if message_on == "stderr" else out + err
        assert said.strip(), f"exit {result.exit_code} with nothing said"


def write_mesh_files() -> dict[str, bytes]:
    """Closed meshes in several formats (the bytes the fuzzer damages): OBJ text, binary and ASCII STL, PLY."""
    import trimesh

    repo = Path(__file__).resolve().parents[1]
    files = {name: (repo / "scenes" / "meshes" / name).read_bytes() for name in ("cube.obj", "tetra.obj")}
    box = trimesh.creation.box(extents=(0.4, 0.3, 0.2))
    files["box.stl"] = box.export(file_type="stl")
    files["box_ascii.stl"] = box.export(file_type="stl_ascii").encode()
    files["box.ply"] = box.export(file_type="ply")
    return files


# --- the properties' shared steps (the suite's tests and benchmarks/fuzz_long.py run the same ones) ----

# a scene that runs in a few milliseconds: the base of the option and file fuzzers
TINY = """\
name: tiny
simulation: {dt: 0.001, steps: 10, integrator: split2}
bodies:
  - name: b
    particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], masses: 1}
    angular_velocity: [1, 2, 3]
"""


def load_scene_file(text: str, folder: Path):  # noqa: ANN201 - (SceneSpec | None, issues, path)
    """`text` written to a real file in `folder` and loaded through the public API: (spec, [], path) or
    (None, the SceneError's issues, path)."""
    import rbcli
    from rbcli.scene.spec import SceneError

    path = Path(folder) / "broken.yaml"
    path.write_text(text, encoding="utf-8", errors="surrogatepass")
    try:
        return rbcli.load_scene(path), [], path
    except SceneError as exc:
        return None, exc.issues, path


def analyse_mesh_file(name: str, raw: bytes, folder: Path):  # noqa: ANN201 - (spec, issues, text, stderr)
    """A scene whose one body is the mesh file `name` holding `raw`, analysed with stderr captured (a
    library's logged traceback would reach the terminal): (spec, issues, scene text, what was printed)."""
    import contextlib
    import io

    from rbcli.scene.load import analyse_scene

    (Path(folder) / name).write_bytes(raw)
    scene = Path(folder) / "mesh.yaml"
    body = f"{{name: m, mesh: {{file: {name}, scale: 0.5}}, spacing: 0.05, density: 100}}"
    text = f"simulation: {{dt: 0.001, steps: 2}}\nbodies:\n  - {body}\n"
    scene.write_text(text)
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr):
        spec, issues = analyse_scene(scene)
    return spec, issues, text, stderr.getvalue()
