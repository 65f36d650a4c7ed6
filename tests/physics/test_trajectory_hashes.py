"""Determinism guard: every integrator on the free-body scenes and on one scene with every force term
(three integrators in the suite, all ten with RBSIM_FULL_HASHES=1: CASES below), split2 on each
single-force scene, and the contact and joint scenes give bitwise the trajectories stored in
trajectory_hashes.json (Box2D's determinism hash, one per scene and integrator).

Why: a refactor of the step (stages, Model/Data, chunk loops) must not change a single bit of any
result. A later change to an integrator's numerics regenerates the file in its own commit, saying why:

    python tests/physics/test_trajectory_hashes.py --regenerate

and a new case adds its hash (and final state) alone, leaving every stored one as it is, with
`--add-missing`.

Bitwise equality only holds for the same machine code, so hashes are keyed by platform and by numpy /
numba versions. On a key with no stored hashes the test still runs: it compares the final states
stored beside the hashes to 1e-9 relative (far above the ~1e-13 that another libm or SIMD order
gives over a few hundred steps, far below any real change of the numerics).
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
STORE = Path(__file__).with_name("trajectory_hashes.json")

# Each scene kind (the combination of force types, contact, joints) compiles its own chunk loop per
# integrator (forces/tables.py), and the compile is what this file costs (~10-20 s a loop, cold). So every
# integrator runs on the free-body kind (three verification scenes, one kind) and on one scene with every
# force term (tests/physics/scenes/every_force.yaml: each force stage inside each integrator), and each
# single-force scene, a kind of its own, with split2 only (its stage alone in the default loop). Issue 30
# measured 526 s for the 99 cases of one kind per force scene and integrator.
FREE_SCENES = ("verification/intermediate_axis.yaml", "verification/fast_spin.yaml", "verification/thin_rod.yaml")
EVERY_FORCE = "tests/physics/scenes/every_force.yaml"
FORCE_SCENES = (
    "verification/spring_tether.yaml",
    "forces/impulse_kick.yaml",  # impulse at t = 0.5 s
    "forces/pushed_box.yaml",  # scheduled force and torque
    "forces/spinning_top.yaml",  # gravity torque about a pivot
    "forces/spring_chain.yaml",  # damped springs
    "forces/projectile_drag.yaml",  # velocity-dependent drag
)
# contact (issue 30): a falling pile (64 balls reaching the floor at 0.23 s and each other soon after)
# and the spinning brick's bounce, with the integrators whose contact paths differ: split2 (the default,
# a mid-step evaluation), semi-implicit (at the step's start), rk4 (the last stage at its end: nothing
# left to advance in the commit) and adaptive dopri5 on the brick (rejected attempts, the step limit)
CONTACT_SCENES = {"verification/contact_pile.yaml": 400, "contact/box_drop.yaml": 400}  # scene: steps
CONTACT_INTEGRATORS = ("split2", "semi-implicit", "rk4")
# joints (issue 27; split2 only, the one integrator that takes them): a pendulum (gravity and a hinge)
# and the ragdoll (ball joints, hinges with limits, contact with the ground: it lands at ~0.36 s) as it was
# before its ball joints took cones (tests/physics/scenes/ragdoll_no_cones.yaml; its hashes are those of
# joints/ragdoll.yaml then, so ball joints without cones still run bitwise as before);
# no loops, whose redundant rows are dropped by pivots near the tolerance (docs/joint_solver.md)
JOINT_SCENES = {"joints/pendulum.yaml": 600, "tests/physics/scenes/ragdoll_no_cones.yaml": 1000}  # scene: steps
FIXED = ("euler-matrix", "euler-quat", "semi-implicit", "semi-implicit-gyro", "rk4", "split2", "split4", "exact",
         "exact4", "dopri5")  # fmt: skip
STEPS = 600  # enough to pass the impulses (t = 0.3 s and 0.5 s at dt = 1 ms); short enough for the suite
RECORD_EVERY = 20

# The suite runs every integrator on the free-body scenes (their loops are the ones the integrator tests
# compile anyway) and EVERY_FORCE with one integrator of each kind of force handling: split2 (kicks and
# its own damping flow), rk4 (forces at its stages) and exact (the deferred torque-free bodies); the
# other seven EVERY_FORCE loops cost ~80 CPU-s cold, a tenth of the suite's compile. RBSIM_FULL_HASHES=1
# runs every case (before and after a refactor of the step: `RBSIM_FULL_HASHES=1 pytest -n0 <this file>`),
# and --regenerate always writes all of them.
EVERY_FORCE_IN_SUITE = ("split2", "rk4", "exact")
CASES = [(scene, name, None) for scene in (*FREE_SCENES, EVERY_FORCE) for name in FIXED]
CASES += [(scene, "split2", None) for scene in FORCE_SCENES]
# adaptive: EVERY_FORCE's torque window opens at 0.1 s, a force jump (adaptive.py: the schedule step floor)
CASES += [(scene, "dopri5", 1e-8) for scene in ("verification/intermediate_axis.yaml", "forces/pushed_box.yaml",
                                                 EVERY_FORCE)]  # fmt: skip
CASES += [(scene, name, None) for scene in CONTACT_SCENES for name in CONTACT_INTEGRATORS]
CASES += [("contact/box_drop.yaml", "dopri5", 1e-6)]
CASES += [(scene, "split2", None) for scene in JOINT_SCENES]
ALL_CASES = CASES
if os.environ.get("RBSIM_FULL_HASHES") != "1":
    CASES = [c for c in ALL_CASES if c[0] != EVERY_FORCE or c[1] in EVERY_FORCE_IN_SUITE or c[2] is not None]


def platform_key() -> str:
    return f"{platform.machine()}-{sys.platform}-numpy{np.__version__}-numba{numba.__version__}"


def case_id(scene: str, integrator: str, tolerance: float | None) -> str:
    return f"{scene}:{integrator}" + (f":tol={tolerance:g}" if tolerance is not None else "")


def run_case(scene: str, integrator: str, tolerance: float | None):  # noqa: ANN201
    from rbcli.api import load_scene, simulate

    spec = load_scene(ROOT / scene if scene.startswith("tests/") else ROOT / "scenes" / scene)
    duration = {**CONTACT_SCENES, **JOINT_SCENES}.get(scene, STEPS) * spec.simulation.dt
    return simulate(
        spec, integrator=integrator, duration=duration, record_every=RECORD_EVERY, tolerance=tolerance,
        on_diverge="return",
    )  # fmt: skip


def trajectory_hash(traj) -> str:  # noqa: ANN001
    digest = hashlib.sha256()
    for name in ("step", "x", "q", "P", "L"):
        digest.update(np.ascontiguousarray(getattr(traj, name)).tobytes())
    return digest.hexdigest()


def final_state(traj) -> list[float]:  # noqa: ANN001
    return np.concatenate([traj.x[-1].ravel(), traj.q[-1].ravel(), traj.P[-1].ravel(), traj.L[-1].ravel()]).tolist()


@pytest.fixture(scope="module")
def store() -> dict:
    return json.loads(STORE.read_text())


@pytest.mark.parametrize(("scene", "integrator", "tolerance"), CASES, ids=[case_id(*c) for c in CASES])
def test_trajectory_is_bitwise_unchanged(store, scene, integrator, tolerance):
    key = case_id(scene, integrator, tolerance)
    traj = run_case(scene, integrator, tolerance)
    hashes = store["hashes"].get(platform_key())
    if hashes is not None:
        assert trajectory_hash(traj) == hashes[key], f"{key}: the trajectory changed (see the module docstring)"
    else:  # another platform or library version: the stored final state, to 1e-9 relative
        expected = np.array(store["final_state"][key])
        np.testing.assert_allclose(final_state(traj), expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


def regenerate(missing_only: bool = False) -> None:
    """Rewrite this platform's hashes (and the final states when none are stored yet); with
    missing_only, compute only the cases this platform has no hash for (new cases) and keep the rest.
    Cases no longer in ALL_CASES are dropped from every platform's hashes and from the final states."""
    store = json.loads(STORE.read_text()) if STORE.exists() else {"hashes": {}, "final_state": {}}
    current = {case_id(*case) for case in ALL_CASES}
    for platform_hashes in store["hashes"].values():
        for key in set(platform_hashes) - current:
            del platform_hashes[key]
    finals = {key: value for key, value in store["final_state"].items() if key in current}
    store["final_state"] = finals
    hashes = dict(store["hashes"].get(platform_key(), {})) if missing_only else {}
    for case in ALL_CASES:
        if case_id(*case) in hashes:
            continue
        traj = run_case(*case)
        hashes[case_id(*case)] = trajectory_hash(traj)
        finals[case_id(*case)] = final_state(traj)
        print(case_id(*case), hashes[case_id(*case)][:16], traj.status)
    store["hashes"][platform_key()] = hashes
    STORE.write_text(json.dumps(store, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    if "--regenerate" in sys.argv:
        regenerate()
    elif "--add-missing" in sys.argv:
        regenerate(missing_only=True)
    else:
        print(__doc__)
