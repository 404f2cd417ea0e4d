"""Bad scenario input fails before any simulation, with one line naming file and field."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import fig3_with

from nsdrake.experiment.diagram import build_diagram
from nsdrake.experiment.scenario import (
    JOINT_TABLES,
    SCENARIO_DIR,
    VECTOR_TABLES,
    ScenarioError,
    load_scenario,
    load_scenario_file,
    shipped_scenarios,
    validate,
    value_at,
)
from nsdrake.reporting.run_folder import scenario_yaml
from nsdrake.station.models import models_dir

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


# --- overlays replace joint tables; a standalone file; every check's needs (issue 42) ---


def test_an_overlay_replaces_a_joint_table_it_gives(tmp_path):
    """Issue 42: a sweep direction {joint1: 1.0} over self_motion's {joint2: 1, joint3: -1,
    joint4: 1} became all four (the maps merged): a direction nobody wrote. Catches a merge
    of a direction, a replace that loses the fields beside it, and a replace of a per-joint
    table (a torque-rate limit given for one joint silently unlimiting the others)."""
    base = load_scenario("self_motion")
    assert base.desired_null_space.sweep.direction == {"joint2": 1.0, "joint3": -1.0, "joint4": 1.0}
    path = tmp_path / "one.yaml"
    path.write_text("desired_null_space: {sweep: {direction: {joint1: 1.0}, amplitude: 0.3}}\n")
    s = load_scenario("self_motion", config=path)
    assert s.desired_null_space.sweep.direction == {"joint1": 1.0}
    assert s.desired_null_space.sweep.amplitude == 0.3  # the section still merges field by field
    assert s.desired_null_space.sweep.frequency == base.desired_null_space.sweep.frequency
    assert s.arm.initial_positions == base.arm.initial_positions  # a table not given is kept
    assert s.notes == []
    # every other joint table changes the joint given and keeps the others (a torque limit
    # given for one joint must not silently unlimit the rest): one entry given, the rest kept
    for table in JOINT_TABLES:
        section, *middle, leaf = table.split(".")
        text = f"{section}: " + "".join(f"{{{p}: " for p in middle) + f"{{{leaf}: {{joint1: 0.25}}}}"
        path.write_text(text + "}" * len(middle) + "\n")
        s = load_scenario("self_motion", config=path, validated=False)
        expected = {"joint1": 0.25}
        if table not in VECTOR_TABLES:
            expected = (value_at(base, table) or {}) | expected
        assert value_at(s, table) == expected, table
    # a Panda's rate limit lowered on one joint keeps the six others' (not unlimited)
    path.write_text("actuator_limits: {torque_rate: {panda_joint6: 500.0}}\n")
    panda = load_scenario("panda_wipe", config=path).actuator_limits.torque_rate
    assert panda == load_scenario("panda_wipe").actuator_limits.torque_rate | {"panda_joint6": 500.0}
    assert len(panda) == 7


def test_an_overlay_that_chooses_another_arm_drops_the_bases_joint_tables_and_says_so(tmp_path):
    """Issue 42: a Panda overlay on self_motion (arm4) failed with 'sweep.direction.joint2:
    unknown joint' (the base's tables name arm4's joints); with the arm changed they are
    dropped, each named in one note; another file of the same joints (a model edited)
    keeps them. Catches tables kept (the model check then refuses them), tables dropped
    silently, and tables dropped for an edited copy of the same arm."""
    panda = load_scenario("panda_wipe")
    path = tmp_path / "panda.yaml"
    path.write_text(
        "arm: {urdf: panda.urdf, tool_frame: tool, initial_positions: "
        + str(panda.arm.initial_positions).replace("'", "")
        + "}\nplate: {position: [0.0, 0.6, 0.0]}\n"
    )
    s = load_scenario("self_motion", config=path, validated=False)
    assert s.arm.initial_positions == panda.arm.initial_positions
    assert s.desired_null_space.sweep.direction == {}
    (note,) = s.notes
    assert "chooses another arm (arm.urdf 'arm4.urdf' -> 'panda.urdf', positions for its 7 joints)" in note
    assert note.endswith("dropped: desired_null_space.sweep.direction") and str(path) in note
    # the same joints in another file (a model edited), with or without their positions:
    # nothing dropped, nothing said
    (tmp_path / "edited.urdf").write_text((models_dir() / "arm4.urdf").read_text())
    positions = "{joint1: 0.1, joint2: 0.2, joint3: 0.3, joint4: 0.4}"
    for text in ("arm: {urdf: edited.urdf}", f"arm: {{urdf: edited.urdf, initial_positions: {positions}}}"):
        path.write_text(text + "\n")
        kept = load_scenario("self_motion", config=path)
        assert kept.desired_null_space.sweep.direction == {"joint2": 1.0, "joint3": -1.0, "joint4": 1.0}
        assert kept.notes == [], text
        build_diagram(kept)


def test_a_standalone_scenario_file_is_a_scenario(tmp_path, monkeypatch):
    """nsdrake run FILE.yaml (issue 42): a path is read as a whole scenario (defaults for
    what it leaves out), its relative model paths from its own folder even under an
    overlay from another folder; a shipped name is the shipped scenario even beside a file
    of that name. Catches the file read as an overlay of a shipped scenario, and an
    overlay's folder taking over the base file's model paths."""
    models = tmp_path / "mine"
    models.mkdir()
    (models / "my_arm.urdf").write_text((models_dir() / "arm4.urdf").read_text())
    fig3 = load_scenario("fig3")
    mine = dataclasses.replace(fig3, arm=dataclasses.replace(fig3.arm, urdf="my_arm.urdf"))
    (models / "my.yaml").write_text(scenario_yaml(mine))
    s = load_scenario(str(models / "my.yaml"))
    assert s.source == str(models / "my.yaml") and s.arm.urdf == "my_arm.urdf"
    assert s.impedance == load_scenario("fig3").impedance
    elsewhere = tmp_path / "tweaks"
    elsewhere.mkdir()
    (elsewhere / "k.yaml").write_text("impedance: {K_f: 2.5}\n")
    s = load_scenario(models / "my.yaml", config=elsewhere / "k.yaml")
    assert s.impedance.K_f == 2.5 and Path(s.base_dir) == elsewhere.resolve()
    assert s.arm.urdf == str((models / "my_arm.urdf").resolve())
    build_diagram(s)  # the model is found
    monkeypatch.chdir(tmp_path)
    Path("fig3").write_text(scenario_yaml(dataclasses.replace(fig3, duration=1.0)))
    shipped = load_scenario("fig3")
    assert shipped.duration == load_scenario(SCENARIO_DIR / "fig3.yaml").duration != 1.0
    assert "the file 'fig3' in this folder is run as ./fig3" in shipped.notes[0]
    assert load_scenario("./fig3").duration == 1.0


@pytest.mark.parametrize(
    ("name", "message"),
    [
        ("fig4", "unknown scenario 'fig4'; the shipped scenarios are fig3, "),
        (
            "my_arm.yaml",
            "my_arm.yaml: no such scenario file (nor a shipped one: the shipped scenarios are fig3",
        ),
        ("sub/arm", "sub/arm: no such scenario file"),
        ("sub", "sub: a folder, not a scenario file"),
    ],
)
def test_a_scenario_that_is_neither_shipped_nor_a_file_says_what_was_tried(
    tmp_path, monkeypatch, name, message
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "sub").mkdir()
    with pytest.raises(ScenarioError) as info:
        load_scenario(name)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_sweep_axis_into_a_joint_table_sets_that_entry():
    """A sweep axis arm.initial_positions.joint2 sets one entry (the overlay gives the whole
    table: the base's with that entry); a whole-table axis replaces. Catches the sweep's
    table replaced by the one entry (no position for joint1, 3, 4)."""
    from nsdrake.studies.sweep_spec import Axis, SweepSpec, plan_runs

    base = load_scenario("self_motion")
    spec = SweepSpec(
        name="t",
        source="t.yaml",
        description="",
        base="self_motion",
        config=None,
        duration=None,
        seed=0,
        axes=(
            Axis("arm.initial_positions.joint2", (0.5,), None),
            Axis("desired_null_space.sweep.direction", ({"joint1": 1.0},), None),
        ),
        metrics=("force_error_rms",),
        text="",
    )
    (run,) = plan_runs(spec, check_models=False)
    assert run.scenario.arm.initial_positions == base.arm.initial_positions | {"joint2": 0.5}
    assert run.scenario.desired_null_space.sweep.direction == {"joint1": 1.0}


NEEDS = [
    ("report: {checks: [self_motion]}", "report.checks[0]: self_motion measures the elbow's swivel"),
    ("report: {checks: [fig3], required_modes: [1]}", "report.required_modes: only the priority check"),
    (
        "report: {checks: [priority], required_modes: [3, 4]}",
        "report.required_modes[1]: mode 4 (joint-limit avoidance) never comes with",
    ),
]


@pytest.mark.parametrize(("text", "message"), NEEDS, ids=[n[1].split(":")[0] for n in NEEDS])
def test_a_checks_needs_are_refused_before_the_run(tmp_path, text, message):
    """Issue 42: report.checks [self_motion] without swivel_frames simulated the whole run,
    then ended in KeyError: "no trace column 'swivel'"; required_modes without the
    priority check were ignored. Catches each need unchecked."""
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, text)
    assert message in str(info.value) and "overrides.yaml" in str(info.value) and "\n" not in str(info.value)


def _in_contact(traces, f_d: float, rows: int = 600, period: float = 0.002):
    """Traces with the columns of ``traces``, ``rows`` periods long, pressing f_d from the
    first row on (so that every check reaches its measuring window)."""
    from nsdrake.experiment.traces import Traces

    columns = {name: np.zeros(rows) for name in traces.names}
    columns["t"] = np.arange(rows) * period
    columns["f_n"] = columns["f_d"] = np.full(rows, f_d)
    return Traces(columns)


# what each case refuses of report.checks (the others compute): (scenario, swivel frames, refused)
NO_LIMITS = {"pose": "has no joint position limits"}
NO_SWIVEL = {"self_motion": "give report.swivel_frames"}
CASES = {
    "fig3": ("fig3", None, NO_LIMITS | NO_SWIVEL),
    "fig3 with swivel frames": ("fig3", ["link1", "link2", "link4"], NO_LIMITS),
    "priority_demo": ("priority_demo", None, NO_LIMITS | NO_SWIVEL),
    "panda_wipe": ("panda_wipe", None, {}),
}


def _each_check(case: str, tmp_path, plots: bool) -> None:
    """Each report.check of ``case``: refused in one line by the checks before the run
    (validate, the station's), or its figures (and with ``plots`` its plots) computed from
    traces with exactly the columns that case's run writes, in contact long enough for
    every check's measuring window."""
    from pydrake.systems.framework import DiagramBuilder

    from nsdrake.experiment.scenario import REPORT_CHECKS
    from nsdrake.experiment.scenario_station import add_scenario_station
    from nsdrake.experiment.simulate import run
    from nsdrake.reporting.run_folder import compute_metrics, write_plots

    name, swivel, refused = CASES[case]
    base = load_scenario(name, duration=0.004)
    if swivel is not None:
        base = dataclasses.replace(base, report=dataclasses.replace(base.report, swivel_frames=swivel))
    traces, built = run(base)  # the columns do not depend on report.checks
    fake = _in_contact(traces, base.reference.force)
    for check in REPORT_CHECKS:
        report = dataclasses.replace(base.report, checks=[check], required_modes=[])
        s = dataclasses.replace(base, report=report)
        if check in refused:
            with pytest.raises(ScenarioError) as info:
                validate(s)
                add_scenario_station(DiagramBuilder(), s, sensing=False)
            assert f"report.checks[0]: {check}" in str(info.value), check
            assert refused[check] in str(info.value) and "\n" not in str(info.value)
            continue
        validate(s)
        add_scenario_station(DiagramBuilder(), s, sensing=False)
        metrics = compute_metrics(s, built.station, fake, None)
        assert {m.name for m in metrics} > {"joint_speed_ratio_max"}, check  # the check's own figures
        if plots:
            assert write_plots(s, built, fake, None, tmp_path), check


@pytest.mark.parametrize("case", sorted(CASES))
def test_every_check_is_refused_before_the_run_or_computes_from_the_columns_the_run_writes(tmp_path, case):
    """Issue 42: each report.check on a planar arm without limits (fig3, with and without
    swivel frames), with an obstacle (priority_demo) and on the Panda's pose task
    (panda_wipe). Catches a need left unchecked (the pose check's joint margins on arm4:
    KeyError q_margin1; self_motion's swivel) and fig3's figures reading the rotational
    axes of a pose task (KeyError 'rx')."""
    _each_check(case, tmp_path, plots=False)


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(CASES))
def test_every_check_that_is_accepted_also_plots(tmp_path, case):
    """The slow twin (matplotlib's figures take seconds): the plots too. Catches a plot
    reading a column the case does not write (pose.png's joint-margin panels on arm4 with
    the self_motion check)."""
    _each_check(case, tmp_path, plots=True)


def test_a_model_named_by_its_package_is_found_in_arm_packages_or_where_pip_installed_it(
    tmp_path, monkeypatch
):
    """arm.urdf: package://NAME/path (issue 42: a scenario file naming a vendor's arm the
    same on every machine): NAME's folder from arm.packages, else the package pip installed
    through cmeel (site-packages/cmeel.prefix/share/NAME, where example-robot-data puts its
    robots). Catches the URI read as a relative path, and the installed package not looked
    for; an unknown package is one line."""
    import sysconfig

    share = tmp_path / "site" / "cmeel.prefix" / "share" / "my-robots"
    (share / "urdf").mkdir(parents=True)
    (share / "meshes").mkdir()
    (share / "meshes" / "mark.obj").write_text(
        "v 0 0 0\nv 0.01 0 0\nv 0 0.01 0\nv 0 0 0.01\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
    )
    mesh = '<visual><geometry><mesh filename="package://my-robots/meshes/mark.obj"/></geometry></visual>'
    arm = (
        (models_dir() / "arm4.urdf").read_text().replace('<link name="link1">', f'<link name="link1">{mesh}')
    )
    (share / "urdf" / "arm.urdf").write_text(arm)  # its mesh named by the package too
    uri = "package://my-robots/urdf/arm.urdf"
    with pytest.raises(
        ScenarioError, match="arm.urdf: model file 'package://my-robots/urdf/arm.urdf': no package"
    ):
        build_diagram(fig3_with(tmp_path, f"arm: {{urdf: '{uri}'}}"))
    # given in arm.packages, relative to the overlay's folder
    build_diagram(
        fig3_with(
            tmp_path, f"arm: {{urdf: '{uri}', packages: {{my-robots: site/cmeel.prefix/share/my-robots}}}}"
        )
    )
    paths = sysconfig.get_paths()
    monkeypatch.setattr(sysconfig, "get_paths", lambda: paths | {"purelib": str(tmp_path / "site")})
    built = build_diagram(fig3_with(tmp_path, f"arm: {{urdf: '{uri}'}}"))  # where pip would have put it
    assert built.station.arm_file == (share / "urdf" / "arm.urdf").resolve()
