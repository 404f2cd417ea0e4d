"""Bad scenario input fails before any simulation, with one line naming file and field."""

from __future__ import annotations

import pytest
from conftest import fig3_with

from nsdrake.diagram import build_diagram
from nsdrake.scenario import ScenarioError, load_scenario, load_scenario_file, shipped_scenarios

BAD = [
    ("duration: [1, 2", "malformed YAML"),
    ("durration: 3", "durration: unknown field"),
    ("impedance: {K_q: 1}", "impedance.K_q: unknown field"),
    ("impedance: {K_f: -1}", "impedance.K_f: must be > 0"),
    ("null_space: {K_n: 0}", "null_space.K_n: must be > 0"),
    ("control_period: -0.002", "control_period: must be > 0"),
    ("duration: 0", "duration: must be > 0"),
    ("duration: -5", "duration: must be > 0"),
    ("duration: abc", "duration: must be a number"),
    ("reference: {force: .nan}", "reference.force: must be a finite number"),
    ("reference: {force: .inf}", "reference.force: must be a finite number"),
    ("arm: {initial_positions: {joint1: .nan}}", "arm.initial_positions.joint1: must be a finite number"),
    ("plane: diagonal", "plane: must be one of horizontal, vertical"),
    ("contact: {approximation: tamsi}", "contact.approximation: must be one of"),
    ("null_space: {pseudo_inverse: left}", "null_space.pseudo_inverse: must be one of"),
    ("null_space: {damping: 0.1}", "null_space.damping: damping is only used by damped_least_squares"),
    ("null_space: {pseudo_inverse: damped_least_squares}", "null_space.damping: the damped least-squares"),
    ("reference: {contact_threshold: 20}", "reference.contact_threshold: 20.0 N must be below"),
    ("task: {axes: [x, x]}", "task.axes: must be distinct"),
    ("plate: {position: [0, 1]}", "plate.position: must be [x, y, z]"),
    ("duration: 1\nduration: 2", "duplicate key 'duration'"),
    ("- 1", "the file: must be a mapping"),
    ("desired_null_space: {joint_speed_limits: {joint1: -1}}", "joint_speed_limits.joint1: must be > 0"),
    ("control_period: 10", "control_period: 10.0 s is longer than the duration 5.0 s"),
    # criteria and selector (issue 3)
    ("desired_null_space: {selector: {d_lim: -0.01}}", "desired_null_space.selector.d_lim: must be >= 0"),
    ("desired_null_space: {selector: {w_lim: -1}}", "desired_null_space.selector.w_lim: must be >= 0"),
    (
        "desired_null_space: {selector: {blend_time: -0.2}}",
        "desired_null_space.selector.blend_time: must be >= 0",
    ),
    (
        "desired_null_space: {criteria: {singularity: {gain: 1}}}",
        "desired_null_space.criteria.singularity: unknown field",
    ),
    ("desired_null_space: {criteria: {obstacle: {gain: -1}}}", "criteria.obstacle.gain: must be >= 0"),
    (
        "desired_null_space: {criteria: {joint_torque: {gain: 0.1}}}",
        "criteria.joint_torque.gain: must be <= 0",
    ),
    (
        "desired_null_space: {criteria: {obstacle: {influence_distance: 0.01}}}",
        "must be >= selector.d_lim + d_band",
    ),
    ("desired_null_space: {speed_headroom: 1.5}", "desired_null_space.speed_headroom: must be below 1"),
    ("obstacles: [{name: post, position: [0.3, 0.2, 0]}]", "obstacles[0]: obstacle 'post' has no geometry"),
    (
        "obstacles: [{name: post, shape: cone, size: [1]}]",
        "obstacles[0].shape: must be one of box, sphere, cylinder",
    ),
    ("obstacles: [{name: post, shape: box, size: [0.1]}]", "obstacles[0].size: a box needs 3 size entries"),
    ("obstacles: [{name: post, shape: sphere, size: [-0.1]}]", "obstacles[0].size[0]: must be > 0"),
    ("obstacles: [{shape: sphere, size: [0.1]}]", "obstacles[0].name: every obstacle needs a name"),
    (
        "obstacles: [{name: a, shape: sphere, size: [0.1]}, {name: a, shape: sphere, size: [0.1]}]",
        "obstacles[1].name: duplicate obstacle name 'a'",
    ),
    ("report: {checks: [fig4]}", "report.checks[0]: must be one of fig3, priority"),
]


@pytest.mark.parametrize(("text", "message"), BAD, ids=[b[0] for b in BAD])
def test_bad_field_is_named_on_one_line(tmp_path, text, message):
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, text)
    text_of_error = str(info.value)
    assert message in text_of_error
    assert "overrides.yaml" in text_of_error  # names the file
    assert "\n" not in text_of_error


BAD_AGAINST_MODEL = [
    (
        "arm: {initial_positions: {joint9: 0.1}}",
        "arm.initial_positions.joint9: unknown joint; the arm's joints are joint1",
    ),
    ("desired_null_space: {joint_speed_limits: {elbow: 1}}", "joint_speed_limits.elbow: unknown joint"),
    ("arm: {urdf: nowhere.urdf}", "arm.urdf: model file 'nowhere.urdf' not found"),
    ("arm: {tool_frame: hand}", "arm.tool_frame: no frame 'hand'"),
]


@pytest.mark.parametrize(("text", "message"), BAD_AGAINST_MODEL, ids=[b[0] for b in BAD_AGAINST_MODEL])
def test_fields_checked_against_the_model_fail_at_build_time(tmp_path, text, message):
    scenario = fig3_with(tmp_path, text)
    with pytest.raises(ScenarioError) as info:
        build_diagram(scenario)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_missing_initial_position_is_reported(tmp_path):
    path = tmp_path / "partial.yaml"
    path.write_text("arm: {initial_positions: {joint1: 0.1, joint2: 0.2}}\n")
    with pytest.raises(ScenarioError, match="no position for joint.s. joint3, joint4"):
        build_diagram(load_scenario_file(path))


def test_unknown_scenario_and_missing_file(tmp_path):
    with pytest.raises(ScenarioError, match="unknown scenario 'fig4'; the shipped scenarios are fig3"):
        load_scenario("fig4")
    with pytest.raises(ScenarioError, match="no such scenario file"):
        load_scenario("fig3", config=tmp_path / "absent.yaml")
    with pytest.raises(ScenarioError, match="--duration: must be > 0"):
        load_scenario("fig3", duration=-1.0)


def test_every_shipped_scenario_loads_and_builds():
    for name in shipped_scenarios():
        build_diagram(load_scenario(name))


def test_overrides_keep_the_other_fields(tmp_path):
    base = load_scenario("fig3")
    s = fig3_with(tmp_path, "impedance: {K_f: 2.5}\narm: {initial_velocities: {joint2: 0.1}}")
    assert s.impedance.K_f == 2.5
    assert s.impedance.K_p_tangent == base.impedance.K_p_tangent
    assert s.arm.initial_positions == base.arm.initial_positions  # maps merge, not replace
    assert s.arm.initial_velocities == {"joint2": 0.1}
