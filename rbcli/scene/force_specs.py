"""Typed force specs: the entries of a scene's `forces:` list, as the loader produces them.

Every spec is a frozen dataclass subclassing `ForceSpec` (fields `kind`, fixed per class, and
`location`); all other fields are keyword-only. Points are body-fixed and given in the body's own
(user) frame, the frame and origin of its particle coordinates (NOT about the centre of mass); a
point can instead name a particle by its index in the body's particle list; neither = the centre of
mass. Vectors are world-frame unless `frame="body"` (they then turn with the body). SI units.
The YAML shapes the loader maps onto these classes are in docs/forces.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rbcli.scene.spec import ForceSpec, SourceLocation

FRAMES = ("world", "body")
FIELD_PER = ("mass", "particle")


@dataclass(frozen=True, kw_only=True)
class BodyPoint:
    """A point fixed in a body: `point` [m] (3,) in the body's own frame, or `particle` (an index into
    the body's particles, 0-based), or neither (the centre of mass)."""

    body: str
    point: np.ndarray | None = None
    particle: int | None = None


@dataclass(frozen=True, kw_only=True)
class Schedule:
    """A time profile s(t) [1] that multiplies a force, torque or field; 0 outside start <= t < stop.

    kind "constant": s = value; "piecewise_linear": through (times [s], values), held at the end
    values outside them; "sine": s = offset + amplitude sin(2 pi frequency t + phase), t absolute [s].
    """

    kind: str = "constant"
    start: float = -math.inf
    stop: float = math.inf
    value: float = 1.0
    times: tuple[float, ...] = ()
    values: tuple[float, ...] = ()
    amplitude: float = 1.0
    frequency: float = 0.0  # [Hz]
    phase: float = 0.0  # [rad]
    offset: float = 0.0


@dataclass(frozen=True, kw_only=True)
class ForceSpring(ForceSpec):
    """Spring-damper: f = -(k (l - l0) + c dl/dt) e along the line from end_b to end_a.

    end_b None: end_a is tied to the world point `anchor` [m] (3,). stiffness k [N/m] >= 0,
    rest_length l0 [m] >= 0, damping c [N s/m] >= 0 (k = 0: a pure damper).
    """

    kind: str = field(default="spring", init=False)
    end_a: BodyPoint
    end_b: BodyPoint | None = None
    anchor: np.ndarray | None = None
    stiffness: float
    rest_length: float = 0.0
    damping: float = 0.0


@dataclass(frozen=True, kw_only=True)
class ForceAtPoint(ForceSpec):
    """A force `vector` [N] (3,) at a body point, world or body frame, scaled by an optional schedule."""

    kind: str = field(default="force", init=False)
    at: BodyPoint
    vector: np.ndarray
    frame: str = "world"
    schedule: Schedule | None = None


@dataclass(frozen=True, kw_only=True)
class ForceTorque(ForceSpec):
    """A pure torque `vector` [N m] (3,) on a body, world or body frame, scaled by an optional schedule."""

    kind: str = field(default="torque", init=False)
    body: str
    vector: np.ndarray
    frame: str = "world"
    schedule: Schedule | None = None


@dataclass(frozen=True, kw_only=True)
class ForceDrag(ForceSpec):
    """Drag on each listed body (None: every body): F = -(linear + quadratic |v|) v [N],
    tau = -(angular_linear + angular_quadratic |omega|) omega [N m]; coefficients >= 0,
    [N s/m], [N s^2/m^2], [N m s], [N m s^2]."""

    kind: str = field(default="drag", init=False)
    bodies: tuple[str, ...] | None = None
    linear: float = 0.0
    quadratic: float = 0.0
    angular_linear: float = 0.0
    angular_quadratic: float = 0.0


@dataclass(frozen=True, kw_only=True)
class ForceImpulse(ForceSpec):
    """An impulse `vector` J [N s] (3,) at a body point at `time` [s]: P += J, L += r x J, exactly."""

    kind: str = field(default="impulse", init=False)
    at: BodyPoint
    time: float
    vector: np.ndarray
    frame: str = "world"


@dataclass(frozen=True, kw_only=True)
class ForceField(ForceSpec):
    """A field evaluated at every particle of the listed bodies (None: every body), world frame:
    a(x) = value + gradient (x - origin); per "mass": F_i = m_i a(x_i) (value [m/s^2], gradient
    [1/s^2]); per "particle": F_i = a(x_i) (value [N], gradient [N/m]). Optional schedule."""

    kind: str = field(default="field", init=False)
    per: str = "mass"
    bodies: tuple[str, ...] | None = None
    value: np.ndarray = field(default_factory=lambda: np.zeros(3))
    gradient: np.ndarray | None = None  # (3, 3): a_j += gradient[j][k] (x_k - origin_k)
    origin: np.ndarray | None = None  # [m] (3,), world; default the world origin
    schedule: Schedule | None = None


# ---- the YAML shape (docs/forces.md) -> specs; for the loader, after schema validation -----------------

_KEYS = {
    "spring": {"body", "point", "particle", "anchor", "bodies", "points", "particles", "stiffness", "rest_length",
               "damping"},
    "force": {"body", "point", "particle", "vector", "frame", "schedule"},
    "torque": {"body", "vector", "frame", "schedule"},
    "drag": {"bodies", "linear", "quadratic", "angular_linear", "angular_quadratic"},
    "impulse": {"body", "point", "particle", "time", "vector", "frame"},
    "field": {"per", "bodies", "value", "gradient", "origin", "schedule"},
}  # fmt: skip
_SCHEDULE_KEYS = {"kind", "start", "stop", "value", "times", "values", "amplitude", "frequency", "phase", "offset"}


def _array(value: object) -> np.ndarray | None:
    return None if value is None else np.asarray(value, dtype=np.float64)


def _required(entry: dict, key: str, default: object = None) -> Any:
    """entry[key] (or `default` when absent), which this force type needs; ValueError when missing or null."""
    value = entry.get(key, default)
    if value is None:
        raise ValueError(f"force {entry.get('type')!r}: missing required key {key!r}")
    return value


def _vector(entry: dict, key: str, default: object = None) -> np.ndarray:
    """A required array entry (a vector or matrix) as float64."""
    return np.asarray(_required(entry, key, default), dtype=np.float64)


def _bodies(value: object) -> tuple[str, ...] | None:
    if value is None or value == "all":
        return None
    if isinstance(value, str):
        return (value,)
    return tuple(value)  # type: ignore[arg-type]


def schedule_from_mapping(entry: dict) -> Schedule:
    """A Schedule from its YAML mapping `{kind, start, stop, value | times, values | amplitude, ...}`."""
    unknown = set(entry) - _SCHEDULE_KEYS
    if unknown:
        raise ValueError(f"unknown schedule keys {sorted(unknown)}; allowed: {sorted(_SCHEDULE_KEYS)}")
    entry = dict(entry)
    for key in ("times", "values"):
        if key in entry:
            entry[key] = tuple(float(v) for v in entry[key])
    return Schedule(**entry)


def force_spec_from_mapping(entry: dict, location: SourceLocation | None = None) -> ForceSpec:
    """A typed force spec from one `forces:` entry as docs/forces.md writes it (a plain mapping of
    numbers, strings and lists, already checked against the schema). ValueError on a wrong shape."""
    kind = entry.get("type")
    if kind not in _KEYS:
        raise ValueError(f"unknown force type {kind!r}; known: {', '.join(_KEYS)}")
    unknown = set(entry) - _KEYS[kind] - {"type"}
    if unknown:
        raise ValueError(f"force {kind!r}: unknown keys {sorted(unknown)}; allowed: {sorted(_KEYS[kind])}")
    get = entry.get
    schedule_entry = get("schedule")
    schedule = schedule_from_mapping(schedule_entry) if schedule_entry is not None else None

    def at() -> BodyPoint:
        return BodyPoint(body=_required(entry, "body"), point=_array(get("point")), particle=get("particle"))

    if kind == "spring":
        common = dict(stiffness=get("stiffness", 0.0), rest_length=get("rest_length", 0.0),
                      damping=get("damping", 0.0), location=location)  # fmt: skip
        if "bodies" in entry:
            names = list(_required(entry, "bodies"))
            points = list(get("points") or [None, None])
            particles = list(get("particles") or [None, None])
            if not (len(names) == len(points) == len(particles) == 2):
                raise ValueError("force 'spring': bodies, points and particles need two entries each")
            ends = [BodyPoint(body=n, point=_array(p), particle=i) for n, p, i in zip(names, points, particles,
                                                                                        strict=True)]  # fmt: skip
            return ForceSpring(end_a=ends[0], end_b=ends[1], **common)
        return ForceSpring(end_a=at(), anchor=_array(get("anchor")), **common)
    if kind == "force":
        return ForceAtPoint(at=at(), vector=_vector(entry, "vector"), frame=get("frame", "world"), schedule=schedule,
                            location=location)  # fmt: skip
    if kind == "torque":
        return ForceTorque(body=_required(entry, "body"), vector=_vector(entry, "vector"),
                           frame=get("frame", "world"), schedule=schedule, location=location)  # fmt: skip
    if kind == "drag":
        coefficients = {k: float(get(k, 0.0)) for k in ("linear", "quadratic", "angular_linear", "angular_quadratic")}
        return ForceDrag(bodies=_bodies(get("bodies")), location=location, **coefficients)
    if kind == "impulse":
        return ForceImpulse(at=at(), time=_required(entry, "time"), vector=_vector(entry, "vector"),
                            frame=get("frame", "world"), location=location)  # fmt: skip
    return ForceField(per=get("per", "mass"), bodies=_bodies(get("bodies")), value=_vector(entry, "value", [0, 0, 0]),
                      gradient=_array(get("gradient")), origin=_array(get("origin")), schedule=schedule,
                      location=location)  # fmt: skip
