"""`rbsim validate` and `rbsim schema` through Typer's CliRunner on a tiny app with just these commands."""

from __future__ import annotations

import json
import subprocess
import sys
from collections import Counter
from pathlib import Path

import pytest
import typer
import yaml
from typer.testing import CliRunner

from rbcli.cli.schema import schema
from rbcli.cli.validate import validate

REPO = Path(__file__).resolve().parents[2]
GOOD = """\
simulation: {dt: 0.001, duration: 1.0}
bodies:
  - name: handle
    particles:
      positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]]
      masses: [1.0, 0.5, 0.5, 0.25]
"""

app = typer.Typer(add_completion=False)
app.command("validate")(validate)
app.command("schema")(schema)
runner = CliRunner()


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_valid_file_exits_0(tmp_path):
    result = runner.invoke(app, ["validate", str(write(tmp_path, "good.yaml", GOOD))])
    assert result.exit_code == 0, result.output
    assert "ok (1 body, 4 particles)" in result.output


def test_invalid_file_exits_1_with_located_issues(tmp_path):
    bad = write(tmp_path, "bad.yaml", GOOD.replace("dt: 0.001", "dt: -1").replace("masses:", "mases:"))
    result = runner.invoke(app, ["validate", str(bad)])
    assert result.exit_code == 1
    lines = result.output.splitlines()
    assert f"{bad}:1:18: error: simulation.dt: -1 is out of range; expected a value > 0 (time step [s])" in lines
    assert any(line.startswith(f"{bad}:6:7: error: bodies[0].particles.mases: unknown key 'mases'") for line in lines)


def test_every_file_is_checked_and_any_failure_exits_1(tmp_path):
    good = write(tmp_path, "good.yaml", GOOD)
    bad = write(tmp_path, "bad.yaml", "simulation: {dt: 1}\n")
    result = runner.invoke(app, ["validate", str(bad), str(good)])
    assert result.exit_code == 1
    assert f"{good}: ok" in result.output and f"{bad}:1:1: error:" in result.output
    assert "1 of 2 scene files valid" in result.output


def test_missing_file_exits_1_naming_it(tmp_path):
    result = runner.invoke(app, ["validate", str(tmp_path / "nope.yaml")])
    assert result.exit_code == 1
    assert f"{tmp_path / 'nope.yaml'}: error: scene file does not exist; expected" in result.output


def test_usage_errors_exit_2():
    assert runner.invoke(app, ["validate"]).exit_code == 2
    assert runner.invoke(app, ["validate", "--bogus", "x.yaml"]).exit_code == 2


def test_warnings_alone_exit_0(tmp_path):
    text = GOOD + "    orientation: {wxyz: [2, 0, 0, 0]}\n"
    result = runner.invoke(app, ["validate", str(write(tmp_path, "w.yaml", text))])
    assert result.exit_code == 0 and ": warning: bodies[0].orientation.wxyz: quaternion has norm 2" in result.output


def test_verbose_prints_mass_properties(tmp_path):
    plate = GOOD.replace(
        "[[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]]", "[[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]"
    ).replace("[1.0, 0.5, 0.5, 0.25]", "[1.0, 1.0, 0.5, 0.5]")
    result = runner.invoke(app, ["validate", "-v", str(write(tmp_path, "plate.yaml", plate))])
    assert result.exit_code == 0
    assert (
        "handle: 4 particles, mass 3 kg, centre of mass [0, 0, 0] m (body frame), principal inertia [1, 2, 3] kg m^2"
        in (result.output)
    )


def test_validate_writes_nothing(tmp_path):
    path = write(tmp_path, "good.yaml", GOOD.replace("duration: 1.0", "duration: 1.0, output: run.mcap"))
    assert runner.invoke(app, ["validate", str(path)]).exit_code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.yaml"]


def test_schema_command_prints_the_schema():
    result = runner.invoke(app, ["schema"])
    assert result.exit_code == 0
    assert json.loads(result.output)["title"] == "rbsim scene"


@pytest.mark.parametrize("verbose", [[], ["-v"]], ids=["plain", "verbose"])
def test_validate_imports_no_heavy_libraries(tmp_path, verbose):
    """-v plans the run (steps, kernel families) from the compiled tables without numba: on a free body and
    on a scene with joints and contact."""
    paths = [str(write(tmp_path, "good.yaml", GOOD)), str(REPO / "scenes" / "joints" / "door.yaml")]
    code = (
        "import sys, typer\n"
        "from rbcli.cli.validate import validate\n"
        "app = typer.Typer(); app.command()(validate); app.command('x')(lambda: None)\n"
        f"sys.argv = ['v', 'validate', *{verbose!r}, *{paths!r}]\n"
        "try:\n    app()\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('numba', 'rerun', 'mcap', 'trimesh', 'scipy') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"
    assert (out.stdout.count("  cost: ") == 2 and "  joints: " in out.stdout) == bool(verbose), out.stdout


# rows per joint type (docs/joints.md, "Rows")
JOINT_ROWS = {"ball": 3, "hinge": 5, "fixed": 6, "slider": 5, "distance": 1}


def verbose_lines(path: Path) -> list[str]:
    result = runner.invoke(app, ["validate", "-v", str(path)])
    assert result.exit_code == 0, result.output
    return result.output.splitlines()


def test_verbose_tells_the_joints_rows_loops_and_cost_of_the_four_bar():
    """Every number against the scene file itself: joints by type and their rows, and the loop. The joints
    and bodies form one connected graph with the world as a vertex, so it has joints - (bodies + 1) + 1
    independent cycles; the solver closes each with the first joint (in file order) whose ends the earlier
    joints already connect: here the last joint, whose rows become the auxiliary rows."""
    path = REPO / "scenes" / "joints" / "four_bar.yaml"
    scene = yaml.safe_load(path.read_text())
    joints, bodies = scene["joints"], scene["bodies"]
    kinds = Counter(joint["type"] for joint in joints)
    rows = sum(JOINT_ROWS[joint["type"]] for joint in joints)
    loops = len(joints) - len(bodies)
    assert loops == 1  # the file's own claim: a four-bar is one loop
    last = joints[-1]
    expected = (
        "  joints: " + ", ".join(f"{n} {kind}" for kind, n in kinds.items()) + f"; {rows} constraint rows; "
        f"1 loop, closed by {last['name']!r} ({JOINT_ROWS[last['type']]} auxiliary rows)"
    )
    lines = verbose_lines(path)
    assert expected in lines, lines
    sim = scene["simulation"]
    steps = round(sim["duration"] / sim["dt"])
    particles = sum(len(body["particles"]["positions"]) for body in bodies)
    assert (
        f"  cost: {len(bodies)} bodies, {particles} particles, {steps:,} steps of {sim['dt']:g} s "
        f"({sim['integrator']}): {steps * len(bodies):,} body-steps"
    ) in lines, lines
    (kernels,) = [line for line in lines if line.startswith("  kernels: ")]
    assert f"the {sim['integrator']} loop for free bodies + forces (gravity) + joints (" in kernels


def test_verbose_tells_the_cost_of_a_free_body_scene_and_no_joints():
    path = REPO / "scenes" / "tutorial.yaml"
    scene = yaml.safe_load(path.read_text())
    (body,) = scene["bodies"]
    sim = scene["simulation"]
    steps = round(sim["duration"] / sim["dt"])
    lines = verbose_lines(path)
    assert not any(line.startswith("  joints:") for line in lines), lines
    particles = len(body["particles"]["positions"])
    assert (
        f"  cost: 1 body, {particles} particles, {steps:,} steps of {sim['dt']:g} s ({sim['integrator']}): "
        f"{steps:,} body-steps"
    ) in lines, lines
    (kernels,) = [line for line in lines if line.startswith("  kernels: ")]
    assert f"the {sim['integrator']} loop for free bodies + forces (gravity) (" in kernels


def test_verbose_counts_contact_spheres_and_sub_steps_in_the_cost(tmp_path):
    """box_drop with 4 sub-steps: body-steps = steps x sub-steps x bodies, as `rbsim run` counts them."""
    text = (REPO / "scenes" / "contact" / "box_drop.yaml").read_text()
    text = text.replace("\n  substeps: auto", "\n  substeps: 4  #")
    assert "substeps: 4" in text
    sim = yaml.safe_load(text)["simulation"]
    assert "integrator" not in sim  # split2, the default with contact
    steps = round(sim["duration"] / sim["dt"])
    lines = verbose_lines(write(tmp_path, "box.yaml", text))
    (contact,) = [line for line in lines if line.startswith("  contact: ")]
    # the brick touches as its box: its lattice spheres are its mass only, and the cost counts one shape
    assert contact.startswith("  contact: 1 box (it touches planes, walls and bodies as its exact shape)"), contact
    assert (
        f"1 contact shape, {steps:,} steps of {sim['dt']:g} s x 4 sub-steps (split2): {steps * 4:,} body-steps"
    ) in "\n".join(lines)
    (kernels,) = [line for line in lines if line.startswith("  kernels: ")]
    assert "+ contact (" in kernels and "joints" not in kernels


SHAPES_ON_A_PLANE = """\
simulation: {{dt: 0.001, duration: 0.1}}
gravity: [0, 0, -9.81]
contact: {{ground: 0{off}}}
bodies:
  - {{name: brick, shape: {{type: box, size: [0.2, 0.1, 0.05]}}, spacing: 0.025, density: 500, position: [0, 0, 0.2]}}
  - {{name: pill, shape: {{type: capsule, radius: 0.03, height: 0.1}}, spacing: 0.02, density: 500,
     position: [0.5, 0, 0.2]}}
  - {{name: ball, shape: {{type: sphere, radius: 0.05}}, spacing: 0.025, density: 500, position: [1, 0, 0.2]}}
"""


def test_the_contact_line_says_which_shapes_touch_as_themselves(tmp_path):
    """A box and a capsule touch the ground as their exact primitive (issue 47: the run's cost depends on
    it); a sphere shape is one exact sphere already and is not counted; with `primitives: false` no shape
    does, and the line says nothing of shapes."""
    on = write(tmp_path, "on.yaml", SHAPES_ON_A_PLANE.format(off=""))
    off = write(tmp_path, "off.yaml", SHAPES_ON_A_PLANE.format(off=", primitives: false"))
    lines = {}
    for path in (on, off):
        result = runner.invoke(app, ["validate", str(path)])
        assert result.exit_code == 0, result.output
        lines[path.stem] = next(line for line in result.output.splitlines() if "contact:" in line)
    # the sphere shape's lattice spheres still touch; the box's and the capsule's are their mass only
    assert (
        "contact spheres, 1 box and 1 capsule (they touch planes, walls and bodies as their exact shapes)"
        in (lines["on"])
    ), lines
    spheres = {name: int(line.split("contact: ")[1].split()[0].replace(",", "")) for name, line in lines.items()}
    assert 0 < spheres["on"] < spheres["off"], spheres
    assert "exact shape" not in lines["off"] and "1 plane" in lines["off"], lines


def test_verbose_says_a_scene_with_forces_runs_the_loop_of_every_mix_of_force_types():
    """forces/tables.py: every scene with a force term beyond gravity has the same kernel tables' type."""
    lines = verbose_lines(REPO / "scenes" / "forces" / "spring_chain.yaml")
    (kernels,) = [line for line in lines if line.startswith("  kernels: ")]
    assert "forces (gravity, spring, drag: the loop of every mix of force types)" in kernels, kernels


# a joint's degrees of freedom in joint coordinates (a free root: 6)
JOINT_FREEDOMS = {"ball": 3, "hinge": 1, "slider": 1, "fixed": 0}


@pytest.mark.parametrize("name", ["double_pendulum", "capsule_ragdoll"])
def test_verbose_tells_a_tree_scenes_links_and_degrees_of_freedom(name):
    """A scene that runs in joint coordinates (it names no integrator and its joints form trees): the
    links, the trees (one per root: a link jointed to the world, or a free body) and the degrees of
    freedom, against the scene file: each joint's own freedoms, 6 for a root that no joint holds to the
    world. The four-bar (a loop: maximal coordinates) has no such line."""
    path = REPO / "scenes" / "joints" / f"{name}.yaml"
    scene = yaml.safe_load(path.read_text())
    joints, bodies = scene["joints"], scene["bodies"]
    to_world = [j for j in joints if "world" in j["bodies"]]
    free_roots = 1 - len(to_world) if len(joints) == len(bodies) - 1 else 0  # a tree that hangs from nothing
    freedoms = sum(JOINT_FREEDOMS[j["type"]] for j in joints) + 6 * free_roots
    trees = len(to_world) + free_roots
    # a tree scene's default: with contact of a few shapes (the capsule ragdoll) reduced-implicit
    integrator = "reduced-implicit" if "contact" in scene else "reduced-rk4"
    expected = (f"  joint coordinates ({integrator}): {len(bodies)} links in {trees} tree{'s' * (trees != 1)}, "
                f"{freedoms} degrees of freedom")  # fmt: skip
    assert expected in verbose_lines(path), verbose_lines(path)
    assert not any("joint coordinates" in line for line in verbose_lines(REPO / "scenes" / "joints" / "four_bar.yaml"))


def test_validate_says_the_sub_steps_auto_chose_and_what_the_run_will_cost(tmp_path):
    """The capsule ragdoll (issue 47 item 3): the contact line counts the sub-steps `substeps: auto` chose
    (settings.substeps, from the stable step), and an estimate line adds the measured costs (scene/run_cost.py)
    of its joint rows, shapes, spheres and bodies over steps x sub-steps; nothing warns under a minute."""
    from rbcli.api import prepare
    from rbcli.physics.integrators import get_integrator
    from rbcli.scene.run_cost import COST_BODY, COST_ROW, COST_SHAPE, COST_SPHERE

    # on split2 (the scene names no integrator: it runs reduced-implicit), whose estimate counts joint rows
    text = (REPO / "scenes" / "joints" / "capsule_ragdoll.yaml").read_text()
    path = tmp_path / "capsule_ragdoll.yaml"
    path.write_text(
        text.replace(
            "simulation: {dt: 0.001, duration: 3.0,", "simulation: {dt: 0.001, duration: 3.0, integrator: split2,"
        )
    )
    compiled = prepare(path)
    settings, model = compiled.settings, compiled.model
    assert settings.substeps > 1
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[1].endswith(f"; {settings.substeps} sub-steps per step (auto)"), lines[1]
    sub_steps = settings.steps * settings.substeps  # split2: 1 force evaluation a step
    rows, shapes = int(model.joint.row_count.sum()), 7
    expected = sub_steps * (COST_ROW * rows + COST_SHAPE * shapes + COST_SPHERE * 1 + COST_BODY * 8)
    head = f"  estimated run: ~{expected:.2g} s of CPU once compiled ({settings.steps:,} steps x {settings.substeps}"
    assert lines[2].startswith(f"{head} sub-steps; joint rows {sub_steps * COST_ROW * rows:.2g} s"), lines[2]
    assert "warning" not in result.output
    # as shipped (reduced-implicit: one force evaluation a sub-step, the links in joint coordinates; its
    # implicit contact is not bounded by the stable step, so no warning at its 2 sub-steps)
    shipped = runner.invoke(app, ["validate", str(REPO / "scenes" / "joints" / "capsule_ragdoll.yaml")])
    assert shipped.exit_code == 0 and "warning" not in shipped.output, shipped.output
    tree = prepare(REPO / "scenes" / "joints" / "capsule_ragdoll.yaml")
    assert tree.settings.integrator == "reduced-implicit" and tree.settings.substeps < settings.substeps
    evaluations = tree.settings.steps * tree.settings.substeps * get_integrator("reduced-implicit").force_evals
    estimate = shipped.output.splitlines()[2]
    assert f"contact shapes {evaluations * COST_SHAPE * shapes:.2g} s" in estimate and "tree links" in estimate, (
        estimate
    )


def test_a_run_over_a_minute_is_warned_about_naming_what_drives_it(tmp_path):
    """The box stack (5 sub-steps a step) run for 2,000 s instead of 10: the estimate, 200 times the 10-s
    run's, is over a minute; the warning names it, the shapes that drive it and the sub-steps with the
    body and stiffness that set them, and what would change it. The 10-s run does not warn."""
    from rbcli.api import prepare
    from rbcli.scene.run_cost import LONG_RUN, run_cost

    path = REPO / "scenes" / "contact" / "box_stack.yaml"
    short = run_cost(prepare(path))
    assert short.seconds < LONG_RUN and not [w for w in prepare(path).warnings if "estimated" in w.message]
    text = path.read_text().replace("duration: 10.0", "duration: 2000.0")
    assert "duration: 2000.0" in text
    long = write(tmp_path, "long.yaml", text)
    cost = run_cost(prepare(long))
    assert cost.seconds == pytest.approx(200 * short.seconds, rel=1e-9) and cost.seconds > LONG_RUN
    result = runner.invoke(app, ["validate", str(long)])
    assert result.exit_code == 0, result.output
    (warning,) = [line for line in result.output.splitlines() if "warning:" in line]
    assert 60 < cost.seconds < 120  # said in seconds below two minutes
    assert f"the run is estimated at ~{cost.seconds:.0f} s of CPU once compiled" in warning, warning
    assert "mostly contact shapes (10:" in warning and "over 5 sub-steps a step" in warning, warning
    assert "body 'box9'" in warning and "a shorter duration or a larger dt" in warning, warning
    assert "integrator: reduced-implicit, whose stiffness sets none" in warning, warning  # the implicit option
