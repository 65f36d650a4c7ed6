"""In-memory recording: the Trajectory that `rbcli.simulate` and `rbcli.read_recording` return, and its
export to .npz (exact, read back with `Trajectory.from_npz`) and CSV."""

from __future__ import annotations

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rbcli.record.frame import FrameBlock, RunHeader, RunSummary


@dataclass
class Trajectory:
    """Recorded frames of a run, stacked.

    t (T,) [s]; step (T,); x (T, N, 3) [m]; q (T, N, 4) wxyz world-from-body (user frame);
    v (T, N, 3) [m/s]; omega (T, N, 3) [rad/s] world; P (T, N, 3) [kg m/s]; L (T, N, 3) [kg m^2/s] world.
    invariants: name -> (T,); particle_position (T, particle_count, 3) when recorded.
    joint_force (T, J, 12) with the joint_forces stream: each joint's reaction over the step that ended
    at the frame, [N] and [N m] about each body's centre of mass, world (FrameBlock.joint_force; NaN
    where no step led to the frame); `joint_reactions` gives it per joint name as (T, 2, 6).
    not_recorded: the names among v, omega, P, L that the source did not hold (a trajectory read from an
    .rrd): those arrays are NaN-filled, of the usual shape, and left out of the CSV.
    """

    body_names: tuple[str, ...]
    t: np.ndarray
    step: np.ndarray
    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    P: np.ndarray
    L: np.ndarray
    invariants: dict[str, np.ndarray] = field(default_factory=dict)
    particle_position: np.ndarray | None = None
    header: RunHeader | None = None
    summary: RunSummary | None = None
    not_recorded: tuple[str, ...] = ()
    joint_force: np.ndarray | None = None
    joint_names: tuple[str, ...] = ()

    @property
    def status(self) -> str:
        return self.summary.status if self.summary else "unknown"

    @property
    def joint_reactions(self) -> dict[str, np.ndarray]:
        """Joint name -> (T, 2, 6): per frame, the force [N] and torque [N m] on the joint's first body
        (row 0) and second (row 1), as Simulation.joint_reactions; {} without the joint_forces stream."""
        if self.joint_force is None:
            return {}
        k_count = self.joint_force.shape[0]
        return {name: self.joint_force[:, j].reshape(k_count, 2, 6) for j, name in enumerate(self.joint_names)}

    def to_npz(self, path: str | Path) -> None:
        """Write every array, the body names, the header and the summary to an uncompressed .npz at `path`
        (the name is used as given). `Trajectory.from_npz` reads it back bit for bit; numpy alone reads
        it too (`np.load(path)["x"]`; the names and run parameters are JSON in `np.load(path)["meta"]`)."""
        arrays: dict[str, np.ndarray] = {name: np.asarray(getattr(self, name)) for name in _NPZ_ARRAYS}
        for i, name in enumerate(self.invariants):
            arrays[f"invariant_{i}"] = np.asarray(self.invariants[name])
        if self.particle_position is not None:
            arrays["particle_position"] = np.asarray(self.particle_position)
        if self.joint_force is not None:
            arrays["joint_force"] = np.asarray(self.joint_force)
        header: dict[str, Any] | None = None
        if self.header is not None:
            offsets = self.header.body_particle_offset
            arrays["particle_count"] = np.array([len(o) for o in offsets], dtype=np.int64)
            arrays["particle_offset"] = (
                np.concatenate([np.asarray(o, dtype=np.float64).reshape(-1, 3) for o in offsets])
                if offsets
                else np.zeros((0, 3))
            )
            header = {"parameters": self.header.parameters(), "scene_text": self.header.scene_text}
        meta = {
            "format": NPZ_FORMAT,
            "body_names": list(self.body_names),
            "invariant_names": list(self.invariants),
            "not_recorded": list(self.not_recorded),
            "joint_names": list(self.joint_names),
            "header": header,
            "summary": None if self.summary is None else _summary_dict(self.summary),
        }
        arrays["meta"] = np.array(json.dumps(meta))
        with open(path, "wb") as f:
            np.savez(f, allow_pickle=False, **arrays)

    @classmethod
    def from_npz(cls, path: str | Path) -> Trajectory:
        """Read a file written by `to_npz`: the same arrays, bit for bit, names, header and summary."""
        with np.load(path, allow_pickle=False) as z:
            if "meta" not in z.files:
                raise ValueError(f"{str(path)!r}: not an rbsim trajectory .npz (no 'meta' entry)")
            meta = json.loads(str(z["meta"]))
            if meta.get("format") != NPZ_FORMAT:
                raise ValueError(f"{str(path)!r}: unknown trajectory .npz format {meta.get('format')!r}")
            t, step, x, q, v, omega, P, L = (z[name] for name in _NPZ_ARRAYS)
            invariants = {name: z[f"invariant_{i}"] for i, name in enumerate(meta["invariant_names"])}
            particles = z["particle_position"] if "particle_position" in z.files else None
            joint_force = z["joint_force"] if "joint_force" in z.files else None
            header = None
            if meta["header"] is not None:
                counts = z["particle_count"]
                offsets = tuple(np.split(z["particle_offset"], np.cumsum(counts)[:-1])) if counts.size else ()
                header = header_from_parameters(meta["header"]["parameters"], meta["header"]["scene_text"], offsets)
        summary = None if meta["summary"] is None else RunSummary(**meta["summary"])
        return cls(
            body_names=tuple(meta["body_names"]),
            t=t,
            step=step,
            x=x,
            q=q,
            v=v,
            omega=omega,
            P=P,
            L=L,
            invariants=invariants,
            particle_position=particles,
            header=header,
            summary=summary,
            not_recorded=tuple(meta["not_recorded"]),
            joint_force=joint_force,
            joint_names=tuple(meta.get("joint_names", ())),
        )

    def to_csv(self, path: str | Path) -> None:
        """Write one row per (recorded frame, body), frames in order and bodies in `body_names` order.

        Columns (SI units in the names): time_s, step, body, x_m, y_m, z_m, qw, qx, qy, qz (world-from-body),
        vx_m_per_s ..., omega_x_rad_per_s ... (world), Px_kg_m_per_s ..., Lx_kg_m2_per_s ... (world), the
        last four groups only where recorded (see `not_recorded`). Floats are written as Python's repr, the
        shortest text that reads back to the same float64, so `np.loadtxt` / `float()` give the arrays back
        exactly. Invariants, particle positions and run parameters are not in the CSV (use `to_npz`).
        """
        groups = [(name, cols) for name, cols in CSV_COLUMNS if name not in self.not_recorded]
        frames, bodies = self.x.shape[:2]
        values = np.concatenate([np.asarray(getattr(self, name), dtype=np.float64) for name, _ in groups], axis=2)
        values = values.reshape(frames * bodies, -1)
        t, step = np.repeat(self.t, bodies).tolist(), np.repeat(self.step, bodies).tolist()
        names = list(self.body_names) * frames
        with open(path, "w", newline="", encoding="utf-8") as f:
            writer = csv.writer(f, lineterminator="\n")
            writer.writerow(["time_s", "step", "body", *(c for _, cols in groups for c in cols)])
            for row, (ti, si, name) in enumerate(zip(t, step, names, strict=True)):
                # csv writes a float with str(), which is repr: the shortest exact round trip
                writer.writerow([float(ti), int(si), name, *values[row].tolist()])


NPZ_FORMAT = "rbsim-trajectory-1"
_NPZ_ARRAYS = ("t", "step", "x", "q", "v", "omega", "P", "L")
CSV_COLUMNS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("x", ("x_m", "y_m", "z_m")),
    ("q", ("qw", "qx", "qy", "qz")),
    ("v", ("vx_m_per_s", "vy_m_per_s", "vz_m_per_s")),
    ("omega", ("omega_x_rad_per_s", "omega_y_rad_per_s", "omega_z_rad_per_s")),
    ("P", ("Px_kg_m_per_s", "Py_kg_m_per_s", "Pz_kg_m_per_s")),
    ("L", ("Lx_kg_m2_per_s", "Ly_kg_m2_per_s", "Lz_kg_m2_per_s")),
)


def _summary_dict(summary: RunSummary) -> dict[str, Any]:
    """Every RunSummary field as JSON-ready Python scalars (JSON writes floats as repr: exact)."""
    optional = (summary.steps_accepted, summary.steps_rejected)
    accepted, rejected = (None if n is None else int(n) for n in optional)
    return {
        "status": str(summary.status),
        "steps": int(summary.steps),
        "frames": int(summary.frames),
        "t_end": float(summary.t_end),
        "message": str(summary.message),
        "steps_accepted": accepted,
        "steps_rejected": rejected,
    }


def header_from_parameters(
    parameters: dict[str, str], scene_text: str, particle_offset: tuple[np.ndarray, ...]
) -> RunHeader:
    """The RunHeader whose `parameters()` a file holds (an MCAP run record, .rrd properties, a to_npz
    file). Keys an older file lacks take neutral defaults; quaternions are wxyz in every rbsim array."""
    p = parameters

    def names(key: str) -> tuple[str, ...]:
        return tuple(json.loads(p[key])) if p.get(key) else ()

    return RunHeader(
        scene_name=p.get("scene_name", ""),
        scene_text=scene_text,
        scene_path=p.get("scene_path") or None,
        scene_sha256=p.get("scene_sha256", ""),
        body_names=names("body_names"),
        body_mass=np.asarray(json.loads(p["body_mass"]) if p.get("body_mass") else [], dtype=np.float64),
        body_particle_offset=particle_offset,
        integrator=p.get("integrator", ""),
        dt=float(p.get("dt", "nan")),
        duration=float(p.get("duration", "nan")),
        record_every=int(p.get("record_every", "1")),
        streams=names("streams"),
        rbsim_version=p.get("rbsim_version", ""),
        seed=int(p.get("seed", "0")),
        invariant_names=names("invariant_names"),
        joint_names=names("joint_names"),
        tolerance=float(p["tolerance"]) if p.get("tolerance") else None,
        units=p.get("units", RunHeader.units),
        quaternion_order="wxyz",
    )


class SinkMemory:
    """Collects blocks; `trajectory()` stacks them once the run is closed."""

    def __init__(self) -> None:
        self.header: RunHeader | None = None
        self.summary: RunSummary | None = None
        self.blocks: list[FrameBlock] = []

    def open(self, header: RunHeader) -> None:
        self.header = header

    def write(self, block: FrameBlock) -> None:
        self.blocks.append(block)

    def close(self, summary: RunSummary) -> None:
        self.summary = summary

    def trajectory(self) -> Trajectory:
        assert self.header is not None, "open() was never called"
        blocks = self.blocks

        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(b, name) for b in blocks])

        inv_names = blocks[0].invariants.keys() if blocks else ()
        particles = blocks[0].particle_position is not None if blocks else False
        joints = bool(blocks) and blocks[0].joint_force is not None
        return Trajectory(
            body_names=self.header.body_names,
            t=cat("t"),
            step=cat("step"),
            x=cat("x"),
            q=cat("q"),
            v=cat("v"),
            omega=cat("omega"),
            P=cat("P"),
            L=cat("L"),
            invariants={k: np.concatenate([b.invariants[k] for b in blocks]) for k in inv_names},
            particle_position=cat("particle_position") if particles else None,
            header=self.header,
            summary=self.summary,
            joint_force=cat("joint_force") if joints else None,
            joint_names=self.header.joint_names if joints else (),
        )
