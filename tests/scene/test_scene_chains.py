"""Chain generators (`bodies: - chain: {...}`, docs/scenes.md "Chains"): a generated chain is the same
scene, spec for spec and array for array once compiled, as the chain written out by hand; each bad field
is a located error saying what was expected; a 2,000-link chain validates with the structure the format
promises. Nothing here compiles a kernel (validate does not)."""

from __future__ import annotations

import dataclasses
import textwrap
from pathlib import Path

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

from rbcli.cli.schema import schema
from rbcli.cli.validate import validate
from rbcli.physics.joints.tables import WORLD
from rbcli.physics.rotation import quat_rotate
from rbcli.scene.load import analyse_scene_text, load_scene, load_scene_text
from rbcli.scene.spec import SceneIssue

REPO = Path(__file__).resolve().parents[2]
HEAD = "simulation: {dt: 0.001, duration: 0.01}\ngravity: [0, 0, -9.81]\n"
LINK = (
    "{shape: {type: capsule, radius: 0.05, height: 0.15, axis: z}, spacing: 0.025, density: 1000, "
    "velocity: [0.5, 0, 0]}"
)
HINGE = (
    "{type: hinge, axis: [0, 2, 0], limits: [-1, 0.5], damping: 0.1, motor: {speed: 1, max_torque: 2}, collide: true}"
)

# four capsules hanging down from (0, 0, 2) on hinges, 0.25 m apart: centres at z = 2 - (k + 1/2) 0.25 and
# joints at z = 2 - k 0.25, numbers a float holds exactly, so the hand-written file can say them
GENERATED = (
    HEAD
    + f"""\
bodies:
  - chain:
      name: link
      count: 4
      start: [0, 0, 2]
      direction: [0, 0, -2]
      spacing: 0.25
      joint: {HINGE}
      template: {LINK}
"""
)
BY_HAND = (
    HEAD
    + "bodies:\n"
    + "".join(f"  - {{name: link{k}, position: [0, 0, {2 - (k + 0.5) * 0.25}], {LINK[1:]}\n" for k in range(4))
    + "joints:\n"
    + "".join(
        f"  - {{name: link_joint{k}, bodies: [link{k}, {f'link{k - 1}' if k else 'world'}], anchor: [0, 0, "
        f"{2 - k * 0.25}], {HINGE[1:]}\n"
        for k in range(4)
    )
)


def assert_same_specs(a, b) -> None:
    """Every field equal (arrays bit for bit), but where each was written (`location`, `locations`)."""
    assert type(a) is type(b)
    for field in dataclasses.fields(a):
        if field.name in ("location", "locations"):
            continue
        x, y = getattr(a, field.name), getattr(b, field.name)
        if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
            assert x is not None and y is not None, (field.name, x, y)
            assert x.shape == y.shape and np.array_equal(x, y), (field.name, x, y)
        else:
            assert x == y, (field.name, x, y)


def assert_same_scenes(generated, by_hand) -> None:
    assert [b.name for b in generated.bodies] == [b.name for b in by_hand.bodies]
    assert [j.name for j in generated.joints] == [j.name for j in by_hand.joints]
    for a, b in zip(generated.bodies, by_hand.bodies, strict=True):
        assert_same_specs(a, b)
    for a, b in zip(generated.joints, by_hand.joints, strict=True):
        assert_same_specs(a, b)
    assert generated.simulation == by_hand.simulation
    # and what compile made of them: the joint table and the initial state, bit for bit
    ga, ha = generated.compiled_model, by_hand.compiled_model
    for key, value in ga.model.joint._asdict().items():
        if isinstance(value, np.ndarray):
            assert np.array_equal(value, getattr(ha.model.joint, key)), key
    for key in ("x", "q", "P", "L"):
        assert np.array_equal(getattr(ga.initial_state, key), getattr(ha.initial_state, key)), key


def test_a_generated_hinge_chain_is_the_chain_written_by_hand():
    generated, by_hand = load_scene_text(GENERATED), load_scene_text(BY_HAND)
    assert [b.name for b in generated.bodies] == ["link0", "link1", "link2", "link3"]
    assert [j.bodies for j in generated.joints] == [
        ("link0", "world"),
        ("link1", "link0"),
        ("link2", "link1"),
        ("link3", "link2"),
    ]
    # a chain's joints choose it, as `joints:` do: a hinge chain is a tree (docs/trees.md)
    assert generated.simulation.integrator == "reduced-rk4"
    assert_same_scenes(generated, by_hand)


def hand_written_chain_100() -> str:
    """scenes/joints/chain_100.yaml as it was written out by hand before the generator (the bodies and
    joints the file listed, with their positions computed as it computed them: 0.02 (i + 1))."""
    particles = "[[0.004, 0, 0], [-0.004, 0, 0], [0, 0.004, 0], [0, -0.004, 0], [0, 0, 0.004], [0, 0, -0.004]]"
    lines = [
        "name: chain-100",
        "simulation: {dt: 0.0005, duration: 3.0, integrator: split2, record: {every: 20}}",
        "gravity: [0, 0, -9.81]",
        f"defaults:\n  particles: {{positions: {particles}, masses: 0.0016666666666666668}}",
        "bodies:",
        *(f"  - {{name: bead{i}, position: [{0.02 * (i + 1)!r}, 0, 2.0]}}" for i in range(100)),
        "joints:",
        "  - {type: distance, bodies: [bead0, world], anchors: [[0, 0, 0], [0, 0, 2.0]]}",
        *(
            f"  - {{type: distance, bodies: [bead{i}, bead{i - 1}], anchors: [[0, 0, 0], [0, 0, 0]]}}"
            for i in range(1, 100)
        ),
    ]
    return "\n".join(lines) + "\n"


def test_the_shipped_chain_100_is_its_hand_written_form():
    """The scene now says it with a chain generator; it is the same scene (its joints keep their names)."""
    path = REPO / "scenes" / "joints" / "chain_100.yaml"
    assert "chain:" in path.read_text()
    assert_same_scenes(load_scene(path), load_scene_text(hand_written_chain_100()))


def test_a_free_chain_of_ball_joints_attached_by_the_joints_list_and_a_named_prefix():
    text = HEAD + textwrap.dedent("""\
        bodies:
          - chain:
              name: bead
              count: 5
              direction: [1, 0, 0]
              spacing: 0.1
              attach: false
              joint: {type: ball, name: knot}
              template: {particles: {positions: [[0, 0, 0]], masses: 0.01, radius: 0.01}}
        joints:
          - {type: ball, bodies: [bead4, world], anchor: [0.5, 0, 0]}
        """)
    spec = load_scene_text(text)
    # no joint 0 in a free chain: joint k holds bead k; the `joints:` list's come after the chains'
    assert [j.name for j in spec.joints] == ["knot1", "knot2", "knot3", "knot4", "joint0"]
    np.testing.assert_allclose([b.position[0] for b in spec.bodies], [0.05, 0.15, 0.25, 0.35, 0.45], atol=1e-16)
    np.testing.assert_array_equal(spec.joints[0].anchor, [0.1, 0, 0])


@pytest.mark.parametrize("kind", ["distance", "ball", "fixed"])
def test_a_chain_attached_to_a_turned_body_holds_it_at_the_start_point(kind):
    """Joint 0's anchor on the body it attaches to is the start point at the initial poses (for a distance
    joint, given in that body's own frame: c + R^T (p - x)), read back from the compiled table."""
    text = HEAD + textwrap.dedent(f"""\
        bodies:
          - name: crane
            particles: {{positions: [[0, 0, 0], [1, 0, 0], [0, 0.3, 0]], masses: [2, 1, 1], radius: 0.05}}
            position: [0.2, 0.1, 3]
            orientation: {{axis_angle: {{axis: [1, 2, 3], angle: 0.7}}}}
          - chain:
              name: rope
              count: 3
              start: [0.5, 0.3, 2.9]
              direction: [0, 0, -1]
              spacing: 0.2
              link_centre: 1
              attach: crane
              joint: {{type: {kind}}}
              template: {{particles: {{positions: [[0, 0, 0]], masses: 0.01, radius: 0.01}}}}
        """)
    spec = load_scene_text(text)
    table, state = spec.compiled_model.model.joint, spec.compiled_model.initial_state
    assert spec.joints[0].bodies == ("rope0", "crane")
    if kind == "fixed":  # welds are merged at compile time (scene/welds.py): crane and links are one body
        assert table is None and spec.compiled_model.model.body_count == 1
        return
    assert table.body_b[0] == 0
    on_crane = state.x[0] + quat_rotate(state.q[0], table.anchor_b[0])
    np.testing.assert_allclose(on_crane, [0.5, 0.3, 2.9], rtol=0, atol=1e-15)
    if kind == "distance":  # rods from the start point to bead 0, then bead to bead, each 0.2 m
        np.testing.assert_allclose(table.length, [0.2, 0.2, 0.2], rtol=0, atol=1e-15)


def test_defaults_reach_the_template_and_a_chain_makes_the_joint_forces_stream_meaningful():
    text = textwrap.dedent("""\
        simulation: {dt: 0.001, duration: 0.01, record: {streams: [bodies, joint_forces]}}
        defaults: {particles: {positions: [[0, 0, 0]], masses: 0.02, radius: 0.01}}
        bodies:
          - chain: {name: b, count: 3, direction: [0, 1, 0], spacing: 0.1, joint: {type: ball}, template: {}}
        """)
    spec, issues = analyse_scene_text(text, "s.yaml")
    assert spec is not None and issues == []
    assert all(b.particle_mass.tolist() == [0.02] for b in spec.bodies)


# ---- located errors ---------------------------------------------------------------------------------------
def chain_scene(**keys: str) -> str:
    """A valid three-link chain next to a body `post`, with `keys` (chain keys as YAML text) changed or added;
    a key whose text is None is left out."""
    fields = {
        "name": "link",
        "count": "3",
        "direction": "[1, 0, 0]",
        "spacing": "0.1",
        "joint": "{type: ball}",
        "template": "{particles: {positions: [[0, 0, 0]], masses: 0.1, radius: 0.01}}",
        **keys,
    }
    lines = [f"      {key}: {value}" for key, value in fields.items() if value is not None]
    post = "  - {name: post, particles: {positions: [[0, 0, 0]], masses: 1, radius: 0.1}, position: [0, 0, 3]}"
    return HEAD + "bodies:\n" + post + "\n  - chain:\n" + "\n".join(lines) + "\n"


def the_error(text: str, fragment: str) -> tuple[SceneIssue, tuple[int, int], str]:
    """The one error whose message holds `fragment`, its (line, column), and that line's text."""
    spec, issues = analyse_scene_text(text, "s.yaml")
    assert spec is None
    matching = [i for i in issues if fragment in i.message and i.severity == "error"]
    assert len(matching) == 1, f"{fragment!r} in {[str(i) for i in issues]}"
    issue = matching[0]
    assert issue.location is not None
    where = (issue.location.line, issue.location.column)
    return issue, where, text.splitlines()[where[0] - 1]


def joint_line(text: str) -> int:
    """The line of the chain's `joint:` key (where its joints' names are given)."""
    return next(n for n, line in enumerate(text.splitlines(), 1) if line.startswith("      joint:"))


def pointed_at(where: tuple[int, int], line: str) -> str:
    return line[where[1] - 1 :]


# (chain keys changed, the error's words, where it points, what it expects)
BAD_FIELDS = [
    ({"count": "0"}, "0 is out of range", "0", "a value >= 1 (number of links [count])"),
    ({"count": "2.5"}, "wrong type: got a number (2.5)", "2.5", "an integer"),
    ({"count": "ten"}, "wrong type: got a string ('ten')", "ten", "an integer"),
    ({"count": "200000"}, "200,000 links is too many", "200000", "at most 100,000 links"),
    ({"direction": "[0, 0, 0]"}, "a zero direction", "[0, 0, 0]", "a non-zero vector"),
    ({"direction": "[1, 0]"}, "wrong length: 2 items", "[1, 0]", "exactly 3 items"),
    ({"direction": None}, "missing required key 'direction'", "chain:", "'direction'"),
    ({"spacing": "0"}, "0 is out of range", "0", "a value > 0 (distance between consecutive links [m])"),
    ({"link_centre": "1.5"}, "1.5 is out of range", "1.5", "a value <= 1"),
    (
        {"joint": "{type: hings, axis: [0, 1, 0]}"},
        "unknown type 'hings' — did you mean 'hinge'?",
        "hings",
        "'slider'",
    ),
    ({"joint": "{type: hinge}"}, "missing required key 'axis'", "joint:", "'axis': joint axis [1]"),
    ({"joint": "{type: hinge, axis: [0, 0, 0]}"}, "a zero axis", "[0, 0, 0]", "a non-zero vector"),
    ({"joint": "{type: ball, axis: [0, 1, 0]}"}, "unknown key 'axis'", "axis", "one of 'type', 'name', 'collide'"),
    (
        {"joint": "{type: hinge, axis: [0, 1, 0], limits: [1, -1]}"},
        "lower limit 1 is above upper limit -1",
        "[1, -1]",
        "lower <= upper",
    ),  # fmt: skip
    (
        {"joint": "{type: slider, axis: [1, 0, 0], motor: {speed: 1, max_torque: 2}}"},
        "unknown key 'max_torque' — did you mean 'max_force'?",
        "max_torque",
        "'max_force'",
    ),  # fmt: skip
    ({"attach": "pots"}, "no body named 'pots' (did you mean 'post'?)", "pots", "a body name, 'world' or false"),
    ({"attach": "3"}, "wrong type: got a number (3)", "3", "a string or true or false"),
    ({"attach": "link0"}, "link 'link0' is attached to itself", "link0", "another body"),
    ({"spacng": "0.1", "spacing": None}, "unknown key 'spacng' — did you mean 'spacing'?", "spacng", "'spacing'"),
    (
        {"template": "{name: x, particles: {positions: [[0, 0, 0]], masses: 0.1}}"},
        "'name' is set by the generator",
        "name: x",
        "",
    ),  # fmt: skip
]


@pytest.mark.parametrize("keys, fragment, at, expected", BAD_FIELDS)
def test_each_bad_field_is_located_at_the_field_with_what_was_expected(keys, fragment, at, expected):
    issue, where, line = the_error(chain_scene(**keys), fragment)
    assert pointed_at(where, line).startswith(at), (str(issue), line)
    assert expected in issue.expected, str(issue)


def test_the_editor_schema_judges_chains_as_rbsims_schema_stage_does():
    """The published schema, as an editor applies it to the file as written (test_scene_schema_editor.py),
    rejects the bad chains the schema stage rejects and accepts the others, and the good chains here."""
    from test_scene_schema_editor import editor_errors, rbsim_schema_stage_rejects

    texts = [chain_scene(**keys) for keys, *_ in BAD_FIELDS] + [GENERATED, chain_scene(attach="true")]
    judged = [(text, rbsim_schema_stage_rejects(text)) for text in texts]
    assert sum(rejects for _, rejects in judged) >= 10 and sum(not rejects for _, rejects in judged) >= 8
    assert [bool(editor_errors(text)) for text, _ in judged] == [rejects for _, rejects in judged]


def test_errors_only_the_compiled_joints_show_point_at_the_key_that_decides_and_are_told_once():
    # hinge limits past a half turn, on every one of the 300 joints: one error, counting the others
    issue, where, line = the_error(
        chain_scene(count="300", joint="{type: hinge, axis: [0, 1, 0], limits: [-1, 4]}"), "reach past a half turn"
    )
    assert pointed_at(where, line).startswith("[-1, 4]") and "(and 299 more joints given here)" in issue.message
    # a distance chain whose link 0 sits on the start point: a rod of length 0, at link_centre
    issue, where, line = the_error(chain_scene(joint="{type: distance}", link_centre="0"), "rod of length 0")
    assert pointed_at(where, line).startswith("0") and issue.message.startswith("joint 'link_joint0'")


def test_static_links_without_contact_are_one_error():
    template = "{static: true, particles: {positions: [[0, 0, 0]], masses: 0.1, radius: 0.01}}"
    issue, where, line = the_error(chain_scene(count="500", template=template), "static bodies need contact")
    assert issue.message.startswith("body 'link0'") and pointed_at(where, line).startswith("chain:")


def test_names_that_collide_with_other_bodies_and_joints_are_located():
    # a body named like link 2, after the chain: at the body's name
    text = chain_scene() + "  - {name: link2, particles: {positions: [[0, 0, 0]], masses: 1, radius: 0.1}}\n"
    issue, where, line = the_error(text, "duplicate body name 'link2'")
    assert pointed_at(where, line).startswith("link2,")
    # a `joints:` entry named like a chain's joint: at that entry's name, naming the chain's line
    text = (
        chain_scene(joint="{type: ball, name: j}")
        + "joints:\n  - {name: j1, type: ball, bodies: [post, world], anchor: [0, 0, 3]}\n"
    )
    issue, where, line = the_error(text, "duplicate joint name 'j1'")
    assert pointed_at(where, line).startswith("j1,") and f"(first at line {joint_line(text)})" in issue.message
    # two chains whose joints take the same names: at the second chain's prefix, once
    second = "  - chain: {name: other, count: 2, direction: [0, 1, 0], spacing: 0.1, joint: {type: ball, name: j}, " \
             "template: {particles: {positions: [[0, 0, 0]], masses: 0.1, radius: 0.01}}}\n"  # fmt: skip
    issue, where, line = the_error(chain_scene(joint="{type: ball, name: j}") + second, "duplicate joint name 'j0'")
    assert "and 1 more" in issue.message and pointed_at(where, line).startswith("j}")


# ---- a long chain -----------------------------------------------------------------------------------------
LONG = 2000


def test_a_2000_link_chain_validates_with_the_structure_the_format_promises(tmp_path):
    """Names, centres of mass on the line, joint k holding link k to link k-1 (link 0 to the world) at
    start + k s d, a tree (no loop) for the solver; and `rbsim validate` says ok. The 5,000-link timing:
    benchmarks/bench_validate.py --chain 5000."""
    path = tmp_path / "rope.yaml"
    path.write_text(HEAD + textwrap.dedent(f"""\
        bodies:
          - chain:
              name: r
              count: {LONG}
              start: [1, 2, 30]
              direction: [3, 0, -4]
              spacing: 0.01
              joint: {{type: hinge, axis: [0, 1, 0], damping: 1.0e-4}}
              template: {{particles: {{positions: [[-0.004, 0, 0], [0.004, 0, 0]], masses: 0.001, radius: 0.002}}}}
        """))  # fmt: skip
    spec = load_scene(path)
    assert [b.name for b in spec.bodies[:2]] == ["r0", "r1"] and spec.bodies[-1].name == f"r{LONG - 1}"
    assert [j.name for j in spec.joints[:2]] == ["r_joint0", "r_joint1"] and len(spec.joints) == LONG
    d = np.array([0.6, 0.0, -0.8])
    k = np.arange(LONG)[:, None]
    # (k + 1/2) s d from the start, as the docs say; to round-off (d = [3, 0, -4] / 5 is not exact)
    np.testing.assert_allclose([b.position for b in spec.bodies], [1, 2, 30] + (k + 0.5) * 0.01 * d, atol=1e-13)
    np.testing.assert_allclose([j.anchor for j in spec.joints], [1, 2, 30] + k * 0.01 * d, atol=1e-13)
    table = spec.compiled_model.model.joint
    np.testing.assert_array_equal(table.body_a, np.arange(LONG))
    np.testing.assert_array_equal(table.body_b, [WORLD, *range(LONG - 1)])
    assert np.all(table.graph.joint_node >= 0)  # a tree: no joint closes a loop
    assert np.all(table.damping == 1e-4) and table.row_count.sum() == 5 * LONG
    app = typer.Typer(add_completion=False)
    app.command("validate")(validate)
    app.command("schema")(schema)  # two commands: with one, typer would take "validate" for the scene
    result = CliRunner().invoke(app, ["validate", str(path)])
    assert result.exit_code == 0 and f"ok ({LONG} bodies, {2 * LONG} particles)" in result.output, result.output
