"""The controller's contract as the documentation states it (docs/own_diagram.md, "Use the
controller in your own diagram"): its timing behind a plant of another time step or a continuous one, its
direct feedthrough (the algebraic loop with a reaction-force sensor), its first period,
a plant with more joints than the arm, the errors its constructor raises, and the page's
example being diagrams/own_arm.py.

The set-up is a user's, written with plain Drake: a 4-joint planar arm of the tests' own
(tests/models.py), a block welded to the world through a joint whose reaction force a
:class:`ForceSensor` reads (the loop exists whether or not anything touches it), constant
references, and joint-torque minimisation on, so that q̇_dⁿ changes and q̈_dⁿ matters.
"""

from __future__ import annotations

import re
import textwrap
from pathlib import Path

import numpy as np
import pytest
from models import serial_arm_urdf
from pydrake.all import (
    AddMultibodyPlant,
    ConstantVectorSource,
    DiagramBuilder,
    LogVectorOutput,
    MatrixGain,
    MultibodyPlantConfig,
    Parser,
    RigidTransform,
    Simulator,
    SpatialInertia,
    WeldJoint,
    ZeroOrderHold,
)

from nsdrake import ControlHold, ControllerConfig, ControllerConfigError, NullSpaceImpedanceController
from nsdrake.station.force_sensor import ForceSensor

ROOT = Path(__file__).resolve().parents[2]
T = 0.002  # control period [s]
ARM = serial_arm_urdf(["z"] * 4, [0.25] * 4, [1.0, 0.8, 0.6, 0.4], name="arm")
Q0 = np.array([0.4, 0.9, 1.0, 0.6])


def config(**null_space) -> ControllerConfig:
    c = ControllerConfig(period=T)
    c.desired_null_space.criteria.joint_torque.gain = -0.005
    for name, value in null_space.items():
        setattr(c.null_space, name, value)
    return c


def user_diagram(time_step: float, hold: str, controller_config: ControllerConfig | None = None, offset=0.01):
    """The arm on a plant of ``time_step`` (0: continuous), the block on its sensor joint, and
    the controller connected to the actuation directly (``hold`` "none") or through
    ``ControlHold`` ("control_hold", "control_hold_state": direct_feedthrough False) or
    Drake's ``ZeroOrderHold`` ("zoh"). x_d is the start 1 cm along x. Returns the diagram
    builder (not built), the controller and the port that reaches the actuation."""
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=time_step), builder)
    Parser(plant).AddModelsFromString(ARM, "urdf")
    block = plant.AddRigidBody(
        "block", plant.AddModelInstance("block"), SpatialInertia.SolidBoxWithMass(1.0, 0.1, 0.1, 0.1)
    )
    mount = plant.AddJoint(
        WeldJoint("mount", plant.world_frame(), block.body_frame(), RigidTransform([0, 2, 0]))
    )
    plant.Finalize()
    plant.SetDefaultPositions(Q0)
    sensor = builder.AddSystem(ForceSensor(plant=plant, sensor_joint=mount))
    builder.Connect(plant.get_reaction_forces_output_port(), sensor.get_input_port())
    controller = builder.AddSystem(
        NullSpaceImpedanceController(
            controller_model=ARM,
            normal=[0.0, 1.0],
            config=controller_config or config(),
            task_axes=("x", "y"),
        )
    )
    builder.Connect(plant.get_state_output_port(), controller.GetInputPort("estimated_state"))
    builder.Connect(sensor.GetOutputPort("wrench"), controller.GetInputPort("measured_wrench"))
    x0 = plant.GetFrameByName("tool").CalcPoseInWorld(plant.CreateDefaultContext()).translation()[:2]
    for port, value in (
        ("desired_position", x0 + [offset, 0.0]),
        ("desired_velocity", np.zeros(2)),
        ("desired_acceleration", np.zeros(2)),
        ("desired_force", [0.0]),
    ):
        builder.Connect(
            builder.AddSystem(ConstantVectorSource(value)).get_output_port(), controller.GetInputPort(port)
        )
    tau = controller.GetOutputPort("generalized_force")
    if hold != "none":
        system = {
            "control_hold": lambda: ControlHold(size=4, period=T),
            "control_hold_state": lambda: ControlHold(size=4, period=T, direct_feedthrough=False),
            "zoh": lambda: ZeroOrderHold(T, 4),
        }[hold]()
        builder.AddSystem(system)
        builder.Connect(tau, system.get_input_port())
        tau = system.get_output_port()
    builder.Connect(tau, plant.get_actuation_input_port())
    return builder, controller, tau


def final_state(hold: str, controller_config: ControllerConfig, duration: float = 0.3) -> np.ndarray:
    builder, _, _ = user_diagram(0.0, hold, controller_config)
    simulator = Simulator(builder.Build())
    simulator.AdvanceTo(duration)
    return simulator.get_context().get_continuous_state_vector().CopyToVector()


@pytest.mark.parametrize("hold", ["none", "control_hold"])
def test_behind_a_continuous_plant_a_reaction_force_sensor_closes_an_algebraic_loop(hold):
    """Every input feeds generalized_force; the reaction forces of a continuous plant depend
    on its actuation: Build refuses the loop, directly or through a hold with feedthrough.
    Catches a page that calls the direct connection fine."""
    builder, _, _ = user_diagram(0.0, hold)
    with pytest.raises(RuntimeError, match="algebraic loop"):
        builder.Build()


def test_behind_a_continuous_plant_control_hold_keeps_the_feedforward_and_zero_order_hold_drops_it():
    """ControlHold(direct_feedthrough=False) builds and samples τ beside the controller's own
    updates; Drake's ZeroOrderHold samples after them, when the stored previous q̇_dⁿ is
    already the current one: its run is the run without the q̈_dⁿ feed-forward, to the last
    bit, and differs from ControlHold's. Catches the page recommending ZeroOrderHold."""
    held = final_state("control_hold_state", config())
    zoh = final_state("zoh", config())
    no_feedforward = final_state("control_hold_state", config(acceleration_feedforward=False))
    np.testing.assert_array_equal(zoh, no_feedforward)
    assert np.max(np.abs(held - zoh)) > 1e-6


def test_behind_a_finer_plant_the_hold_applies_one_torque_per_period():
    """A plant stepping at T/4: through ControlHold the actuation is constant over each
    control period (the controller is evaluated once per period); connected directly it
    changes at every plant step. Catches a page that calls the direct connection fine."""

    def actuation(hold):
        builder, _, tau = user_diagram(T / 4, hold)
        log = LogVectorOutput(tau, builder, T / 4)
        simulator = Simulator(builder.Build())
        simulator.AdvanceTo(0.2)
        return log.FindLog(simulator.get_context()).data()[:, :400].reshape(4, 100, 4)  # joint, period, step

    held = actuation("control_hold")
    assert np.array_equal(held, np.repeat(held[:, :, :1], 4, axis=2))
    direct = actuation("none")
    assert np.max(np.abs(np.diff(direct, axis=2))) > 1e-6


def test_the_first_period_blends_from_rest_without_feedforward_or_rate_limit():
    """At a fresh context: q̇_dⁿ = 0 (the selector blends in from mode 0), and τ is the same
    with and without the q̈_dⁿ feed-forward (no previous sample) and with a torque-rate limit
    of 1e-6 N m/s (no previous torque); one period later the feed-forward and the limit act."""
    limited = config()
    limited.actuator_limits.torque_rate = {f"joint{i}": 1e-6 for i in range(1, 5)}
    variants = {"full": config(), "no_feedforward": config(acceleration_feedforward=False), "rate": limited}
    first, second = {}, {}
    for name, c in variants.items():
        builder, controller, _ = user_diagram(T, "none", c)
        simulator = Simulator(builder.Build())
        simulator.Initialize()
        context = controller.GetMyContextFromRoot(simulator.get_context())
        assert np.all(controller.GetOutputPort("desired_null_space_velocity").Eval(context) == 0.0)
        first[name] = controller.GetOutputPort("generalized_force").Eval(context).copy()
        simulator.AdvanceTo(T)
        second[name] = controller.GetOutputPort("generalized_force").Eval(context).copy()
    assert np.max(np.abs(first["full"])) > 0.1  # the 1 cm step asks for torque
    np.testing.assert_array_equal(first["full"], first["no_feedforward"])
    np.testing.assert_array_equal(first["full"], first["rate"])
    assert np.max(np.abs(second["full"] - second["no_feedforward"])) > 1e-9
    np.testing.assert_allclose(second["rate"], first["rate"], rtol=0, atol=1e-6 * T * 1.0001)


def docs_section() -> str:
    """The documentation's page on the component (docs/own_diagram.md), which holds what
    the README's section "Use the controller in your own diagram" held."""
    return (ROOT / "docs" / "own_diagram.md").read_text()


def python_blocks(section: str) -> list[str]:
    """The section's python code blocks, each as written (a block in a list item dedented)."""
    return [textwrap.dedent(b) for b in re.findall(r"```python\n(.*?)```", section, flags=re.S)]


def test_the_docs_example_is_the_whole_of_diagrams_own_arm_py():
    """The page shows diagrams/own_arm.py, which a test runs (test_controller.py), whole:
    included from the file with no option that shows only part of it (:lines:,
    :start-after:, …), so nothing is left for the reader to fill in and the page cannot
    drift from the program. Catches an example pasted into the page, or cut short."""
    includes = re.findall(r"```\{literalinclude\} (\S+)\n((?::\S+:.*\n)*)```", docs_section())
    assert includes[0] == ("../diagrams/own_arm.py", ":language: python\n")


def test_the_docs_wiring_for_a_plant_with_more_joints_selects_the_arms():
    """The docs' snippet, run as written on a plant whose first model instance is another
    2-joint arm: the controller reads the arm's own [q; q̇], and its τ reaches the arm's
    actuators and no other. Catches a selection that takes the plant's first 2n entries."""
    (snippet,) = [b for b in python_blocks(docs_section()) if "MakeStateSelectorMatrix" in b]
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlant(MultibodyPlantConfig(time_step=T), builder)
    parser = Parser(plant)
    parser.SetAutoRenaming(True)
    (other,) = parser.AddModelsFromString(
        serial_arm_urdf(["z", "z"], [0.3, 0.3], [1.0, 1.0], name="other"), "urdf"
    )
    (arm,) = parser.AddModelsFromString(ARM, "urdf")
    plant.Finalize()
    controller = builder.AddSystem(
        NullSpaceImpedanceController(
            controller_model=ARM, normal=[0.0, 1.0], config=config(), task_axes=("x", "y")
        )
    )
    for port, size in (("measured_wrench", 6), ("desired_position", 2), ("desired_velocity", 2)):
        builder.Connect(
            builder.AddSystem(ConstantVectorSource(np.zeros(size))).get_output_port(),
            controller.GetInputPort(port),
        )
    for port, size in (("desired_acceleration", 2), ("desired_force", 1)):
        builder.Connect(
            builder.AddSystem(ConstantVectorSource(np.zeros(size))).get_output_port(),
            controller.GetInputPort(port),
        )
    exec(
        snippet,
        {"builder": builder, "plant": plant, "arm": arm, "controller": controller, "MatrixGain": MatrixGain},
    )
    diagram = builder.Build()
    context = diagram.CreateDefaultContext()
    plant_context = plant.GetMyMutableContextFromRoot(context)
    plant.SetPositions(plant_context, other, [-1.0, -2.0])
    plant.SetPositions(plant_context, arm, Q0)
    plant.SetVelocities(plant_context, arm, [0.1, 0.2, 0.3, 0.4])
    controller_context = controller.GetMyContextFromRoot(context)
    state = controller.GetInputPort("estimated_state").Eval(controller_context)
    np.testing.assert_array_equal(state, np.concatenate([Q0, [0.1, 0.2, 0.3, 0.4]]))
    tau = controller.GetOutputPort("generalized_force").Eval(controller_context)
    u = plant.get_actuation_input_port().Eval(plant_context)
    assert np.max(np.abs(tau)) > 0.1
    np.testing.assert_array_equal(plant.GetActuationFromArray(arm, u), tau)
    np.testing.assert_array_equal(plant.GetActuationFromArray(other, u), [0.0, 0.0])


@pytest.mark.parametrize(
    ("arguments", "error", "words"),
    [
        (
            {"normal": [0.0, 1.0, 0.0]},
            ControllerConfigError,
            "normal: must be 2 numbers, a direction on the task axes",
        ),
        ({"task_axes": ("x", "y", "z"), "normal": [0, 1, 0]}, ControllerConfigError, "cannot span them"),
        (
            {"task_axes": ("x", "y", "z", "rx", "ry", "rz"), "normal": [0, 1, 0]},
            ControllerConfigError,
            "no redundancy",
        ),
        ({"joint_speed_limits": {"elbow": 1.0}}, ControllerConfigError, "elbow: unknown joint"),
        ({"obstacle_gain": 1.0}, ControllerConfigError, "no link collision geometry"),
        ({"tool_frame": "flange"}, ValueError, "no frame named 'flange'"),
        (
            {"task_axes": ("x", "q")},
            ControllerConfigError,
            "task_axes[1]: must be one of x, y, z, rx, ry, rz",
        ),
        (
            {"controller_model": "/nonexistent/arm.urdf"},
            ControllerConfigError,
            "controller_model: '/nonexistent/arm.urdf' is neither a readable URDF file",
        ),
        (
            {"controller_model": "<robot name='x'><link name='a'></robot>"},
            ControllerConfigError,
            "controller_model: the URDF is not XML",
        ),
        ({"K_n": 5000.0}, ControllerConfigError, "config.null_space.K_n: K_n T = 10 ≥ 2"),
    ],
    ids=[
        "normal",
        "span",
        "redundancy",
        "joint name",
        "obstacles",
        "tool frame",
        "axis name",
        "file",
        "xml",
        "K_n T",
    ],
)
def test_the_constructor_raises_the_documented_errors(arguments, error, words):
    """The docs' list of what the constructor refuses, each with its exception type and a
    message naming the problem."""
    c = config(**({"K_n": arguments.pop("K_n")} if "K_n" in arguments else {}))
    c.desired_null_space.joint_speed_limits = arguments.pop("joint_speed_limits", {})
    c.desired_null_space.criteria.obstacle.gain = arguments.pop("obstacle_gain", 0.0)
    kwargs = {
        "controller_model": ARM,
        "normal": [0.0, 1.0],
        "config": c,
        "task_axes": ("x", "y"),
        **arguments,
    }
    with pytest.raises(error, match=re.escape(words)):
        NullSpaceImpedanceController(**kwargs)
