"""The Python API refuses what the command line refuses (issue 15, items 2 and 3), with
the same one-line messages naming the argument and field, before any native code (Drake,
Pinocchio, numba) sees the input: nsdrake/control/validation.py is the one home of the
rules, and the scenario reader reads the controller's sections through it."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import fig3_with
from models import serial_arm_urdf
from pydrake.geometry import Box, Sphere
from pydrake.math import RigidTransform

from nsdrake import ControllerConfig, ControllerConfigError, ControllerModel, NullSpaceImpedanceController
from nsdrake.control.config import ImpedanceConfig
from nsdrake.control.model import ModelMismatchError, Obstacle, PinocchioDynamics, check_agreement
from nsdrake.control.validation import config_problems
from nsdrake.experiment.scenario import ScenarioError
from nsdrake.station.models import models_dir

PLANAR3 = serial_arm_urdf(["z"] * 3, [0.3, 0.25, 0.2], [1.0, 0.7, 0.4])


def refusal(make) -> str:
    """The one-line message of the ControllerConfigError ``make()`` raises."""
    with pytest.raises(ControllerConfigError) as info:
        make()
    message = str(info.value)
    assert "\n" not in message
    return message


def section(name: str, **fields):
    """A ControllerConfig section with ``fields`` changed from its defaults."""
    return dataclasses.replace(getattr(ControllerConfig(), name), **fields)


def desired(**fields):
    """desired_null_space with fields changed; "criteria.x.gain"-style keys reach inside."""
    d = ControllerConfig().desired_null_space
    for path, value in fields.items():
        *parents, leaf = path.split("__")
        node = d
        for p in parents:
            node = getattr(node, p)
        setattr(node, leaf, value)
    return d


# (ControllerConfig keyword arguments, the field the error names, the problem it states)
CONFIG_CASES = [
    ({"period": 0}, "period", "must be > 0, got 0"),
    ({"period": -0.002}, "period", "must be > 0, got -0.002"),
    ({"nominal_force": math.nan}, "nominal_force", "must be a finite number, got nan"),
    ({"impedance": section("impedance", K_p_tangent=-1.0)}, "impedance.K_p_tangent", "must be > 0, got -1.0"),
    ({"impedance": section("impedance", K_f="1.0")}, "impedance.K_f", "must be a finite number, got '1.0'"),
    ({"impedance": section("impedance", K_v_normal=math.inf)}, "impedance.K_v_normal", "must be a finite"),
    ({"impedance": section("impedance", K_p_normal=-5.0)}, "impedance.K_p_normal", "must be >= 0, got -5.0"),
    ({"impedance": section("impedance", max_task_inertia=0.0)}, "impedance.max_task_inertia", "must be > 0"),
    (
        {"impedance": section("impedance", gravity_compensation="no")},
        "impedance.gravity_compensation",
        "must be true or false, got 'no'",
    ),
    ({"null_space": section("null_space", K_n=0.0)}, "null_space.K_n", "must be > 0, got 0.0"),
    (
        {"null_space": section("null_space", pseudo_inverse="left")},
        "null_space.pseudo_inverse",
        "must be one of dynamically_consistent, moore_penrose, damped_least_squares, got 'left'",
    ),
    (
        {"null_space": section("null_space", damping=0.1)},
        "null_space.damping",
        "damping is only used by damped_least_squares",
    ),
    (
        {"null_space": section("null_space", coriolis_compensation=1)},
        "null_space.coriolis_compensation",
        "must be true or false, got 1",
    ),
    (
        {"desired_null_space": desired(criteria__joint_torque__gain=0.1)},
        "desired_null_space.criteria.joint_torque.gain",
        "must be <= 0 (a negative gain minimises the torque), got 0.1",
    ),
    (
        {"desired_null_space": desired(selector__d_lim=-0.01)},
        "desired_null_space.selector.d_lim",
        "must be >= 0, got -0.01",
    ),
    (
        {"desired_null_space": desired(speed_headroom=1.0)},
        "desired_null_space.speed_headroom",
        "must be below 1, got 1.0",
    ),
    (
        {"desired_null_space": desired(joint_speed_limits={"joint1": -1.0})},
        "desired_null_space.joint_speed_limits.joint1",
        "must be > 0, got -1.0",
    ),
    (
        {"desired_null_space": desired(joint_speed_limits=[1.0, 2.0])},
        "desired_null_space.joint_speed_limits",
        "must be a mapping of joint name to number, got [1.0, 2.0]",
    ),
    (
        {"desired_null_space": desired(source="sweep")},
        "desired_null_space.sweep.direction",
        "a sweep needs a non-zero direction",
    ),
    (
        {"desired_null_space": desired(criteria__obstacle__influence_distance=0.01)},
        "desired_null_space.criteria.obstacle.influence_distance",
        "0.01 m must be >= selector.d_lim + d_band = 0.06 m",
    ),
    (
        {"actuator_limits": section("actuator_limits", torque={"joint2": 0.0})},
        "actuator_limits.torque.joint2",
        "must be > 0, got 0.0",
    ),
    ({"impedance": {"K_p_tangent": 400.0}}, "impedance", "must have the fields K_p_tangent"),
]


@pytest.mark.parametrize(("fields", "where", "problem"), CONFIG_CASES, ids=[c[1] for c in CONFIG_CASES])
def test_controller_config_refuses_each_bad_field_naming_it(fields, where, problem):
    """Catches a configuration the scenario reader would refuse passing the Python API
    (a negative gain, a gain given as text, a NaN, a switch that is a string and so always
    true) into a controller that then computes nonsense or fails deep in numpy."""
    message = refusal(lambda: ControllerConfig(**fields))
    assert message.startswith(f"ControllerConfig.{where}: ") and problem in message, message


def test_a_field_changed_after_the_config_was_made_is_refused_by_the_controller(planar3_model):
    """ControllerConfig checks itself when made; the controller checks again (a user sets
    fields afterwards, as diagrams/own_arm.py does), naming its argument ``config``."""
    config = ControllerConfig()
    config.impedance.K_f = -2.0
    message = refusal(lambda: controller(planar3_model, config=config))
    assert message == "config.impedance.K_f: must be > 0, got -2.0"
    config = ControllerConfig()
    config.null_space.K_n = 1000.0  # K_n T = 2 at 2 ms: the scenario checks refuse it too
    message = refusal(lambda: controller(planar3_model, config=config))
    assert message.startswith("config.null_space.K_n: K_n T = 2 ≥ 2")


# (scenario overlay, the field a scenario names, ControllerConfig keyword arguments, the field it names)
AGREEMENT_CASES = [
    ("control_period: 0.0\n", "control_period", {"period": 0.0}, "period"),
    ("reference: {force: -3.0}\n", "reference.force", {"nominal_force": -3.0}, "nominal_force"),
    (
        "impedance: {K_f: -1.0}\n",
        "impedance.K_f",
        {"impedance": section("impedance", K_f=-1.0)},
        "impedance.K_f",
    ),
    (
        "null_space: {pseudo_inverse: damped_least_squares}\n",
        "null_space.damping",
        {"null_space": section("null_space", pseudo_inverse="damped_least_squares")},
        "null_space.damping",
    ),
    (
        "desired_null_space: {criteria: {obstacle: {gain: -1.0}}}\n",
        "desired_null_space.criteria.obstacle.gain",
        {"desired_null_space": desired(criteria__obstacle__gain=-1.0)},
        "desired_null_space.criteria.obstacle.gain",
    ),
    (
        "desired_null_space: {selector: {q_lim: 0.2, q_band: 0.2}}\n",
        "desired_null_space.criteria.joint_limits.influence",
        {"desired_null_space": desired(selector__q_lim=0.2, selector__q_band=0.2)},
        "desired_null_space.criteria.joint_limits.influence",
    ),
]


@pytest.mark.parametrize(
    ("overlay", "scenario_field", "fields", "api_field"), AGREEMENT_CASES, ids=[c[1] for c in AGREEMENT_CASES]
)
def test_the_scenario_reader_and_the_python_api_state_the_same_problem(
    tmp_path, overlay, scenario_field, fields, api_field
):
    """Catches the two paths drifting apart: a rule changed in one place only, or a field
    the scenario checks and the API does not (the scenario reads the controller's
    sections through nsdrake.control.validation, so only the field names differ)."""
    api = refusal(lambda: ControllerConfig(**fields))
    problem = api.split(": ", 1)[1]
    assert api == f"ControllerConfig.{api_field}: {problem}"
    with pytest.raises(ScenarioError) as info:
        fig3_with(tmp_path, overlay)
    assert str(info.value).endswith(f": {scenario_field}: {problem}"), str(info.value)


# Fields of desired_null_space inside one criterion's hysteresis band: beyond its level-2
# threshold (d_lim 0.05 m by default, q_lim here), short of threshold + band.
IN_BAND = [
    (
        {"criteria__obstacle__influence_distance": 0.055},
        "obstacle.influence_distance",
        "d_lim + d_band = 0.06 m",
    ),
    (
        {"selector__q_lim": 0.1, "selector__q_band": 0.2, "criteria__joint_limits__influence": 0.25},
        "joint_limits.influence",
        "q_lim + q_band = 0.3 rad",
    ),
]


@pytest.mark.parametrize(("fields", "where", "rule"), IN_BAND, ids=["obstacle", "joint limits"])
def test_an_influence_inside_the_hysteresis_band_is_refused(fields, where, rule):
    """A criterion that took level 2 keeps it until its distance passes threshold + band; an
    influence distance short of that leaves it on level 2 with no gradient in between.
    Catches the check comparing the influence with the threshold alone, forgetting the band
    (issue 28, mistake 3: the existing case, 0.01 m, is below d_lim too)."""
    message = refusal(lambda: ControllerConfig(desired_null_space=desired(**fields)))
    assert message.startswith(f"ControllerConfig.desired_null_space.criteria.{where}: ") and rule in message


@pytest.mark.parametrize(
    "fields",
    [
        {"criteria__obstacle__influence_distance": 0.06},  # d_lim 0.05 + d_band 0.01
        {"selector__q_lim": 0.1, "selector__q_band": 0.2, "criteria__joint_limits__influence": 0.3},
    ],
    ids=["obstacle", "joint limits"],
)
def test_an_influence_at_the_end_of_the_band_is_accepted(fields):
    """The rule's boundary: an influence equal to threshold + band, written as the user
    writes decimals. Catches the sum compared in binary (0.05 + 0.01 = 0.060000000000000005
    > 0.06), which refused it with "0.06 m must be >= … = 0.06 m"."""
    assert not any(
        "influence" in where
        for where, _ in config_problems(ControllerConfig(desired_null_space=desired(**fields)))
    )


# --- the controller's own arguments --------------------------------------------------------


@pytest.fixture(scope="module")
def planar3_model():
    return ControllerModel.from_urdf(PLANAR3, tool_frame="tool", task_axes=("x", "y"))


def controller(model, **kwargs):
    arguments = {"controller_model": model, "normal": [0.0, 1.0], "config": ControllerConfig()} | kwargs
    return NullSpaceImpedanceController(**arguments)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        (
            {"normal": [0.0, 0.0]},
            "normal: must be a non-zero direction on the task axes ['x', 'y'] (or None: no force axis), "
            "got [0.0, 0.0]",
        ),
        ({"normal": [0.0, math.nan]}, "normal: must be finite, got [0.0, nan]"),
        ({"normal": [0.0, 1.0, 0.0]}, "normal: must be 2 numbers, a direction on the task axes ['x', 'y']"),
        ({"normal": ["up", "down"]}, "normal: must be 2 numbers"),
        ({"wrench_point": [0.0, 0.6]}, "wrench_point: must be [x, y, z] or None, got [0.0, 0.6]"),
        ({"wrench_point": [0.0, math.inf, 0.0]}, "wrench_point: must be finite, got [0.0, inf, 0.0]"),
        ({"controller_model": 42}, "controller_model: must be a ControllerModel, a URDF path or text"),
        ({"config": {"period": 0.002}}, "config: must have the fields period"),
    ],
    ids=[
        "zero normal",
        "NaN normal",
        "normal of 3",
        "text normal",
        "short point",
        "inf point",
        "int",
        "dict",
    ],
)
def test_bad_controller_arguments_are_one_line_naming_the_argument(planar3_model, kwargs, message):
    assert refusal(lambda: controller(planar3_model, **kwargs)).startswith(message)


def test_a_normal_of_any_length_is_its_direction(planar3_model):
    """The documented choice: ``normal`` is normalised (a direction; the force is f_d).
    Catches a normal used as given, which scales the force gain and the measured
    normal force by its length: τ at the same inputs must not change with it."""
    rng = np.random.default_rng(3)
    q, v = rng.uniform(-1.0, 1.0, 3), rng.uniform(-0.5, 0.5, 3)
    wrench = rng.standard_normal(6)
    torques = []
    for normal in ([0.0, 1.0], [0.0, 5.0]):
        c = controller(planar3_model, normal=normal)
        assert np.allclose(c.normal, [0.0, 1.0])
        context = c.CreateDefaultContext()
        inputs = {
            "estimated_state": np.concatenate([q, v]),
            "measured_wrench": wrench,
            "desired_position": [0.3, 0.4],
            "desired_velocity": [0.01, 0.0],
            "desired_acceleration": [0.0, 0.0],
            "desired_force": [4.0],
        }
        for name, value in inputs.items():
            c.GetInputPort(name).FixValue(context, value)
        torques.append(c.GetOutputPort("generalized_force").Eval(context))
    assert np.allclose(torques[0], torques[1], rtol=1e-12, atol=1e-12)


# --- the model ----------------------------------------------------------------------------


def arm4_text() -> str:
    return (models_dir() / "arm4.urdf").read_text()


def loop_urdf() -> str:
    """arm4 with a second joint from the base to link3: a kinematic loop."""
    loop = '<joint name="loop_joint" type="continuous"><parent link="base"/><child link="link3"/></joint>'
    return arm4_text().replace("</robot>", loop + "</robot>")


def no_limit_urdf() -> str:
    """A 3-joint planar arm whose revolute joints have no <limit> (Drake reads it, Pinocchio does not)."""
    return PLANAR3.replace('type="continuous"', 'type="revolute"')


@pytest.mark.parametrize(
    ("urdf", "kwargs", "message"),
    [
        ('<robot name="r"><link name="a">', {}, "controller_model: the URDF is not XML: no element found"),
        ("robot:\n  name: r\n", {}, "controller_model: the URDF is not XML: syntax error"),
        (
            '{"robot": {"name": "r"}}',
            {},
            'controller_model: \'{"robot": {"name": "r"}}\' is neither a readable',
        ),
        (
            Path("/nonexistent/arm.urdf"),
            {},
            "controller_model: '/nonexistent/arm.urdf' is neither a readable URDF",
        ),
        (
            '<sdf version="1.7"><model name="m"/></sdf>',
            {},
            "controller_model: not a URDF: the root element is <sdf>, not <robot>",
        ),
        (
            serial_arm_urdf(["z"] * 3, [0.3] * 3, [1.0, 0.0, 1.0]),
            {},
            "controller_model: link 'link2': mass 0 kg must be > 0",
        ),
        (loop_urdf(), {}, "controller_model: link 'link3': child of two joints ('joint3' and 'loop_joint')"),
        (
            serial_arm_urdf(["z"], [0.3], [1.0]),
            {},
            "task_axes: ['x', 'y'] on an arm of 1 joint leave no redundancy for a null space",
        ),
        (PLANAR3, {"tool_frame": "flange"}, "tool_frame: the controller model has no frame named 'flange'"),
        (PLANAR3, {"task_axes": ("x", "q")}, "task_axes[1]: must be one of x, y, z, rx, ry, rz, got 'q'"),
        (PLANAR3, {"task_axes": ("x", "x")}, "task_axes: must be distinct axes, got ['x', 'x']"),
        (PLANAR3, {"gravity": [0.0, 0.0, math.nan]}, "gravity: must be finite, got [0.0, 0.0, nan]"),
        (PLANAR3, {"gravity": [0.0, -1e5, 0.0]}, "gravity: 1e+05 m/s² is beyond the 1000 m/s² (100 g)"),
        (
            PLANAR3,
            {"obstacles": [Obstacle("big", Sphere(1e200), RigidTransform())]},
            "obstacles[0]: its size 1e+200 m is beyond the 100 m nsdrake models",
        ),
        (
            PLANAR3,
            {"obstacles": [Obstacle("far", Box(0.1, 0.1, 0.1), RigidTransform([1e6, 0.0, 0.0]))]},
            "obstacles[0]: its position 1e+06 m is beyond the 100 m",
        ),
    ],
    ids=[
        "unclosed XML",
        "YAML text",
        "JSON text",
        "missing file",
        "SDF",
        "zero mass",
        "kinematic loop",
        "one joint",
        "no such frame",
        "no such axis",
        "repeated axis",
        "NaN gravity",
        "gravity of 10000 g",
        "obstacle of 1e200 m",
        "obstacle 1000 km away",
    ],
)
def test_bad_models_are_refused_in_one_line_naming_the_argument(urdf, kwargs, message):
    """Catches URDF text read as a file name, a zero mass blamed on the two libraries
    disagreeing, a one-joint arm ending in a numba typing error, a loop or a bad frame as
    a Drake traceback, and absurd sizes that overflow the obstacle criterion later."""
    arguments = {"tool_frame": "tool", "task_axes": ("x", "y")} | kwargs
    got = refusal(lambda: ControllerModel.from_urdf(urdf, **arguments))
    assert got.startswith(message), got


def test_pinocchio_models_what_only_drake_reads():
    """ "auto" dynamics: a URDF Pinocchio's own parser cannot read (revolute joints without
    <limit>, which Drake accepts) still gets Pinocchio's terms: its model is built from the
    plant Drake parsed (nsdrake/control/pinocchio_tree.py), not from the text."""
    model = ControllerModel.from_urdf(no_limit_urdf(), tool_frame="tool", task_axes=("x", "y"))
    assert model.dynamics == "pinocchio"
    assert ControllerModel.from_urdf(PLANAR3, tool_frame="tool", task_axes=("x", "y")).dynamics == "pinocchio"


def test_the_model_check_scales_with_gravity_and_still_catches_a_different_model():
    """C q̇ is Pinocchio's nle − g: under a gravity of 1e12 m/s² its rounding is about 1e-4,
    which the old check (relative to |C q̇| alone) blamed on the libraries reading the URDF
    differently. Relative to |g| it passes; a URDF with one mass changed still fails."""
    from pydrake.multibody.parsing import Parser
    from pydrake.multibody.plant import MultibodyPlant

    from nsdrake.control.dynamics import ArmModel

    text = arm4_text()
    gravity = np.array([0.0, -1e12, 0.0])
    plant = MultibodyPlant(0.0)
    Parser(plant).AddModelsFromString(text, "urdf")
    plant.mutable_gravity_field().set_gravity_vector(gravity)
    plant.Finalize()
    arm = ArmModel(plant, plant.GetFrameByName("tool"), ("x", "y"))
    check_agreement(PinocchioDynamics(text, arm, gravity), arm)
    heavier = text.replace('<mass value="0.4"/>', '<mass value="0.41"/>', 1)
    with pytest.raises(ModelMismatchError, match="controller_model: the controller model's H from Pinocchio"):
        check_agreement(PinocchioDynamics(heavier, arm, gravity), arm)


def test_hostile_urdfs_never_crash_the_process(tmp_path):
    """Issue 15, item 2: a URDF with no joints killed Python with a segmentation fault in
    Pinocchio (its Jacobian of zero columns); a one-joint arm made numba fail to type a
    kernel. In a process of their own, each is one ControllerConfigError line and the
    process ends normally; and `nsdrake run` with the joint-less arm exits 2 with one line."""
    inertia = '<inertia ixx="0.1" iyy="0.1" izz="0.1" ixy="0" ixz="0" iyz="0"/>'
    inertial = f'<inertial><mass value="1"/>{inertia}</inertial>'
    no_joints = (
        f'<robot name="r"><link name="base">{inertial}</link>'
        '<joint name="w" type="fixed"><parent link="world"/><child link="base"/></joint>'
        f'<link name="tool">{inertial}<collision><geometry><sphere radius="0.01"/></geometry>'
        "</collision></link>"
        '<joint name="t" type="fixed"><parent link="base"/><child link="tool"/>'
        '<origin xyz="0 0.5 0"/></joint></robot>'
    )
    (tmp_path / "no_joints.urdf").write_text(no_joints)
    script = f"""
import sys
sys.path.insert(0, {str(Path(__file__).parents[1])!r})
from models import serial_arm_urdf
from nsdrake import ControllerConfig, ControllerConfigError, NullSpaceImpedanceController
for urdf in (open({str(tmp_path / "no_joints.urdf")!r}).read(), serial_arm_urdf(["z"], [0.3], [1.0])):
    try:
        NullSpaceImpedanceController(controller_model=urdf, normal=[0.0, 1.0], config=ControllerConfig())
    except ControllerConfigError as e:
        print(e)
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr  # a segfault is -11
    assert done.stdout.splitlines() == [
        "controller_model: the arm has no revolute or prismatic joint: nothing to control",
        "task_axes: ['x', 'y'] on an arm of 1 joint leave no redundancy for a null space "
        "(the controller needs more joints than task axes)",
    ]
    (tmp_path / "c.yaml").write_text("arm: {urdf: no_joints.urdf, initial_positions: {joint1: 0.0}}\n")
    command = [sys.executable, "-m", "nsdrake", "run", "fig3", "--config", "c.yaml", "--out", "out"]
    done = subprocess.run(command, capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.splitlines() == [
        "nsdrake: error: fig3.yaml + c.yaml: arm.urdf: no_joints.urdf: the arm has no revolute or prismatic "
        "joint: nothing to control"
    ]
    assert not (tmp_path / "out").exists()


def test_the_default_configuration_and_the_shipped_scenarios_pass(tmp_path):
    """The rules refuse nothing the project ships or defaults to (a rule too strict fails here)."""
    ControllerConfig()
    ControllerConfig(impedance=ImpedanceConfig(max_task_inertia=math.inf))
    fig3_with(tmp_path, "realism: {physics: {enabled: true, substeps: 128}}\n")
