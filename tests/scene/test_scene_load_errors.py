"""Every class of scene error: the message says what is wrong and what was expected, at the exact line:col."""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import pytest

from rbcli.physics.integrators import get_integrator
from rbcli.scene.load import analyse_scene_text, check_scene, load_scene, load_scene_text
from rbcli.scene.spec import SceneError, SceneIssue

SIM = "simulation: {dt: 0.001, duration: 1.0}\n"
HANDLE = """\
  - name: handle
    particles:
      positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]]
      masses: [1.0, 0.5, 0.5, 0.25]
"""


def issues_of(text: str, base_dir: Path | None = None) -> list[SceneIssue]:
    spec, issues = analyse_scene_text(textwrap.dedent(text), "s.yaml", base_dir)
    assert (spec is None) == any(i.severity == "error" for i in issues)
    return issues


def the_issue(issues: list[SceneIssue], fragment: str) -> SceneIssue:
    """The one issue whose message contains `fragment`."""
    matching = [i for i in issues if fragment in i.message]
    assert len(matching) == 1, f"{fragment!r} in {[str(i) for i in issues]}"
    return matching[0]


def at(issue: SceneIssue) -> tuple[int, int]:
    return issue.location.line, issue.location.column


def test_valid_scene_has_no_issues():
    assert issues_of(SIM + "bodies:\n" + HANDLE) == []


def test_unknown_top_level_key_with_did_you_mean():
    issues = issues_of(SIM + "gravty: [0, 0, -9.81]\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "unknown key 'gravty'")
    assert at(issue) == (2, 1)
    assert "did you mean 'gravity'" in issue.message and "'bodies'" in issue.expected


def test_typo_of_a_required_key_is_reported_once():
    # 'bodys' explains the missing 'bodies'; no second "missing required key" issue
    issues = issues_of(SIM + "bodys:\n" + HANDLE)
    assert len(issues) == 1
    assert at(the_issue(issues, "did you mean 'bodies'")) == (2, 1)


def test_unknown_body_key():
    issues = issues_of(SIM + "bodies:\n" + HANDLE + "    positon: [0, 0, 1]\n")
    issue = the_issue(issues, "unknown key 'positon'")
    assert at(issue) == (7, 5) and "did you mean 'position'" in issue.message
    assert issue.message.startswith("bodies[0].positon:")


def test_missing_required_key_at_its_mapping():
    issues = issues_of("simulation:\n  duration: 1.0\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "missing required key 'dt'")
    assert at(issue) == (1, 1) and "time step [s]" in issue.expected


def test_missing_one_of_duration_or_steps():
    issues = issues_of("simulation: {dt: 0.1}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "missing one of 'duration', 'steps'")
    assert at(issue) == (1, 1)


def test_wrong_type():
    issues = issues_of("simulation: {dt: fast, duration: 1.0}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "wrong type")
    assert at(issue) == (1, 18)
    assert "a string ('fast')" in issue.message and issue.expected.startswith("a number")


def test_wrong_length():
    issues = issues_of(SIM + "bodies:\n" + HANDLE + "    position: [0, 1]\n")
    issue = the_issue(issues, "wrong length: 2 items")
    assert at(issue) == (7, 15) and "exactly 3 items" in issue.expected


@pytest.mark.parametrize("literal", [".nan", ".inf", "-.inf", "1e999"])
def test_not_finite(literal):
    issues = issues_of(SIM + "bodies:\n" + HANDLE + f"    velocity: [0, {literal}, 0]\n")
    issue = the_issue(issues, "not a finite number")
    assert at(issue) == (7, 19) and issue.expected == "a finite number"
    assert len(issues) == 1  # not also a confusing type or range error


def test_nan_dt_is_reported_once():
    issues = issues_of("simulation: {dt: .nan, duration: 1.0}\nbodies:\n" + HANDLE)
    assert len(issues) == 1 and at(the_issue(issues, "not a finite number")) == (1, 18)


@pytest.mark.parametrize(
    "sim, line_col, fragment",
    [
        ("{dt: -0.001, duration: 1.0}", (1, 18), "-0.001 is out of range"),
        ("{dt: 0, duration: 1.0}", (1, 18), "0 is out of range"),
        ("{dt: 0.001, duration: 0}", (1, 35), "0 is out of range"),
        ("{dt: 0.001, steps: 0}", (1, 32), "0 is out of range"),
    ],
)
def test_positive_dt_and_duration(sim, line_col, fragment):
    issues = issues_of(f"simulation: {sim}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, fragment)
    assert at(issue) == line_col and ">" in issue.expected


def test_negative_mass():
    issues = issues_of(SIM + "bodies:\n" + HANDLE.replace("[1.0, 0.5, 0.5, 0.25]", "[1.0, -0.5, 0.5, 0.25]"))
    issue = the_issue(issues, "-0.5 is out of range")
    assert at(issue) == (6, 21) and issue.message.startswith("bodies[0].particles.masses[1]")
    assert issue.expected.startswith("a value > 0")


def test_enum_with_did_you_mean():
    issues = issues_of("simulation: {dt: 0.1, duration: 1, record: {streams: [bodies, invariant]}}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "unknown value 'invariant'")
    assert at(issue) == (1, 63) and "did you mean 'invariants'" in issue.message


def test_unknown_integrator_with_did_you_mean():
    issues = issues_of("simulation: {dt: 0.1, duration: 1, integrator: rk5}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "unknown integrator 'rk5'")
    assert at(issue) == (1, 48) and "did you mean 'rk4'" in issue.message and "split2" in issue.expected


@pytest.mark.parametrize("name, tolerance", [("rk5", False), ("Split2", False), ("rk4", True)])
def test_integrator_refusals_come_from_one_check(name, tolerance):
    """The scene loader, compile's overrides and the registry lookup say the registry's one refusal."""
    from rbcli.api import check_integrator, prepare

    refusal = check_integrator(name, tolerance=tolerance)
    assert refusal is not None and refusal.key == ("tolerance" if tolerance else "integrator")
    extra = ", tolerance: 1.0e-6" if tolerance else ""
    issue = the_issue(issues_of(f"simulation: {{dt: 0.1, duration: 1, integrator: {name}{extra}}}\nbodies:\n" + HANDLE),
                      refusal.reason.split(" (")[0].split(";")[0])  # fmt: skip
    assert issue.expected == refusal.expected
    scene = load_scene_text("simulation: {dt: 0.1, duration: 1}\nbodies:\n" + HANDLE)
    with pytest.raises(ValueError, match=re.escape(refusal.reason)):
        prepare(scene, integrator=name, tolerance=1e-6 if tolerance else None)
    if not tolerance:
        with pytest.raises(KeyError, match=re.escape(refusal.naming(name))):
            get_integrator(name)
    else:
        assert check_integrator("dopri5", tolerance=True) is None


def test_tolerance_needs_an_adaptive_integrator():
    issues = issues_of("simulation: {dt: 0.1, duration: 1, tolerance: 1.0e-6}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "tolerance needs an adaptive integrator")
    assert at(issue) == (1, 36) and "dopri5" in issue.expected


def test_output_extension():
    issues = issues_of("simulation: {dt: 0.1, duration: 1, output: out.csv}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "'out.csv' is not of the expected form")
    assert at(issue) == (1, 44) and ".mcap or .rrd" in issue.expected


# ---- oneOf: the branch the user meant, not a dump of all of them ------------------------------------------
def test_shape_type_typo_lists_the_types():
    body = "  - name: b\n    shape: {type: spehre, radius: 0.1}\n    spacing: 0.02\n    density: 1000\n"
    issues = issues_of(SIM + "bodies:\n" + body)
    assert len(issues) == 1
    issue = the_issue(issues, "unknown type 'spehre'")
    assert at(issue) == (4, 19) and "did you mean 'sphere'" in issue.message and "'capsule'" in issue.expected


def test_shape_missing_field_reports_only_that_branch():
    body = "  - name: b\n    shape: {type: cylinder, radius: 0.1}\n    spacing: 0.02\n    density: 1000\n"
    issues = issues_of(SIM + "bodies:\n" + body)
    assert len(issues) == 1
    assert at(the_issue(issues, "missing required key 'height'")) == (4, 5)


def test_orientation_wrong_length_in_the_right_form():
    issues = issues_of(SIM + "bodies:\n" + HANDLE + "    orientation: {wxyz: [1, 0, 0]}\n")
    assert len(issues) == 1
    issue = the_issue(issues, "wrong length: 3 items")
    assert at(issue) == (7, 25) and "exactly 4 items" in issue.expected


def test_orientation_unknown_form_with_did_you_mean():
    issues = issues_of(SIM + "bodies:\n" + HANDLE + "    orientation: {quaternion: [1, 0, 0, 0]}\n")
    issue = the_issue(issues, "unknown key 'quaternion'")
    assert at(issue) == (7, 19) and "{wxyz: [w, x, y, z]}" in issue.expected


def test_scalar_or_list_wrong_type_names_both_forms():
    issues = issues_of(SIM + "bodies:\n" + HANDLE.replace("[1.0, 0.5, 0.5, 0.25]", "heavy"))
    issue = the_issue(issues, "matches no accepted form")
    assert at(issue) == (6, 15)
    assert "a number > 0" in issue.expected and "a list of numbers > 0" in issue.expected


def test_angular_velocity_frame_typo():
    issues = issues_of(SIM + "bodies:\n" + HANDLE + "    angular_velocity: {bdy: [0, 0, 1]}\n")
    issue = the_issue(issues, "unknown key 'bdy'")
    assert at(issue) == (7, 24) and "did you mean 'body'" in issue.message


# ---- exclusive choices -------------------------------------------------------------------------------------
def test_both_velocity_and_momentum_at_the_second_key():
    issues = issues_of(SIM + "bodies:\n" + HANDLE + "    velocity: [0, 0, 1]\n    momentum: [0, 0, 2]\n")
    issue = the_issue(issues, "give either 'velocity' or 'momentum', not both")
    assert at(issue) == (8, 5)


def test_both_angular_momentum_and_angular_velocity():
    extra = "    angular_velocity: [0, 0, 1]\n    angular_momentum: [0, 0, 2]\n"
    issues = issues_of(SIM + "bodies:\n" + HANDLE + extra)
    assert at(the_issue(issues, "not both")) == (8, 5)


def test_particles_and_shape_together():
    extra = "    shape: {type: sphere, radius: 0.1}\n"
    issues = issues_of(SIM + "bodies:\n" + HANDLE + extra)
    issue = the_issue(issues, "give only one of")
    assert at(issue) == (7, 5) and "'particles', 'shape'" in issue.message


def test_body_without_particles_or_shape():
    issues = issues_of(SIM + "bodies:\n  - name: ghost\n    position: [0, 0, 0]\n")
    issue = the_issue(issues, "missing one of 'particles', 'shape', 'mesh', 'compound'")
    assert at(issue) == (3, 5)


# ---- semantic checks ---------------------------------------------------------------------------------------
def test_collinear_particles_are_rejected_with_the_reason():
    body = "  - name: rod\n    particles: {positions: [[0, 0, 0], [1, 0, 0], [3, 0, 0]], masses: 1.0}\n"
    issues = issues_of(SIM + "bodies:\n" + body)
    issue = the_issue(issues, "cannot be a rigid body")
    assert at(issue) == (4, 5)
    assert issue.message.startswith("bodies[0].particles")
    assert "on one line" in issue.message and "radius" in issue.expected


def test_collinear_particles_with_a_radius_are_a_rigid_body():
    body = "  - name: rod\n    particles: {positions: [[0, 0, 0], [1, 0, 0]], masses: 1.0, radius: 0.05}\n"
    assert issues_of(SIM + "bodies:\n" + body) == []


def test_single_particle_is_rejected():
    body = "  - name: dot\n    particles: {positions: [[1, 2, 3]], masses: [2.0]}\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + body), "a single particle is one point")
    assert at(issue) == (4, 5)
    assert "line" not in issue.message + issue.expected  # one particle lies on no line to move it off
    assert "radius" in issue.expected and "more particles" in issue.expected


def test_particles_all_at_one_point_are_told_to_spread():
    body = "  - name: dots\n    particles: {positions: [[1, 2, 3], [1, 2, 3]], masses: 1.0}\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + body), "all particles are at one point")
    assert "line" not in issue.expected and "spread in three dimensions" in issue.expected


def test_too_coarse_a_spacing_is_a_warning():
    # one lattice particle (radius spacing/2, a solid sphere) is a rigid body, but not much of a box
    body = "  - name: b\n    shape: {type: box, size: [0.2, 0.2, 0.2]}\n    spacing: 0.3\n    density: 1\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + body), "only 1 particle")
    assert issue.severity == "warning" and at(issue) == (4, 5) and "smaller spacing" in issue.expected


def test_zero_quaternion():
    issues = issues_of(SIM + "bodies:\n" + HANDLE + "    orientation: {wxyz: [0, 0, 0, 0]}\n")
    issue = the_issue(issues, "quaternion is zero")
    assert at(issue) == (7, 25)


def test_non_unit_quaternion_is_a_warning_and_normalised():
    spec, issues = analyse_scene_text(SIM + "bodies:\n" + HANDLE + "    orientation: {wxyz: [2, 0, 0, 0]}\n", "s.yaml")
    assert spec is not None and spec.bodies[0].orientation_wxyz.tolist() == [1, 0, 0, 0]
    issue = the_issue(issues, "norm 2")
    assert issue.severity == "warning" and at(issue) == (7, 25)
    assert spec.warnings == tuple(issues)


def test_non_orthonormal_matrix():
    extra = "    orientation: {matrix: [[1, 0, 0], [0, 1, 0], [0, 0.5, 1]]}\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + HANDLE + extra), "not orthonormal")
    assert at(issue) == (7, 27) and "determinant +1" in issue.expected


def test_reflection_matrix():
    extra = "    orientation: {matrix: [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}\n"
    assert at(the_issue(issues_of(SIM + "bodies:\n" + HANDLE + extra), "reflection")) == (7, 27)


def test_euler_same_axis_twice():
    extra = "    orientation: {euler: {angles: [0, 0, 0], convention: xxy}}\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + HANDLE + extra), "same axis twice")
    assert at(issue) == (7, 58)


def test_zero_rotation_axis():
    extra = "    orientation: {axis_angle: {axis: [0, 0, 0], angle: 1}}\n"
    assert at(the_issue(issues_of(SIM + "bodies:\n" + HANDLE + extra), "axis is zero")) == (7, 38)


def test_duplicate_body_names():
    issues = issues_of(SIM + "bodies:\n" + HANDLE + HANDLE)
    issue = the_issue(issues, "duplicate body name 'handle'")
    assert at(issue) == (7, 11) and "first at line 3" in issue.message


def test_duplicate_names_from_a_generator():
    grid = "  - grid: {name: handle, count: [2, 1, 1], spacing: 1, template: {particles: {positions: [[0,0,0],[1,0,0],[0,1,0]], masses: 1}}}\n"  # noqa: E501
    issues = issues_of(SIM + "bodies:\n" + grid + HANDLE.replace("name: handle", "name: handle_1"))
    assert at(the_issue(issues, "duplicate body name 'handle_1'")) == (4, 11)


def test_masses_count_mismatch():
    issues = issues_of(SIM + "bodies:\n" + HANDLE.replace("[1.0, 0.5, 0.5, 0.25]", "[1.0, 0.5]"))
    issue = the_issue(issues, "2 values for 4 particle positions")
    assert at(issue) == (6, 15) and "one mass per position" in issue.expected


def test_shape_needs_spacing_and_density():
    body = "  - name: b\n    shape: {type: sphere, radius: 0.1}\n"
    issues = issues_of(SIM + "bodies:\n" + body)
    assert at(the_issue(issues, "needs 'spacing' or 'count'")) == (3, 5)
    body = "  - name: b\n    shape: {type: sphere, radius: 0.1}\n    spacing: 0.02\n"
    assert at(the_issue(issues_of(SIM + "bodies:\n" + body), "needs 'density' or 'mass'")) == (3, 5)


def test_density_with_explicit_particles():
    issue = the_issue(issues_of(SIM + "bodies:\n" + HANDLE + "    density: 1000\n"), "'density' applies to shape")
    assert at(issue) == (7, 5)


def test_spacing_too_small_is_refused_before_allocating():
    body = "  - name: b\n    shape: {type: sphere, radius: 1.0}\n    spacing: 1.0e-6\n    density: 1\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + body), "lattice points")
    assert at(issue) == (4, 5) and "limit" in issue.message


def test_unreadable_mesh_file(tmp_path):
    body = "  - name: m\n    mesh: {file: meshes/nope.obj}\n    spacing: 0.1\n    density: 1\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + body, tmp_path), "does not exist")
    assert at(issue) == (4, 18) and "nope.obj" in issue.message


def test_open_mesh_is_rejected(tmp_path):
    (tmp_path / "open.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n")
    body = "  - name: m\n    mesh: {file: open.obj}\n    spacing: 0.1\n    density: 1\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + body, tmp_path), "not closed")
    assert at(issue) == (4, 18)


def test_garbage_mesh_file(tmp_path):
    (tmp_path / "junk.obj").write_bytes(b"\x00\x01\x02 not a mesh")
    body = "  - name: m\n    mesh: {file: junk.obj}\n    spacing: 0.1\n    density: 1\n"
    issue = the_issue(issues_of(SIM + "bodies:\n" + body, tmp_path), "junk.obj")
    assert at(issue) == (4, 18)


def test_record_rate_faster_than_steps():
    issues = issues_of("simulation: {dt: 0.01, duration: 1, record: {rate: 1000}}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "faster than the step rate")
    assert at(issue) == (1, 52)


def test_record_rate_not_a_whole_number_of_steps_is_a_warning():
    spec, issues = analyse_scene_text("simulation: {dt: 0.01, duration: 1, record: {rate: 30}}\nbodies:\n" + HANDLE)
    issue = the_issue(issues, "not a whole number of steps")
    assert issue.severity == "warning" and spec.simulation.record.every == 3


def test_dt_longer_than_duration():
    issue = the_issue(issues_of("simulation: {dt: 2, duration: 1}\nbodies:\n" + HANDLE), "longer than duration")
    assert at(issue) == (1, 18)


def test_generator_template_error_reported_once():
    grid = "  - grid: {name: g, count: [10, 10, 1], spacing: 1, template: {shape: {type: sphere, radius: 0.1}, spacing: 0.05, densty: 3}}\n"  # noqa: E501
    issues = issues_of(SIM + "bodies:\n" + grid)
    assert len(issues) == 1 and "did you mean 'density'" in issues[0].message


def test_error_in_defaults_is_located_in_defaults_and_reported_once():
    text = SIM + "defaults:\n  velocity: [0, 0]\nbodies:\n" + HANDLE + HANDLE.replace("handle", "h2")
    issues = issues_of(text)
    assert len(issues) == 1
    assert at(the_issue(issues, "wrong length")) == (3, 13)


def test_defaults_velocity_replaced_by_a_body_momentum():
    text = SIM + "defaults:\n  velocity: [0, 0, 1]\nbodies:\n" + HANDLE + "    momentum: [1, 0, 0]\n"
    spec = load_scene_text(text)
    assert spec.bodies[0].velocity is None and spec.bodies[0].momentum.tolist() == [1, 0, 0]


def test_all_issues_reported_at_once():
    text = """\
    simulation: {dt: -1, duration: 1, integrator: eulr-matrix}
    gravity: [0, 0]
    bodies:
      - name: a
        particles: {positions: [[0, 0, 0], [1, 0, 0]], masses: 1}
      - name: b
        shape: {type: box, size: [1, 1, -1]}
        spacing: 0.1
        density: 1
      - name: a
        particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0]], masses: [1, 2]}
    """
    with pytest.raises(SceneError) as info:
        load_scene_text(textwrap.dedent(text), "s.yaml")
    found = sorted(at(i) for i in info.value.issues)
    # dt, gravity, rod inertia, box size, duplicate name, masses count (integrator not checked: sim is bad)
    assert found == [(1, 18), (2, 10), (5, 5), (7, 37), (10, 11), (11, 71)]


def test_top_level_not_a_mapping():
    issue = the_issue(issues_of("- a\n- b\n"), "a scene must be a mapping")
    assert at(issue) == (1, 1)


def test_missing_file_via_check_scene(tmp_path):
    issues = check_scene(tmp_path / "nope.yaml")
    assert len(issues) == 1 and issues[0].location is None and "nope.yaml" in issues[0].message
    with pytest.raises(SceneError):
        load_scene(tmp_path / "nope.yaml")


def test_template_position_is_explained():
    grid = "  - grid: {name: g, count: [2, 1, 1], spacing: 1, template: {position: [1, 2, 3], shape: {type: sphere, radius: 0.1}, spacing: 0.05, density: 1}}\n"  # noqa: E501
    issue = the_issue(issues_of(SIM + "bodies:\n" + grid), "set by the generator")
    assert at(issue) == (3, 62)


# ---- format version -----------------------------------------------------------------------------------------
def test_newer_scene_format_is_the_only_error():
    # a newer file may use keys this rbsim does not know: one located error, not a screen of unknown keys
    issues = issues_of("version: 2\n" + SIM + "bodies:\n" + HANDLE + "    warp: 9\n")
    assert len(issues) == 1
    issue = the_issue(issues, "scene format version 2 is newer than this rbsim understands")
    assert at(issue) == (1, 10) and "up to version 1" in issue.message and "newer rbsim" in issue.expected


def test_current_scene_format_version_is_accepted():
    assert issues_of("version: 1\n" + SIM + "bodies:\n" + HANDLE) == []


def test_scene_format_version_must_be_a_positive_integer():
    assert at(the_issue(issues_of("version: 0\n" + SIM + "bodies:\n" + HANDLE), "out of range")) == (1, 10)
    assert at(the_issue(issues_of("version: one\n" + SIM + "bodies:\n" + HANDLE), "wrong type")) == (1, 10)
