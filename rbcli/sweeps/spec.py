"""A validated sweep: the base scene, the axes with their values, and how they combine into variants.

Variant i is the base scene's parsed data with every axis value of i set at its path (`paths.set_at`),
then loaded by the normal scene loader. The variants are numbered in a fixed order, so a number names
the same scene in every run of the sweep (the key that resuming and the results table use):
- product: the list and grid axes form a grid (row-major: the last axis varies fastest), and each grid
  point is repeated for `samples` draws of the random axes (the sample number varies fastest of all);
- zip: the i-th value of every axis (the random axes give `samples` values).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rbcli.scene.yaml_located import YamlPath
from rbcli.sweeps.paths import ScenePath, path_text

# More variants than this is a typo in `num` or `samples` (the parameters are held in memory).
MAX_VARIANTS = 10_000_000


@dataclass(frozen=True)
class Axis:
    """One varied scene value. values: the list or grid values, or the random draws (`samples` of them);
    each a plain YAML value (number, string, list, mapping). location: the axis in the sweep file."""

    path: ScenePath
    kind: str  # "values", "grid" or "random"
    values: tuple[Any, ...]
    location: YamlPath
    name: str = ""

    @property
    def column(self) -> str:
        """The results column of this axis: its name, else its path."""
        return self.name or path_text(self.path)


@dataclass(frozen=True)
class SweepSpec:
    """Everything needed to enumerate and run the variants (see the module docstring)."""

    name: str
    source_path: str
    scene_path: str  # the base scene file, resolved against the sweep file's folder
    scene_text: str
    axes: tuple[Axis, ...]
    combine: str = "product"
    samples: int | None = None
    seed: int = 0
    batch: int | None = None
    frames: int | None = 101  # None: the scene's own record cadence
    logs: bool = False
    output: str | None = None
    definition: dict[str, Any] = field(default_factory=dict)  # the sweep as written (JSON-able)

    @property
    def shape(self) -> tuple[int, ...]:
        """Sizes of the variant grid: the list and grid axes (product) then the samples; (n,) for zip."""
        if self.combine == "zip":
            return (len(self.axes[0].values),)
        sizes = [len(a.values) for a in self.axes if a.kind != "random"]
        if any(a.kind == "random" for a in self.axes):
            sizes.append(int(self.samples or 0))
        return tuple(sizes)

    @property
    def variant_count(self) -> int:
        return math.prod(self.shape)

    def variant_values(self, index: int) -> tuple[Any, ...]:
        """The value of every axis (in axis order) for variant `index`."""
        if not 0 <= index < self.variant_count:
            raise IndexError(f"variant {index} out of range 0..{self.variant_count - 1}")
        if self.combine == "zip":
            return tuple(axis.values[index] for axis in self.axes)
        coords = np.unravel_index(index, self.shape)
        sample = int(coords[-1]) if any(a.kind == "random" for a in self.axes) else 0
        fixed = iter(int(c) for c in coords)
        return tuple(axis.values[sample] if axis.kind == "random" else axis.values[next(fixed)] for axis in self.axes)

    @property
    def fingerprint(self) -> str:
        """sha256 of what decides the results: the sweep's definition, the base scene's text and where it is
        (messages name it). Parts of a folder with another fingerprint belong to another sweep and are never
        merged with these."""
        where = os.path.abspath(self.scene_path)
        key = json.dumps({"definition": self.definition, "scene": self.scene_text, "path": where}, sort_keys=True)
        return hashlib.sha256(key.encode()).hexdigest()

    def metadata(self) -> dict[str, Any]:
        """What the results table records about the sweep (its schema metadata `rbsim_sweep`)."""
        return {
            "name": self.name,
            "sweep_file": self.source_path,
            "scene": self.scene_path,
            "scene_sha256": hashlib.sha256(self.scene_text.encode()).hexdigest(),
            "combine": self.combine,
            "samples": self.samples,
            "seed": self.seed,
            "frames": self.frames if self.frames is not None else "scene",
            "variants": self.variant_count,
            "axes": [{"path": path_text(a.path), "kind": a.kind, "column": a.column} for a in self.axes],
            "fingerprint": self.fingerprint,
            "definition": self.definition,
        }


def grid_values(start: Any, stop: Any, num: int, spacing: str) -> tuple[Any, ...]:
    """`num` values from start to stop (both included), linear or log spaced, element-wise for vectors.
    Integer ends on a linear grid whose values are all whole give integers (e.g. a `steps` axis)."""
    lo, hi = np.asarray(start, dtype=np.float64), np.asarray(stop, dtype=np.float64)
    values = np.geomspace(lo, hi, num) if spacing == "log" else np.linspace(lo, hi, num)
    whole = spacing != "log" and _is_int(start) and _is_int(stop) and bool(np.all(values == np.round(values)))
    return tuple(_plain(v, integer=whole) for v in values)


def random_values(distribution: dict[str, Any], samples: int, seed: int, axis_number: int) -> tuple[Any, ...]:
    """`samples` draws, each of the broadcast shape of the distribution's parameters. Each axis has its own
    stream, seeded by (seed, axis number): adding an axis does not change the draws of the others."""
    rng = np.random.default_rng([seed, axis_number])
    kind = distribution["distribution"]
    if kind == "normal":
        mean, std = np.asarray(distribution["mean"], float), np.asarray(distribution["std"], float)
        draws = rng.normal(mean, std, size=(samples, *np.broadcast_shapes(mean.shape, std.shape)))
    else:
        low, high = np.asarray(distribution["low"], float), np.asarray(distribution["high"], float)
        shape = (samples, *np.broadcast_shapes(low.shape, high.shape))
        if kind == "loguniform":
            draws = np.exp(rng.uniform(np.log(low), np.log(high), size=shape))
        else:
            draws = rng.uniform(low, high, size=shape)
    return tuple(_plain(v) for v in draws)


def _is_int(value: Any) -> bool:
    items = value if isinstance(value, list) else [value]
    return all(isinstance(v, int) and not isinstance(v, bool) for v in items)


def _plain(value: np.ndarray, integer: bool = False) -> Any:
    """A numpy value as the YAML scalar or list a scene would hold (float64 -> float: exact)."""
    if np.ndim(value) == 0:
        return int(value) if integer else float(value)
    return [_plain(v, integer) for v in value]
