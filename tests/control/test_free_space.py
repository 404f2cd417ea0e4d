"""The controller as a new user meets it (issue 18): a 7-joint arm nsdrake has never seen,
a free-space pose task with no force axis (``normal`` None, no wrench sensor, no force
command), the null-space torque as an output and q̇_dⁿ as an input — through the public
API only.

The arm is this file's own: an iiwa-like chain (alternating z and y axes, 0.34 / 0.40 /
0.40 / 0.126 m) with made-up masses and inertias, not a shipped model.
"""

from __future__ import annotations

import numpy as np
import pytest
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import AddMultibodyPlantSceneGraph, MultibodyPlant
from pydrake.multibody.tree import JacobianWrtVariable
from pydrake.systems.analysis import Simulator
from pydrake.systems.framework import DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, LogVectorOutput

import nsdrake

T = 0.001  # control period = plant step [s]
POSE = ("x", "y", "z", "rx", "ry", "rz")
Q0 = np.array([0.0, 0.6, 0.0, -1.2, 0.0, 0.8, 0.0])

# (parent offset z [m], axis, mass [kg], link length for the inertia [m])
LINKS = [
    (0.0, "0 0 1", 4.0, 0.34),
    (0.34, "0 1 0", 4.0, 0.20),
    (0.0, "0 0 1", 3.0, 0.40),
    (0.40, "0 1 0", 2.7, 0.20),
    (0.0, "0 0 1", 1.7, 0.40),
    (0.40, "0 1 0", 1.8, 0.10),
    (0.0, "0 0 1", 0.3, 0.126),
]


def seven_joint_urdf() -> str:
    """The test's own arm: solid-cylinder inertias (radius 6 cm) about each link's centre."""
    parts = ['<robot name="arm7">', '<link name="base"/>']
    parent = "base"
    for k, (z, axis, mass, length) in enumerate(LINKS, start=1):
        r = 0.06
        rod, axial = mass * (3 * r**2 + length**2) / 12, mass * r**2 / 2
        parts += [
            f'<link name="l{k}"><inertial><origin xyz="0 0 {length / 2}"/><mass value="{mass}"/>'
            f'<inertia ixx="{rod}" iyy="{rod}" izz="{axial}" ixy="0" ixz="0" iyz="0"/>'
            "</inertial></link>",
            f'<joint name="j{k}" type="revolute"><parent link="{parent}"/><child link="l{k}"/>'
            f'<origin xyz="0 0 {z}"/><axis xyz="{axis}"/>'
            '<limit lower="-2.9" upper="2.9" effort="2000" velocity="2"/></joint>',
            f'<transmission type="SimpleTransmission" name="t{k}"><actuator name="m{k}"/>'
            f'<joint name="j{k}"/><mechanicalReduction>1</mechanicalReduction></transmission>',
        ]
        parent = f"l{k}"
    parts += [
        '<link name="tool"/>',
        '<joint name="tool_weld" type="fixed"><parent link="l7"/><child link="tool"/>'
        '<origin xyz="0 0 0.126"/></joint>',
        '<joint name="base_weld" type="fixed"><parent link="world"/><child link="base"/></joint>',
        "</robot>",
    ]
    return "\n".join(parts)


URDF = seven_joint_urdf()


def config(K_n: float = 40.0) -> nsdrake.ControllerConfig:
    c = nsdrake.ControllerConfig(period=T)
    c.null_space.K_n = K_n
    return c


def plain_plant(time_step: float = 0.0) -> MultibodyPlant:
    plant = MultibodyPlant(time_step)
    Parser(plant).AddModelsFromString(URDF, "urdf")
    plant.Finalize()
    return plant


def tool_poses(q):
    plant = plain_plant()
    context = plant.CreateDefaultContext()
    tool = plant.GetFrameByName("tool")
    positions, rotations = [], []
    for k in range(q.shape[1]):
        plant.SetPositions(context, q[:, k])
        X = tool.CalcPoseInWorld(context)
        positions.append(X.translation())
        rotations.append(X.rotation().matrix())
    return np.array(positions), np.array(rotations)


def start_pose():
    plant = plain_plant()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, Q0)
    X = plant.GetFrameByName("tool").CalcPoseInWorld(context)
    return X.translation(), X.rotation()


def desired_orientation_source(R) -> np.ndarray:
    return R.ToQuaternion().wxyz()


STEP = 0.05  # [m]


@pytest.mark.parametrize("axis", [0, 1, 2], ids=["x", "y", "z"])
def test_free_space_step_response_is_critically_damped_on_every_position_axis(axis):
    """The component's defaults (K_p 400, K_v 40 on every position axis when there is no
    force axis) on a 5 cm step: the tool follows the ideal critically damped curve
    Δ (1 − (1 + ω t) e^{−ωt}), ω = √K_p = 20 rad/s, within 2% of the step at every
    sample. Catches a position axis left with the plate's normal gains (K_p 100, K_v 200:
    78% after 3 s), a force term acting with no force axis, and wrench or force inputs
    that must be wired in free space."""
    p0, R0 = start_pose()
    step = np.zeros(3)
    step[axis] = STEP
    controller = nsdrake.NullSpaceImpedanceController(controller_model=URDF, config=config(), task_axes=POSE)
    x_d = p0 + step
    t, _, p, _ = closed_loop(controller, x_d, R0, 0.6)
    omega = np.sqrt(400.0)
    ideal = STEP * (1.0 - (1.0 + omega * t) * np.exp(-omega * t))
    error = np.abs((p[:, axis] - p0[axis]) - ideal)
    assert error.max() <= 0.02 * STEP, (
        f"worst {error.max() / STEP:.2%} of the step at t = {t[error.argmax()]:.3f} s"
    )


def closed_loop(controller, x_d, R_d, duration, qdot_ns=None):
    """The arm on a discrete plant stepping at T (gravity on), the controller wired through
    its public ports only: the state, the desired pose (R_d held) and q̇_dⁿ if given;
    no wrench, no force command. Returns (times, q, tool positions, tool rotations)."""
    quaternion = desired_orientation_source(R_d)
    builder = DiagramBuilder()
    plant, _ = AddMultibodyPlantSceneGraph(builder, T)
    Parser(plant).AddModelsFromString(URDF, "urdf")
    plant.Finalize()
    builder.AddSystem(controller)
    builder.Connect(plant.get_state_output_port(), controller.GetInputPort("estimated_state"))
    builder.Connect(controller.GetOutputPort("generalized_force"), plant.get_actuation_input_port())
    commands = {
        "desired_position": x_d,
        "desired_velocity": np.zeros(3),
        "desired_acceleration": np.zeros(3),
        "desired_orientation": quaternion,
        "desired_angular_velocity": np.zeros(3),
        "desired_angular_acceleration": np.zeros(3),
    }
    if qdot_ns is not None:
        commands["desired_null_space_velocity"] = qdot_ns
    for name, value in commands.items():
        source = builder.AddSystem(ConstantVectorSource(np.asarray(value, dtype=float)))
        builder.Connect(source.get_output_port(), controller.GetInputPort(name))
    logger = LogVectorOutput(plant.get_state_output_port(), builder, publish_period=T)
    diagram = builder.Build()
    simulator = Simulator(diagram)
    context = simulator.get_mutable_context()
    plant.SetPositions(plant.GetMyMutableContextFromRoot(context), Q0)
    simulator.AdvanceTo(duration)
    log = logger.FindLog(context)
    q = log.data()[:7]
    positions, rotations = tool_poses(q)
    return log.sample_times(), q, positions, rotations


def task_jacobian_and_inertia(q):
    """J (6 × 7, [v; ω] of the tool point, world frame) and H from a plain Drake plant."""
    plant = plain_plant()
    context = plant.CreateDefaultContext()
    plant.SetPositions(context, q)
    tool = plant.GetFrameByName("tool")
    J = plant.CalcJacobianSpatialVelocity(
        context, JacobianWrtVariable.kV, tool, np.zeros(3), plant.world_frame(), plant.world_frame()
    )
    return np.vstack([J[3:], J[:3]]), plant.CalcMassMatrix(context)


@pytest.mark.parametrize("fused", [False, True], ids=["named systems", "fused"])
def test_null_space_torque_output_does_not_move_the_task(fused):
    """Eq. 11: J H⁻¹ τ₀ = 0 for the ``null_space_torque`` port at seeded random states and
    a q̇_dⁿ from outside (so τ₀ is large), against J and H of a plain Drake plant, to
    1e-12 relative (the task inertia cap inactive). Catches τ₀ projected with the
    Moore–Penrose inverse (Jᵀ J^{+T} instead of Jᵀ J̄ᵀ: 1e-1 here), the port carrying τ
    or the task torque, and the external q̇_dⁿ ignored (τ₀ would be small)."""
    controller = nsdrake.NullSpaceImpedanceController(
        controller_model=URDF, config=config(), task_axes=POSE, fused=fused
    )
    context = controller.CreateDefaultContext()
    rng = np.random.default_rng(18)
    p0, R0 = start_pose()
    for name, value in (
        ("desired_position", p0),
        ("desired_velocity", np.zeros(3)),
        ("desired_acceleration", np.zeros(3)),
        ("desired_orientation", desired_orientation_source(R0)),
        ("desired_angular_velocity", np.zeros(3)),
        ("desired_angular_acceleration", np.zeros(3)),
    ):
        controller.GetInputPort(name).FixValue(context, value)
    sizes = []
    for _ in range(5):
        q = Q0 + 0.3 * rng.standard_normal(7)
        v = 0.5 * rng.standard_normal(7)
        qdot_ns = 2.0 * rng.standard_normal(7)
        controller.GetInputPort("estimated_state").FixValue(context, np.concatenate([q, v]))
        controller.GetInputPort("desired_null_space_velocity").FixValue(context, qdot_ns)
        tau0 = controller.GetOutputPort("null_space_torque").Eval(context)
        tau = controller.GetOutputPort("generalized_force").Eval(context)
        task = controller.GetOutputPort("task_torque").Eval(context)
        J, H = task_jacobian_and_inertia(q)
        A = J @ np.linalg.inv(H)
        assert np.linalg.norm(A @ tau0) <= 1e-12 * np.linalg.norm(A, 2) * np.linalg.norm(tau0)
        np.testing.assert_allclose(tau, task + tau0, rtol=0, atol=1e-12 * np.abs(tau).max())
        sizes.append(np.linalg.norm(tau0))
    assert min(sizes) > 1.0, sizes  # the external q̇_dⁿ drives a real null-space torque


def test_the_plain_step_takes_the_same_null_space_velocity():
    """ControllerStep with ``desired_null_space_velocity`` and no wrench or force (free
    space) gives the Diagram's τ and s τ₀ to 1e-12 at a random state."""
    p0, R0 = start_pose()
    rng = np.random.default_rng(7)
    q, v, qdot_ns = Q0 + 0.2 * rng.standard_normal(7), rng.standard_normal(7), rng.standard_normal(7)
    step = nsdrake.ControllerStep(controller_model=URDF, config=config(), task_axes=POSE)
    quaternion = desired_orientation_source(R0)
    zero = np.zeros(3)
    result = step.step(
        0.0, q, v, None, p0, zero, zero, None, quaternion, zero, zero, desired_null_space_velocity=qdot_ns
    )
    controller = nsdrake.NullSpaceImpedanceController(controller_model=URDF, config=config(), task_axes=POSE)
    context = controller.CreateDefaultContext()
    for name, value in (
        ("estimated_state", np.concatenate([q, v])),
        ("desired_position", p0),
        ("desired_velocity", zero),
        ("desired_acceleration", zero),
        ("desired_orientation", quaternion),
        ("desired_angular_velocity", zero),
        ("desired_angular_acceleration", zero),
        ("desired_null_space_velocity", qdot_ns),
    ):
        controller.GetInputPort(name).FixValue(context, value)
    tau = controller.GetOutputPort("generalized_force").Eval(context)
    tau0 = controller.GetOutputPort("null_space_torque").Eval(context)
    scale = np.abs(tau).max()
    np.testing.assert_allclose(result.tau, tau, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(result.null_space_torque, tau0, rtol=0, atol=1e-12 * scale)


def test_an_external_null_space_velocity_moves_the_elbow_and_not_the_tool():
    """q̇_dⁿ from outside (0.5 rad/s on the first joint; the law keeps its null-space
    part) for 1 s of a held pose: the elbow (the origin of link 4) swings by more than
    5 cm while the tool point stays within 1 µm of where it was (0.25 µm measured).
    Catches the input not wired (no self-motion) and a law that lets the self-motion
    reach the task."""
    p0, R0 = start_pose()
    controller = nsdrake.NullSpaceImpedanceController(controller_model=URDF, config=config(), task_axes=POSE)
    qdot_ns = np.array([0.5, 0, 0, 0, 0, 0, 0.0])
    _, q, p, _ = closed_loop(controller, p0, R0, 1.0, qdot_ns=qdot_ns)
    elbow = frame_positions(q, "l4")
    swing = np.linalg.norm(elbow - elbow[0], axis=1).max()
    drift = np.linalg.norm(p - p0, axis=1).max()
    assert swing > 0.05, f"the elbow moved {swing * 100:.2f} cm"
    assert drift <= 1e-6, f"the tool moved {drift * 1e6:.3f} µm"


def frame_positions(q, frame: str) -> np.ndarray:
    plant = plain_plant()
    context = plant.CreateDefaultContext()
    out = []
    for k in range(q.shape[1]):
        plant.SetPositions(context, q[:, k])
        out.append(plant.GetFrameByName(frame).CalcPoseInWorld(context).translation())
    return np.array(out)
