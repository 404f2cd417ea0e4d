"""Every fixed-base arm of the ``example-robot-data`` package (PyPI), loaded as shipped, holds
its tool's pose (issue 42).

Each arm's file is loaded untouched by :meth:`nsdrake.ControllerModel.from_file` (a floating
root welded to the world; grippers, heads, torsos and mobile bases locked with ``joints=``),
and a :class:`nsdrake.ControllerStep` holds the tool where it starts -- its full pose on an
arm with redundancy for one (n ≥ 7), else its position -- for :data:`DURATION` in closed
loop against Drake's own plant of the same file while the null space moves the joints
(q̇_dⁿ = ±:data:`NULL_SPACE_SPEED` sin²(π t / DURATION) per joint, signs alternating, projected
by the law). That plant is a discrete ``MultibodyPlant`` parsed from the file by Drake alone
(no nsdrake code), its floating root welded with ``WeldFrames``, every joint not controlled
held by Drake's joint locking (``Joint.Lock``), the commands applied as generalized forces.

The figures: the largest tool position and orientation errors over the run, as shipped; as
shipped with the law's model compensating the damping as D q̇ only (``damping_time`` 0); with
the joints' damping removed (plant and controller both); the largest command relative to the
file's effort limit, and how far the joints moved. The law compensates the file's damping D
as D q̇ of the tick's state and as the inertia T_D D it adds over a held command
(:class:`nsdrake.control.dynamics.ArmModel`): Drake's discrete plant integrates it
implicitly, −D q̇ at the step's end, so with the plant stepping once per control period
T_D = :data:`PLANT_STEP` exactly (:data:`DAMPING_TIME`). Without that term the xArm7's wrist
(T D / H_jj ≈ 14: the file declares damping whose time constant is 0.07 ms, and no rotor
inertia) is a much heavier joint than the law's model of it.

``python bench/bench_vendor_arms.py`` writes the table (``docs/results/vendor_arms/table.md``).
"""

from __future__ import annotations

import math
import sysconfig
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.math import RigidTransform
from pydrake.multibody.parsing import Parser
from pydrake.multibody.plant import MultibodyPlant
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.analysis import Simulator

PACKAGE = "example-robot-data"
INSTALL = "pip install 'nsdrake[arms]' (or: pip install example-robot-data)"
DURATION = 1.0  # [s]
PERIOD = 0.001  # the control period [s]
PLANT_STEP = PERIOD  # the simulated plant's step [s]
# T_D, the damping's inertia time of the controller's model: Drake's discrete plant stepping
# once per control period integrates −D q̇ₙ₊₁, an added inertia h D exactly [s].
DAMPING_TIME = PLANT_STEP
POSE = ("x", "y", "z", "rx", "ry", "rz")
POSITION = ("x", "y", "z")
NULL_SPACE_SPEED = 0.1  # |q̇_dⁿ| per joint, signs alternating along the chain [rad/s]


@dataclass(frozen=True)
class VendorArm:
    """An arm description of the package: its file (below ``robots/``), the tool frame, the
    arm's joints (None: every joint of the file) and the locked joints' positions."""

    name: str
    file: str
    tool: str
    joints: tuple[str, ...] | None = None
    locked: tuple[tuple[str, float], ...] = ()


def _numbered(prefix: str, count: int, suffix: str = "") -> tuple[str, ...]:
    return tuple(f"{prefix}{k}{suffix}" for k in range(1, count + 1))


UR = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
PANDA = _numbered("panda_joint", 7)
TALOS = _numbered("arm_left_", 7, "_joint")
BAXTER = tuple(f"left_{j}" for j in ("s0", "s1", "e0", "e1", "w0", "w1", "w2"))
TIAGO = _numbered("arm_", 7, "_joint")
Z1 = _numbered("joint", 6)
SO = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll")
ARMS = (
    VendorArm("Panda", "panda_description/urdf/panda.urdf", "panda_hand_tcp", PANDA),
    VendorArm("Panda (collision)", "panda_description/urdf/panda_collision.urdf", "panda_hand_tcp", PANDA),
    *(
        VendorArm(f"UR{size}{label}", f"ur_description/urdf/ur{size}{suffix}.urdf", "tool0")
        for size, suffix, label in (
            ("3", "_robot", ""),
            ("3", "_joint_limited_robot", " (limited)"),
            ("3", "_gripper", " (gripper)"),
            ("5", "_robot", ""),
            ("5", "_joint_limited_robot", " (limited)"),
            ("5", "_gripper", " (gripper)"),
            ("10", "_robot", ""),
            ("10", "_joint_limited_robot", " (limited)"),
        )
    ),
    VendorArm("xArm7", "xarm_description/urdf/xarm7.urdf", "link_eef"),
    VendorArm(
        "Jaco (Kinova j2s6s200)",
        "kinova_description/robots/kinova.urdf",
        "j2s6s200_end_effector",
        _numbered("j2s6s200_joint_", 6),
    ),
    VendorArm("Z1", "z1_description/urdf/z1.urdf", "gripperStator", Z1, (("jointGripper", -0.8),)),
    VendorArm("SO-100", "so_arm_description/urdf/so100.urdf", "gripper", SO),
    VendorArm("SO-101", "so_arm_description/urdf/so101.urdf", "gripper_frame_link", SO),
    VendorArm("TALOS left arm", "talos_data/robots/talos_left_arm.urdf", "wrist_left_ft_tool_link", TALOS),
    VendorArm("Baxter, left arm", "baxter_description/urdf/baxter.urdf", "left_gripper", BAXTER),
    VendorArm("TIAGo, arm", "tiago_description/robots/tiago.urdf", "arm_tool_link", TIAGO),
    VendorArm(
        "Z1 on B1",
        "b1_description/urdf/b1-z1.urdf",
        "gripperStator",
        Z1,
        (("jointGripper", -0.8), *((f"{leg}_calf_joint", -1.5) for leg in ("FR", "FL", "RR", "RL"))),
    ),
)  # fmt: skip


def robots_folder() -> Path | None:
    """The package's ``robots/`` folder, or None when it is not installed."""
    folder = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / PACKAGE / "robots"
    return folder if folder.is_dir() else None


def packages() -> dict[str, str]:
    """Its URIs say ``package://example-robot-data/...``; its package.xml names another package."""
    return {PACKAGE: str(robots_folder().parent)}


def load(arm: VendorArm, **options):
    """The controller's model of ``arm`` (:meth:`nsdrake.ControllerModel.from_file`, the file as
    shipped; ``damping_time`` :data:`DAMPING_TIME` unless ``options`` say) and its task axes."""
    from nsdrake.control import ControllerModel

    path = robots_folder() / arm.file
    options = {"damping_time": DAMPING_TIME, **options}
    common = dict(packages=packages(), joints=arm.joints, locked=dict(arm.locked), **options)
    model = ControllerModel.from_file(path, tool_frame=arm.tool, task_axes=POSITION, **common)
    if model.n >= 7:
        model = ControllerModel.from_file(path, tool_frame=arm.tool, task_axes=POSE, **common)
    return model, model.arm.task_axes


def start(model, limits: np.ndarray) -> np.ndarray:
    """q0: the first of seeded draws within the joints' limits (the middle 40% of each range,
    ranges cut to ±π) away from singular poses (the task Jacobian's smallest singular value
    at least 0.05 m or rad per rad) where the arm holds itself within 80% of its effort
    ``limits`` (Baxter's shoulders need their springs, which the file leaves out, elsewhere)."""
    lower, upper = model.plant.GetPositionLowerLimits(), model.plant.GetPositionUpperLimits()
    lower, upper = np.maximum(lower, -math.pi), np.minimum(upper, math.pi)
    context = model.plant.CreateDefaultContext()
    rng = np.random.default_rng(0)
    for _ in range(2000):
        q = lower + (upper - lower) * rng.uniform(0.3, 0.7, model.n)
        terms = model.arm.terms(context, q, np.zeros(model.n), False)
        if np.linalg.svd(terms.J, compute_uv=False)[-1] >= 0.05 and np.all(np.abs(terms.g) <= 0.8 * limits):
            return q
    raise RuntimeError("no pose away from singularities found")


def hold_config():
    """The controller's configuration for the hold: the defaults at a 1 ms period, the task
    inertia uncapped (the cap, ``max_task_inertia``, damps Λ near singular poses, where τ₀
    then leaks into the task; the Panda's Λ passes the default 50 kg at most poses of its
    range), so that the law is exactly the paper's."""
    from nsdrake.control import ControllerConfig

    config = ControllerConfig(period=PERIOD)
    config.impedance.max_task_inertia = math.inf
    config.impedance.max_task_rotational_inertia = math.inf
    return config


@dataclass
class Hold:
    """The figures of one closed-loop hold."""

    n: int
    task: str  # "pose" or "position"
    position_error: float  # the largest ‖p − p_d‖ over the run [m]
    angle_error: float  # the largest rotation angle of R_dᵀ R [rad] (0 for a position task)
    effort: float  # the largest |τ_j| / effort limit_j over the run and the joints
    joint_motion: float  # the largest |q_j(t) − q_j(0)| over the run [rad or m]
    limited: bool  # every joint has a finite effort limit
    damped: bool  # the file declares damping on some joint of the arm


def simulated_plant(arm: VendorArm, model, damping: bool = True):
    """Drake's own plant of the arm's file (module docstring): (plant, simulator, the joints'
    damping D (nv,) [N m s/rad] (zero unless ``damping``), the velocity and the position index
    of each controlled joint)."""
    plant = MultibodyPlant(PLANT_STEP)
    parser = Parser(plant)
    for name, folder in packages().items():
        parser.package_map().Add(name, folder)
    parser.AddModels(str(robots_folder() / arm.file))
    children = {int(plant.get_joint(j).child_body().index()) for j in plant.GetJointIndices()}
    for index in range(1, plant.num_bodies()):  # the root floats: Drake's own weld
        if index not in children:
            plant.WeldFrames(
                plant.world_frame(), plant.get_body(BodyIndex(index)).body_frame(), RigidTransform()
            )
    declared = {}
    for j in plant.GetJointIndices():
        joint = plant.get_joint(j)
        if joint.num_velocities() == 1:
            declared[j] = joint.default_damping() if damping else 0.0
            joint.set_default_damping(declared[j])
    for constraint in plant.GetConstraintIds():  # <mimic> couplers, between joints locked below
        plant.RemoveConstraint(constraint)
    plant.Finalize()
    D = np.zeros(plant.num_velocities())
    for j, value in declared.items():
        D[plant.get_joint(j).velocity_start()] = value
    simulator = Simulator(plant)
    context = simulator.get_mutable_context()
    controlled = [plant.GetJointByName(name) for name in model.joint_names]
    locked = model.parsed.locked if model.parsed is not None else {}
    q = plant.GetPositions(context)
    others = [plant.get_joint(j) for j in plant.GetJointIndices() if plant.get_joint(j).num_velocities()]
    others = [j for j in others if j.name() not in model.joint_names]
    for joint in others:
        q[joint.position_start()] = locked.get(joint.name(), 0.0)
    plant.SetPositions(context, q)
    for joint in others:
        joint.Lock(context)
    return (
        plant,
        simulator,
        D,
        [j.velocity_start() for j in controlled],
        [j.position_start() for j in controlled],
    )


def held_model(arm: VendorArm, compensate: bool, damping_time: float):
    """The controller's model of ``arm`` for :func:`hold` and its task axes: the file's damping
    with ``damping_time`` (``compensate``), or the damping zeroed in the model."""
    model, axes = load(arm, damping_time=damping_time if compensate else 0.0)
    if not compensate:
        model.arm.damping[:] = 0.0
        model.arm._damped = False
        if model.pinocchio is not None:
            model.pinocchio._damping = None
    return model, axes


def tool_errors(X, p_d, R_d) -> tuple[float, float]:
    """The tool's position error ‖p − p_d‖ [m] at pose ``X`` and the rotation angle of
    R_dᵀ R [rad] (0 where ``R_d`` is None: a position task)."""
    angle = 0.0 if R_d is None else abs(float(R_d.inverse().multiply(X.rotation()).ToAngleAxis().angle()))
    return float(np.linalg.norm(X.translation() - p_d)), angle


def hold(
    arm: VendorArm,
    duration: float = DURATION,
    damping: bool = True,
    compensate: bool = True,
    damping_time: float = DAMPING_TIME,
) -> Hold:
    """Holds the tool of ``arm`` where it starts for ``duration`` (module docstring).
    ``damping``: the simulated joints keep the file's damping; ``compensate``: the controller's
    model keeps it too (else it is zeroed there, as if the law ignored it), with the inertia
    ``damping_time`` · D it adds over a held command (0: D q̇ only)."""
    from nsdrake.control import ControllerStep
    from nsdrake.control.controller import torque_limits

    model, axes = held_model(arm, compensate, damping_time)
    config = hold_config()
    step = ControllerStep(controller_model=model, config=config, task_axes=axes)
    limits = torque_limits(config, model)
    q0 = start(model, limits)
    plant, simulator, D, v_index, q_index = simulated_plant(arm, model, damping)
    context = simulator.get_mutable_context()
    q_all = plant.GetPositions(context)
    q_all[q_index] = q0
    plant.SetPositions(context, q_all)
    tool = plant.GetFrameByName(arm.tool)
    X_d = tool.CalcPoseInWorld(context)
    p_d, R_d = X_d.translation(), X_d.rotation()
    quaternion = R_d.ToQuaternion().wxyz() if len(axes) == 6 else None
    zero = np.zeros(3)
    speeds = NULL_SPACE_SPEED * np.where(np.arange(model.n) % 2 == 0, 1.0, -1.0)
    force = plant.get_applied_generalized_force_input_port().FixValue(
        context, np.zeros(plant.num_velocities())
    )
    worst_p = worst_angle = worst_effort = motion = 0.0
    simulator.Initialize()
    for k in range(round(duration / PERIOD)):
        q, v = plant.GetPositions(context)[q_index], plant.GetVelocities(context)[v_index]
        rotation = (quaternion, zero, zero) if len(axes) == 6 else (None, None, None)
        qdot_n = speeds * math.sin(math.pi * k * PERIOD / duration) ** 2
        result = step.step(
            k * PERIOD, q, v, None, p_d, zero, zero, None, *rotation, desired_null_space_velocity=qdot_n
        )
        tau = np.zeros(plant.num_velocities())
        tau[v_index] = result.tau
        worst_effort = max(worst_effort, float(np.max(np.abs(result.tau) / limits)))
        force.GetMutableData().set_value(tau)
        simulator.AdvanceTo((k + 1) * PERIOD)
        errors = tool_errors(tool.CalcPoseInWorld(context), p_d, R_d if len(axes) == 6 else None)
        worst_p, worst_angle = max(worst_p, errors[0]), max(worst_angle, errors[1])
        motion = max(motion, float(np.max(np.abs(plant.GetPositions(context)[q_index] - q0))))
    return Hold(
        n=model.n,
        task="pose" if len(axes) == 6 else "position",
        position_error=worst_p,
        angle_error=worst_angle,
        effort=worst_effort,
        joint_motion=motion,
        limited=bool(np.all(np.isfinite(limits))),
        damped=bool(np.any(D[v_index])),
    )


HEADER = (
    "| arm | file | joints | task | position error [µm] | orientation error [°] "
    "| the damping as D q̇ only: position [µm] | D q̇ only: orientation [°] "
    "| without the file's damping: position [µm] | orientation [°] | largest command / effort limit "
    "| joint motion [rad] |"
)
COLUMNS = HEADER.count("|") - 1


def row(arm: VendorArm) -> str:
    """The table's row of ``arm``: its hold as shipped, as shipped with the law's model taking
    the damping as D q̇ only (``damping_time`` 0; "–" for a file without damping, where the two
    models are one), then with its joints' damping removed from the file (the plant and the
    controller's model both), or the one line that refuses it."""
    from nsdrake.control import ControllerConfigError

    try:
        shipped, undamped = hold(arm), hold(arm, damping=False, compensate=False)
        rate_only = hold(arm, damping_time=0.0) if shipped.damped else None
    except ControllerConfigError as e:
        text = str(e).replace(str(robots_folder()) + "/", "")
        return f"| {arm.name} | `{arm.file}` | refused: {text.replace('|', '/')} |" + " |" * (COLUMNS - 3)

    def degrees(h: Hold | None) -> str:
        return f"{math.degrees(h.angle_error):.2g}" if h is not None and h.task == "pose" else "–"

    def microns(h: Hold | None) -> str:
        return f"{h.position_error * 1e6:.2g}" if h is not None else "–"

    efforts = [h.effort for h in (shipped, undamped, rate_only) if h is not None]
    return (
        f"| {arm.name} | `{arm.file}` | {shipped.n} | {shipped.task} "
        f"| {microns(shipped)} | {degrees(shipped)} "
        f"| {microns(rate_only)} | {degrees(rate_only)} | {microns(undamped)} | {degrees(undamped)} "
        f"| {max(efforts):.2f} | {shipped.joint_motion:.2g} |"
    )


def table() -> str:
    """The markdown table of every arm's hold (module docstring)."""
    return "\n".join([HEADER, "|" + "---|" * COLUMNS, *(row(arm) for arm in ARMS)]) + "\n"
