"""The `joints:` format: what loads, and every class of joint error located at the key at fault
(docs/joints.md), with `rbsim validate` of a joint scene writing nothing."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rbcli.physics.joints.tables import JOINT_DISTANCE, JOINT_HINGE
from rbcli.physics.rotation import quat_rotate
from rbcli.scene.load import analyse_scene_text, load_scene_text
from rbcli.scene.spec import SceneIssue

REPO = Path(__file__).resolve().parents[2]

# two 1 kg rods along z in their own frames, centres of mass at z = -0.5 of their particle frames
SCENE = """\
simulation: {dt: 0.001, duration: 0.01}
gravity: [0, 0, -9.81]
bodies:
  - name: upper
    particles: {positions: [[0, 0, 0], [0, 0, -1]], masses: 0.5, radius: 0.05}
    position: [0, 0, 0.5]
  - name: lower
    particles: {positions: [[0, 0, 0], [0, 0, -1]], masses: 0.5, radius: 0.05}
    position: [0, 0, -0.5]
joints:
"""


def issues_of(joints: str, scene: str = SCENE) -> list[SceneIssue]:
    spec, issues = analyse_scene_text(scene + joints, "s.yaml")
    assert (spec is None) == any(i.severity == "error" for i in issues)
    return issues


def the_error(issues: list[SceneIssue], fragment: str) -> SceneIssue:
    matching = [i for i in issues if fragment in i.message and i.severity == "error"]
    assert len(matching) == 1, f"{fragment!r} in {[str(i) for i in issues]}"
    return matching[0]


def at(issue: SceneIssue) -> tuple[int, int]:
    assert issue.location is not None
    return issue.location.line, issue.location.column


LINE = SCENE.count("\n") + 1  # the line of the first joint entry


def col(line: str, fragment: str) -> int:
    """The 1-based column where `fragment` starts in a joint's line: where an issue must point."""
    return line.index(fragment) + 1


def test_a_double_pendulum_loads_with_body_frame_anchors_in_the_principal_frame():
    spec = load_scene_text(
        SCENE
        + "  - {name: top, type: hinge, bodies: [world, upper], anchor: [0, 0, 1], axis: [0, 2, 0]}\n"
        + "  - {type: distance, bodies: [upper, lower], anchors: [[0, 0, -1], [0, 0, -0.5]]}\n"
    )
    table = spec.compiled_model.model.joint
    assert list(table.kind) == [JOINT_HINGE, JOINT_DISTANCE]
    assert [j.name for j in spec.joints] == ["top", "joint1"]
    # the world end is swapped to b; the rod's top (user z = 0) is 0.5 m above its centre of mass
    assert list(table.body_a) == [0, 0] and list(table.body_b) == [-1, 1]
    q0 = spec.compiled_model.initial_state.q[0]  # world-from-principal
    up = quat_rotate(q0, table.anchor_a[0])
    np.testing.assert_allclose(up, [0, 0, 0.5], atol=1e-15)
    np.testing.assert_allclose(table.anchor_b[0], [0, 0, 1])
    np.testing.assert_allclose(quat_rotate(q0, table.axis_a[0]), [0, 1, 0], atol=1e-15)
    assert table.row_count.tolist() == [5, 1]


def test_unknown_body_and_world_typo():
    line = "  - {type: ball, bodies: [uper, wrld], anchor: [0, 0, 1]}\n"
    issues = issues_of(line)
    assert "did you mean 'upper'" in the_error(issues, "no body named 'uper'").message
    assert at(the_error(issues, "no body named 'wrld'")) == (LINE, col(line, "wrld"))


def test_a_body_jointed_to_itself_and_world_to_world():
    first, second = (
        "  - {type: ball, bodies: [upper, upper], anchor: [0, 0, 1]}\n",
        "  - {type: ball, bodies: [world, world], anchor: [0, 0, 1]}\n",
    )
    issues = issues_of(first + second)
    assert at(the_error(issues, "'upper' is jointed to itself")) == (LINE, col(first, "[upper, upper]"))
    assert at(the_error(issues, "both ends are the world")) == (LINE + 1, col(second, "[world, world]"))


def test_zero_axis():
    line = "  - {type: hinge, bodies: [upper, world], anchor: [0, 0, 1], axis: [0, 0, 0]}\n"
    issue = the_error(issues_of(line), "zero axis")
    assert at(issue) == (LINE, col(line, "[0, 0, 0]")) and issue.expected == "a non-zero vector"


def test_anchors_that_disagree_with_the_initial_poses_say_by_how_much():
    # upper's top (user z = 0) is at world z = 1; the world anchor given is 3 cm off
    line = "  - {type: ball, bodies: [upper, world], anchors: [[0, 0, 0], [0.03, 0, 1]]}\n"
    issue = the_error(issues_of(line), "apart")
    assert "anchors are 0.03 m apart at the initial poses" in issue.message
    assert at(issue) == (LINE, col(line, "[[0, 0, 0]"))


def test_anchors_that_agree_load_and_a_slider_only_checks_across_its_axis():
    assert issues_of("  - {type: ball, bodies: [upper, world], anchors: [[0, 0, 0], [0, 0, 1]]}\n") == []
    # 0.4 m along the slider's axis is travel, not a mismatch; across it, it is refused
    ok = "  - {type: slider, bodies: [upper, world], anchors: [[0, 0, 0], [0, 0, 1.4]], axis: [0, 0, 1]}\n"
    assert issues_of(ok) == []
    bad = "  - {type: slider, bodies: [upper, world], anchors: [[0, 0, 0], [0.2, 0, 1]], axis: [0, 0, 1]}\n"
    assert "0.2 m apart across the axis" in the_error(issues_of(bad), "apart").message


def test_per_body_axes_that_disagree():
    issue = the_error(
        issues_of("  - {type: hinge, bodies: [upper, lower], anchor: [0, 0, 0], axes: [[0, 1, 0], [0, 1, 0.01]]}\n"),
        "axes are",
    )
    assert "0.01 rad apart" in issue.message


def test_distance_length_and_a_zero_rod():
    wrong = "  - {type: distance, bodies: [upper, world], anchors: [[0, 0, 0], [0, 0, 2]], length: 1.5}\n"
    assert "apart at the initial poses, the rod is 1.5 m" in the_error(issues_of(wrong), "the rod is").message
    zero = "  - {type: distance, bodies: [upper, lower], anchors: [[0, 0, -1], [0, 0, 0]]}\n"
    assert at(the_error(issues_of(zero), "rod of length 0")) == (LINE, col(zero, "[[0, 0, -1]"))


def test_a_joint_between_fixed_ends():
    scene = SCENE.replace("    position: [0, 0, -0.5]\n", "    position: [0, 0, -0.5]\n    static: true\n")
    scene = scene.replace("joints:\n", "contact: {ground: -10}\njoints:\n")
    issues = issues_of("  - {type: ball, bodies: [lower, world], anchor: [0, 0, 0]}\n", scene)
    assert "both ends are fixed" in the_error(issues, "both ends are fixed").message


def test_keys_that_do_not_fit_the_type():
    ball = "  - {type: ball, bodies: [upper, world], anchor: [0, 0, 1], axis: [0, 1, 0]}\n"
    hinge = "  - {type: hinge, bodies: [upper, world], anchor: [0, 0, 1], axis: [0, 1, 0], length: 1}\n"
    issues = issues_of(ball + hinge)
    assert at(the_error(issues, "unknown key 'axis'")) == (LINE, col(ball, "axis"))
    assert at(the_error(issues, "unknown key 'length'")) == (LINE + 1, col(hinge, "length"))


def test_anchor_and_anchors_together_or_neither():
    both = "  - {type: ball, bodies: [upper, world], anchor: [0, 0, 1], anchors: [[0, 0, 0], [0, 0, 1]]}\n"
    neither = "  - {type: ball, bodies: [upper, world]}\n"
    assert any(i.severity == "error" for i in issues_of(both))
    assert any(i.severity == "error" for i in issues_of(neither))


def test_limits_lower_above_upper():
    line = "  - {type: hinge, bodies: [upper, world], anchor: [0, 0, 1], axis: [0, 1, 0], limits: [1, -1]}\n"
    issue = the_error(issues_of(line), "lower limit")
    assert "lower limit 1 is above upper limit -1" in issue.message and at(issue) == (LINE, col(line, "[1, -1]"))


def test_hinge_limits_past_a_half_turn():
    line = "  - {type: hinge, bodies: [upper, world], anchor: [0, 0, 1], axis: [0, 1, 0], limits: [-1, 3.2]}\n"
    issue = the_error(issues_of(line), "reach past a half turn")
    assert at(issue) == (LINE, col(line, "[-1, 3.2]")) and "between -pi and pi" in issue.expected


def test_dampers_and_motors_reach_the_table():
    spec = load_scene_text(
        SCENE + "  - {type: hinge, bodies: [upper, world], anchor: [0, 0, 1], axis: [0, 1, 0], damping: 0.1, "
        "motor: {speed: -1.5, max_torque: 2}}\n"
        + "  - {type: slider, bodies: [lower, upper], anchor: [0, 0, 0], axis: [0, 0, 1], "
        "motor: {speed: 0.2, max_force: 7}}\n"
    )
    table = spec.compiled_model.model.joint
    assert table.damping.tolist() == [0.1, 0.0]
    assert table.motor_speed.tolist() == [-1.5, 0.2] and table.motor_cap.tolist() == [2.0, 7.0]
    assert np.isinf(table.limit_lower).all() and np.isinf(table.limit_upper).all()  # no limits given


def test_duplicate_joint_names():
    issues = issues_of(
        "  - {name: j, type: ball, bodies: [upper, world], anchor: [0, 0, 1]}\n"
        "  - {name: j, type: ball, bodies: [lower, upper], anchor: [0, 0, 0]}\n"
    )
    assert f"(first at line {LINE})" in the_error(issues, "duplicate joint name 'j'").message


@pytest.mark.parametrize("integrator", ["rk4", "exact", "semi-implicit"])
def test_an_integrator_that_does_not_hold_joints_is_refused_naming_the_ones_that_do(integrator):
    scene = SCENE.replace("duration: 0.01}", f"duration: 0.01, integrator: {integrator}}}")
    issue = the_error(issues_of("  - {type: ball, bodies: [upper, world], anchor: [0, 0, 1]}\n", scene), "joints")
    assert issue.message.endswith(
        f"integrator '{integrator}' does not hold joints; the ones that do: split2, reduced-euler, reduced-rk4, "
        "reduced-implicit"
    )
    assert at(issue) == (1, col(scene.splitlines()[0], integrator))


def test_a_joint_scene_defaults_to_its_family_s_integrator_and_refuses_a_tolerance():
    """Joints that form trees run reduced-rk4 unless the scene says maximal; a loop, a distance joint or a
    kinematic body in a joint keeps split2 (docs/trees.md, "Which integrator a jointed scene gets")."""
    ball = "  - {type: ball, bodies: [upper, world], anchor: [0, 0, 1]}\n"
    assert load_scene_text(SCENE + ball).simulation.integrator == "reduced-rk4"
    maximal = SCENE.replace("duration: 0.01}", "duration: 0.01, coordinates: maximal}")
    assert load_scene_text(maximal + ball).simulation.integrator == "split2"
    elbow = "  - {type: ball, bodies: [lower, upper], anchor: [0, 0, -0.5]}\n"
    assert load_scene_text(SCENE + ball + elbow).simulation.integrator == "reduced-rk4"
    loop = "  - {type: ball, bodies: [lower, world], anchor: [0, 0, -1.5]}\n"
    assert load_scene_text(SCENE + ball + elbow + loop).simulation.integrator == "split2"
    rod = "  - {type: distance, bodies: [lower, upper], anchors: [[0, 0, 0], [0, 0, 0]]}\n"
    assert load_scene_text(SCENE + ball + rod).simulation.integrator == "split2"
    kinematic = SCENE.replace("    position: [0, 0, 0.5]\n", "    position: [0, 0, 0.5]\n    kinematic: true\n")
    kinematic = kinematic.replace("bodies:\n", "contact: {}\nbodies:\n", 1)
    assert load_scene_text(kinematic + elbow).simulation.integrator == "split2"
    scene = SCENE.replace("duration: 0.01}", "duration: 0.01, integrator: dopri5, tolerance: 1e-6}")
    issue = the_error(issues_of("  - {type: ball, bodies: [upper, world], anchor: [0, 0, 1]}\n", scene), "fixed step")
    assert issue.location is not None and issue.location.line == 1


def test_validate_a_joint_scene_writes_nothing_and_imports_no_numba(tmp_path):
    path = tmp_path / "pendulum.yaml"
    path.write_text((REPO / "scenes" / "joints" / "pendulum.yaml").read_text().replace("record: {every: 10}",
                    "record: {every: 10}, output: run.mcap"))  # fmt: skip
    code = (
        "import sys\nfrom rbcli.cli.app import main\n"
        f"sys.argv = ['rbsim', 'validate', {str(path)!r}]\n"
        "try:\n    main()\nexcept SystemExit as exc:\n    print('exit', exc.code)\n"
        "print(sorted(m for m in ('numba', 'rerun', 'mcap') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]", out.stdout + out.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pendulum.yaml"]


def _tree_with_contact(bodies: str, contact: str = "  ground: 0\n") -> str:
    return (
        "name: t\nsimulation: {dt: 0.001, duration: 0.01}\ngravity: [0, 0, -9.81]\ncontact:\n" + contact
        + "bodies:\n" + bodies + "joints:\n  - {type: ball, bodies: [b1, b0], anchor: [0, 0, 0.5]}\n"
    )  # fmt: skip


def test_a_tree_with_contact_of_a_few_shapes_defaults_to_reduced_implicit():
    """A jointed tree with contact runs reduced-implicit (docs/trees.md, "Which integrator a jointed scene
    gets") where the most contact points it can have at once, counted from the shapes (1 with a sphere, 2
    for capsules, 4 box-box and a box on a plane) and the clouds' spheres (one each, against each sphere
    or shape of the other body), fit the solve's capacity, pairs held by a joint (without `collide`)
    left out; a sampled lattice (`primitives: false`, a mesh) or more bodies keep reduced-rk4. The shipped
    capsule ragdoll: 15 on its plane, 6 with its head and 30 between its capsules, 51; the particle
    ragdoll's 16 spheres: 92."""
    from rbcli.physics.contact.tables import IMPLICIT_CAPACITY
    from rbcli.scene.load import implicit_contact_fits

    capsule = "shape: {type: capsule, radius: 0.05, height: 0.3}, spacing: 0.05, mass: 1"
    two = f"  - {{name: b0, {capsule}, position: [0, 0, 0.3]}}\n  - {{name: b1, {capsule}, position: [0, 0, 0.7]}}\n"
    assert load_scene_text(_tree_with_contact(two)).simulation.integrator == "reduced-implicit"
    primitives_off = _tree_with_contact(two, "  ground: 0\n  primitives: false\n")
    assert load_scene_text(primitives_off).simulation.integrator == "reduced-rk4"
    cloud = two.replace(
        f"name: b1, {capsule}", "name: b1, particles: {positions: [[0, 0, 0], [0.1, 0, 0]], masses: 1.0, radius: 0.05}"
    )
    assert load_scene_text(_tree_with_contact(cloud)).simulation.integrator == "reduced-implicit"
    # 12 spheres each on the plane (24) and against each other (144): past the capacity; held by their
    # joint (not `collide: true`), the pair never touches: 24
    row = ", ".join(f"[{0.1 * i}, 0, 0]" for i in range(12))
    twelve = f"particles: {{positions: [{row}], masses: 1.0, radius: 0.05}}"
    clouds = two.replace(f"b0, {capsule}", f"b0, {twelve}").replace(f"b1, {capsule}", f"b1, {twelve}")
    spec = load_scene_text(_tree_with_contact(clouds))
    assert implicit_contact_fits(list(spec.bodies), spec.contact) is False
    assert implicit_contact_fits(list(spec.bodies), spec.contact, spec.joints) is True
    assert spec.simulation.integrator == "reduced-implicit"
    box = "shape: {type: box, size: [0.2, 0.2, 0.2]}, spacing: 0.05, mass: 1"
    # n boxes on one plane: 4 n + 4 n (n - 1) / 2 points; 7 fit (112), 8 do not (144)
    for n, fits in ((7, True), (8, False)):
        boxes = "".join(f"  - {{name: b{i}, {box}, position: [{0.5 * i}, 0, 0.1]}}\n" for i in range(n))
        spec = load_scene_text(_tree_with_contact(boxes))
        assert implicit_contact_fits(list(spec.bodies), spec.contact) is fits
        assert (4 * n + 2 * n * (n - 1) <= IMPLICIT_CAPACITY) is fits
        assert spec.simulation.integrator == ("reduced-implicit" if fits else "reduced-rk4")
    ragdoll = load_scene_text((Path(__file__).resolve().parents[2] / "scenes/joints/capsule_ragdoll.yaml").read_text())
    assert ragdoll.simulation.integrator == "reduced-implicit"
    particles = load_scene_text((Path(__file__).resolve().parents[2] / "scenes/joints/ragdoll.yaml").read_text())
    assert particles.simulation.integrator == "reduced-implicit"
