"""A compound part whose density (or mass) rounds its particle masses to exactly 0 in float64, or makes
them overflow, is refused with an error at that part (it used to load with massless particles)."""

from __future__ import annotations

import textwrap

import pytest

from rbcli.scene.load import analyse_scene_text


def _scene(body: str) -> str:
    return "simulation: {dt: 0.001, duration: 0.01}\nbodies:\n" + textwrap.indent(textwrap.dedent(body), "  ")


HAMMER = """\
- name: hammer
  spacing: 0.01
  {body_key}
  compound:
    - shape: {{type: cylinder, radius: 0.015, height: 0.30, axis: z}}
      density: 700
    - shape: {{type: box, size: [0.12, 0.04, 0.04]}}
      offset: [0.02, 0, 0.32]
      {part_key}
"""


def _errors(text: str):
    spec, issues = analyse_scene_text(text, "s.yaml")
    errors = [i for i in issues if i.severity == "error"]
    assert spec is None and errors, [str(i) for i in issues]
    return errors


@pytest.mark.parametrize(
    ("part_key", "line", "column", "fragment"),
    [
        ("density: 1.0e-323", 11, 9, "density 9.88131e-324 kg/m^3"),  # x 1e-6 m^3 -> exactly 0.0
        ("density: 1.0e+308", None, None, "overflow"),  # spacing 0.01: x 1e-6 stays finite, so it loads
        ("mass: 1.0e-323", 11, 9, "mass 9.88131e-324 kg over"),  # / 192 particles -> 0.0
    ],
)
def test_a_part_whose_particle_masses_round_to_zero_is_refused_at_that_part(part_key, line, column, fragment):
    text = _scene(HAMMER.format(body_key="", part_key=part_key))
    spec, issues = analyse_scene_text(text, "s.yaml")
    if line is None:  # a control: large but finite masses load
        assert spec is not None, [str(i) for i in issues]
        return
    (error,) = _errors(text)
    assert str(error).startswith(f"s.yaml:{line}:{column}: error: bodies[0].compound[1].")
    assert fragment in error.message and "round to 0" in error.message


def test_the_bodys_density_rounding_to_zero_is_located_at_each_part_it_applies_to():
    body = """\
    - name: rod
      spacing: 0.01
      density: 1.0e-323
      compound:
        - shape: {type: box, size: [0.1, 0.02, 0.02]}
        - shape: {type: box, size: [0.02, 0.1, 0.02]}
          density: 500
    """
    errors = _errors(_scene(body))
    assert len(errors) == 1  # the second part has its own density
    assert str(errors[0]).startswith("s.yaml:7:9: error: bodies[0].compound[0]:")
    assert "the body's density" in errors[0].message and "round to 0" in errors[0].message


def test_a_body_mass_spread_to_nothing_is_refused_at_the_body_mass():
    body = """\
    - name: rod
      spacing: 0.01
      mass: 1.0e-323
      compound:
        - shape: {type: box, size: [0.1, 0.02, 0.02]}
        - shape: {type: box, size: [0.02, 0.1, 0.02]}
          density: 500
    """
    (error,) = _errors(_scene(body))
    assert str(error).startswith("s.yaml:5:5: error: bodies[0].mass:") and "round to 0" in error.message


def test_a_part_density_that_overflows_is_refused_at_that_part():
    text = _scene(HAMMER.format(body_key="", part_key="density: 1.0e+308").replace("spacing: 0.01", "spacing: 10.0"))
    text = text.replace("radius: 0.015, height: 0.30", "radius: 15, height: 300").replace(
        "size: [0.12, 0.04, 0.04]", "size: [120, 40, 40]"
    )
    (error,) = _errors(text)
    assert str(error).startswith("s.yaml:11:9: error: bodies[0].compound[1].density:") and "overflow" in error.message
