"""Bad scenario input fails before any simulation, with one line naming file and field."""

from __future__ import annotations

import time

import pytest
from conftest import fig3_with

from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.scenario import ScenarioError, load_scenario, load_scenario_file, shipped_scenarios

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


# --- the strict YAML reader (issue 9): limits, keys, YAML 1.2 floats, short echoes -----


def _laughs(levels: int) -> str:
    """A "billion laughs" value for task.axes: each level lists the previous one 10 times
    (levels=7: 10⁷ strings from a few hundred bytes), all inside one field."""
    anchors = "&l0 [x, x, x, x, x, x, x, x, x, x]"
    for k in range(1, levels):
        anchors = f"&l{k} [{anchors}, " + ", ".join([f"*l{k - 1}"] * 9) + "]"
    return f"task:\n  axes: [{anchors}]\n"


def test_alias_expansion_is_bounded_and_fails_fast(tmp_path):
    """Catches a reader that expands aliases without a bound: the shape check and the
    error's echo of the value walk all 10⁷ strings (seconds and hundreds of MB here, minutes
    and GBs at 10⁹) before any error."""
    start = time.perf_counter()
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, _laughs(7))
    elapsed = time.perf_counter() - start
    message = str(info.value)
    assert "overrides.yaml: line 2: more than 10000 values once aliases are expanded" in message
    assert "\n" not in message and len(message) < 200
    assert elapsed < 0.5, f"{elapsed:.2f} s"


def test_small_aliases_are_read(tmp_path):
    """Catches a bound so tight (or a refusal of aliases) that reusing a value is refused."""
    s = fig3_with(
        tmp_path,
        "plate: {position: &p [0.0, 0.6, 0.0]}\n"
        "obstacles: [{name: post, shape: sphere, size: [0.05], position: *p}]",
    )
    assert s.obstacles[0].position == [0.0, 0.6, 0.0]


def test_recursive_alias_is_refused(tmp_path):
    """Catches a recursive value (an alias inside the list it names) reaching the shape
    check, where it recursed until RecursionError."""
    with pytest.raises(
        ScenarioError, match=r"overrides.yaml: line 1: alias \*a is inside the value it names"
    ):
        fig3_with(tmp_path, "task: {axes: &a [*a]}")


def test_deep_nesting_is_refused_on_one_line(tmp_path):
    """Catches unbounded nesting: 1000 nested lists raised RecursionError in PyYAML's composer."""
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, "duration: " + "[" * 1000 + "]" * 1000)
    assert str(info.value).endswith("overrides.yaml: line 1: nested deeper than 32 levels")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("arm: {initial_positions: {[joint1]: 0.1}}", "line 1: a key must be a name, got a list"),
        ("impedance:\n  ? {K_f: 1}\n  : 2", "line 2: a key must be a name, got a mapping"),
        ("impedance: {1: 2}", "line 1: a key must be a name, got 1; quote it if it is one"),
        ("arm: {initial_velocities: {on: 0.1}}", "line 1: a key must be a name, got True"),
    ],
)
def test_keys_that_are_not_names_are_refused(tmp_path, text, message):
    """Catches a list or mapping key escaping as TypeError (unhashable) and a number or
    true/false key passing for a name ("impedance.1: unknown field", or a joint called True)."""
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, text)
    assert f"overrides.yaml: {message}" in str(info.value) and "\n" not in str(info.value)


def test_yaml_1_2_floats_are_numbers(tmp_path):
    """Catches PyYAML's YAML 1.1 reading: 1e3 and -2E-3 were strings ("must be a number")."""
    s = fig3_with(tmp_path, "duration: 1e3\ncontrol_period: 1.0e-3\nreference: {tangent_speed: -2E-3}")
    assert s.duration == 1000.0 and isinstance(s.duration, float)
    assert s.control_period == 0.001
    assert s.reference.tangent_speed == -0.002


def test_merge_keys_are_refused_by_name(tmp_path):
    """Catches a merge key reported as "malformed YAML" (it is valid YAML 1.1 that nsdrake
    does not take), or silently taken."""
    with pytest.raises(ScenarioError) as info:
        fig3_with(
            tmp_path,
            "obstacles:\n  - &o {name: a, shape: sphere, size: [0.1]}\n  - {<<: *o, name: b}",
        )
    message = str(info.value)
    assert "overrides.yaml: line 3: merge keys (<<) are not supported" in message
    assert "malformed" not in message


@pytest.mark.parametrize(
    ("text", "start"),
    [
        ("duration: '" + "9" * 5000 + "'", "duration: must be a number, got '999"),
        ("x" * 1000 + ": 1", "xxx"),  # YAML keys end at 1024 characters
        ("plane: " + "y" * 5000, "plane: must be one of horizontal, vertical, got 'yyy"),
        ("duration: [" + ", ".join(["1"] * 3000) + "]", "duration: must be a number, got [1, 1"),
    ],
    ids=["long string", "long key", "long choice", "long list"],
)
def test_long_values_are_cut_in_messages(tmp_path, text, start):
    """Catches an error message that echoes a user's value in full (here 1000 to 5000 characters).
    The bound, half the shortest value, leaves room for the message's fixed part (the file's
    path, and for an unknown key the list of the valid fields, which grows with the scenario)."""
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, text)
    message = str(info.value)
    assert start in message and "…" in message
    # The file's path (pytest's temporary folder, longer under xdist) is not the user's value.
    assert len(message.removeprefix(str(tmp_path))) < 400, len(message)


def test_oversized_file_is_refused(tmp_path):
    """Catches a reader that reads a file of any size (a scenario is a few kB)."""
    text = "description: '" + "z" * 1_200_000 + "'\n"
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, text)
    assert str(info.value).endswith(
        f"overrides.yaml: {len(text)} bytes; nsdrake refuses scenario files over 1000000 bytes"
    )
