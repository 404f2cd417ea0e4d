"""NullSpaceImpedanceController: the paper's whole controller as one Drake component."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Demultiplexer, Multiplexer

from nsdrake.control.config import ControllerConfig
from nsdrake.control.layout import tick_parts
from nsdrake.control.model import ControllerModel
from nsdrake.control.plan import ControllerPlan, generalized_inverse, speed_limits, torque_limits
from nsdrake.control.systems import (
    ActuatorLimitsSystem,
    CriteriaSystem,
    FusedController,
    ImpedanceController,
    NullSpaceController,
    NullSpaceVelocitySource,
    PrioritySelector,
    RobotTermsSystem,
    SelfMotionSweep,
    ZeroIfUnconnected,
)
from nsdrake.control.validation import (  # noqa: F401 (ControllerConfigError, check_task_span: re-exported)
    ControllerConfigError,
    check_task_span,
    validate_controller,
)

__all__ = [
    "ControllerConfigError",
    "NullSpaceImpedanceController",
    "generalized_inverse",
    "speed_limits",
    "torque_limits",
    "without_null_space_task",
]


def without_null_space_task(config: ControllerConfig) -> ControllerConfig:
    """The same controller with q̇_dⁿ = 0: every criterion gain and the sweep set to zero,
    so the null-space controller only damps self-motion."""
    d = config.desired_null_space
    c = d.criteria
    criteria = dataclasses.replace(
        c,
        obstacle=dataclasses.replace(c.obstacle, gain=0.0),
        joint_torque=dataclasses.replace(c.joint_torque, gain=0.0),
        manipulability=dataclasses.replace(c.manipulability, gain=0.0),
    )
    sweep = dataclasses.replace(d.sweep, amplitude=0.0)
    posture = dataclasses.replace(d.posture, gain=0.0)
    return dataclasses.replace(
        config, desired_null_space=dataclasses.replace(d, criteria=criteria, sweep=sweep, posture=posture)
    )


class NullSpaceImpedanceController(Diagram):
    """Task-space impedance control of position and force (Eqs. 6–8) with null-space
    velocity control through the dynamically consistent pseudo-inverse (Eqs. 14, 21),
    the desired null-space velocity from criterion gradients (Eqs. 29–33) ordered by
    Fig. 1's priority selector. Nemec & Žlajpah, Robotica 18 (2000) 513–518.

    The law, with the model terms H, C, g, J of the controller's own model at the
    measured state (q, q̇), x = p(q) the tool point on the task axes, F the measured
    contact force and n the unit task direction in which the tool pushes (for a
    pose task, x_d − x is the pose error [x_d − x; log(R_d R_WTᵀ)], ẋ = [v_T; ω]
    and J the task rows of the tool's spatial Jacobian: :mod:`nsdrake.control.orientation`)::

        τ    = Jᵀ Λ (ẍ_c − J̇ q̇) + J_Tᵀ W_T + C q̇ + g + τ₀                 (Eqs. 6–7)
        ẍ_c  = ẍ_d + K_v (ẋ_d − ẋ) + K_p (x_d − x) + n K_f (f_d − nᵀF)      (Eq. 8 + force)
        τ₀   = H N (q̈_dⁿ + (J̄̇ J + J̄ J̇) q̇ + K_n eⁿ + H⁻¹ C eⁿ)           (Eq. 21)
        eⁿ   = q̇_dⁿ − N q̇,   N = I − J̄ J,   J̄ = H⁻¹ Jᵀ Λ,   Λ = (J H⁻¹ Jᵀ)⁻¹  (Eqs. 13, 14)
        q̇_dⁿ = Σ_k K_k N_k H⁻¹ Φ_k  (Eq. 30 on each priority level; Fig. 1 orders them,
                                      joint-limit avoidance added: nsdrake.control.priority)

    J_Tᵀ W_T is Eq. 6's Jᵀ F for the whole measured wrench moved to the tool point
    (:mod:`nsdrake.control.impedance`); q̈_dⁿ is the backward difference of q̇_dⁿ over one
    period. With an exact model the closed loop is::

        (ẍ_d − ẍ) + K_v (ẋ_d − ẋ) + K_p (x_d − x) + n K_f (f_d − f_n) = 0    (Eq. 10)
        ėⁿ = −K_n eⁿ + J̄ J (J̄̇ J + J̄ J̇) q̇ − N H⁻¹ C eⁿ                      (Eq. 22)

    so τ₀ never accelerates the task (J H⁻¹ τ₀ = 0, Eq. 11), contact forces never
    accelerate the null space (N H⁻¹ Jᵀ F = 0, Eq. 26), and ν = ½ eⁿᵀ H eⁿ decreases
    as ν̇ = −K_n eⁿᵀ H eⁿ (Eq. 24). Switches in ``config`` drop each compensation term
    or swap J̄ for the Moore–Penrose or damped inverse, to measure what they do.

    .. pydrake_system::

        name: NullSpaceImpedanceController
        input_ports:
        - estimated_state
        - measured_wrench
        - desired_position
        - desired_velocity
        - desired_acceleration
        - desired_force
        - desired_orientation (with rotational task axes)
        - desired_angular_velocity (with rotational task axes)
        - desired_angular_acceleration (with rotational task axes)
        - desired_null_space_velocity (optional)
        output_ports:
        - generalized_force
        - null_space_torque
        - task_torque
        - null_space_velocity_error
        - lyapunov
        - desired_null_space_velocity
        - mode
        - speed_scale
        - manipulability
        - d_min
        - joint_torque_criterion
        - obstacle_potential
        - joint_limits_criterion
        - joint_limit_margin
        - task_position
        - saturation

    Inputs (name (size) [unit]: meaning; n joints, m_t translational task axes):

    - ``estimated_state`` (2n) [rad, rad/s]: [q; q̇] in the controller model's velocity
      order.
    - ``measured_wrench`` (6) [N m, N]: [M; f], the wrench the tool exerts on the
      environment, world frame, moment about ``wrench_point``. With ``normal=None`` (no
      force axis) optional: unconnected, it reads zero.
    - ``desired_position``, ``desired_velocity``, ``desired_acceleration`` (m_t each)
      [m, m/s, m/s²]: x_d, ẋ_d, ẍ_d, one entry per translational task axis.
    - ``desired_force`` (1) [N]: f_d along n. With ``normal=None`` optional: unconnected,
      it reads zero.
    - ``desired_orientation`` (4) [-]: with rotational task axes (``rx``, ``ry``, ``rz``,
      after the translational ones), R_d as a unit quaternion [w, x, y, z].
    - ``desired_angular_velocity``, ``desired_angular_acceleration`` (3 each) [rad/s,
      rad/s²]: with rotational task axes, ω_d and ω̇_d (world frame); the law uses their
      task rows.
    - ``desired_null_space_velocity`` (n) [rad/s]: q̇_dⁿ from outside (teleoperation of the
      elbow, a planner, a policy), optional. Connected (or fixed), it is the q̇_dⁿ of
      Eq. 21 and wins over the configured source (the criteria through Fig. 1's selector,
      or the sweep), used as given (no joint-speed scaling, no blend); unconnected, the
      configured source's.

    With ``normal=None``, a connected ``desired_force`` is refused when the controller is
    evaluated (it would change nothing). Every input is checked when it is used: a value
    that is not finite (or a zero ``desired_orientation``) raises
    :class:`nsdrake.control.validation.ControllerInputError` naming the port, its entry and
    the time, before any torque is computed from it, and an input it needs that was never
    connected nor fixed raises it naming the port (``desired_orientation``). Nothing is
    held or assumed: every input but the optional ones is read at every evaluation.

    Outputs:

    - ``generalized_force`` (n) [N m]: τ of Eq. 7 (τ₀ included), velocity order; if your
      actuators are not one per joint in order, map it with Bᵀ
      (``MatrixGain(plant.MakeActuationMatrix().T)``).
    - ``null_space_torque`` (n) [N m]: s τ₀, Eq. 21's τ₀ as it is in τ, after the
      actuator limits (J H⁻¹ τ₀ = 0: it does not move the task).
    - ``task_torque`` (n) [N m]: τ − τ₀ of Eq. 7, before the limits.
    - ``null_space_velocity_error`` (n) [rad/s]: eⁿ (Eq. 14).
    - ``lyapunov`` (1) [J]: ν (Eq. 23).
    - ``desired_null_space_velocity`` (n) [rad/s]: q̇_dⁿ.
    - ``mode`` (1) [-]: the criterion on level 2 of Fig. 1: 0 none, 1 obstacle
      avoidance, 2 joint torque, 3 manipulability, 4 joint limits.
    - ``speed_scale`` (1) [-]: the joint-speed limits' factor on q̇_dⁿ (1: none bound).
    - ``manipulability`` (1) [m²]: w = √det(J Jᵀ).
    - ``d_min`` (1) [m]: the smallest link–obstacle distance.
    - ``joint_torque_criterion`` (1) [N² m²]: ‖Jᵀ F_d‖² (Eq. 32).
    - ``obstacle_potential`` (1) [m³]: the obstacle criterion (Eq. 31).
    - ``joint_limits_criterion`` (1) [rad³]: the joint-limit criterion
      (:mod:`nsdrake.control.criteria.joint_limits`).
    - ``joint_limit_margin`` (1) [rad]: the smallest distance of a joint to a limit of
      the controller model.
    - ``task_position`` (m_t) [m]: x, the tool point on the translational task axes.
    - ``saturation`` (2) [-]: the share s of τ₀ kept under the actuator limits and the
      number of joints whose task torque had to be clipped
      (:mod:`nsdrake.control.actuator_limits`: τ = τ_task + s τ₀ within each joint's
      torque and torque-rate window, τ₀ reduced first).

    Args:
        controller_model: a :class:`nsdrake.ControllerModel`, a URDF path (the arm
            alone, welded to the world by the file), or a finalized MultibodyPlant
            of the arm that the controller may own — never the simulated plant.
        tool_frame: the frame whose origin is the task point (URDF/plant input only).
        task_axes: world axes of x, e.g. ("x", "y"), ("x", "y", "z") or the full pose
            ("x", "y", "z", "rx", "ry", "rz") (URDF/plant input only).
        normal: (m_t,) direction on the translational task axes in which the tool
            pushes: any finite non-zero vector, normalised here. None (the default): no
            force axis, a free-space position or pose task; every translational axis
            then takes ``config.impedance``'s K_p_tangent and K_v_tangent (the defaults,
            400 and 40, are critically damped: K_v = 2 √K_p).
        config: gains, inverse, switches, criteria, selector and speed limits.
        wrench_point: p_WSo (3,), the point the measured moment is about [m];
            None: the tool point itself.
        fused: False (default): the paper's structure, one named system per stage of
            the tick (robot_terms, criteria, priority_selector or self_motion_sweep,
            impedance_controller, null_space_controller, actuator_limits), each with
            its own ports, what ``diagram.svg`` shows; True: the same stages in one
            LeafSystem (``fused_controller``) between a Multiplexer of the inputs and a
            Demultiplexer of the outputs, with the same ports and the same τ at every
            tick, about a third of the cost per tick (docs/architecture.md, "Speed, measured").

    Timing and state: :mod:`nsdrake.control.stages` (the stages, their order, the
    discrete state and Drake's event order, which both structures keep).
    :class:`nsdrake.ControllerStep` runs the same stages without a Simulator.

    Preconditions: the controller model's joints are revolute or prismatic, one
    actuator each; J has full row rank m along the way (redundancy n > m).

    Timing and feedthrough: a sampled-data law of period T = ``config.period``. Its
    state (the previous q̇_dⁿ of q̈_dⁿ's backward difference, the selector's mode and
    switch time, the previous torque of the rate limit) is updated by periodic events at
    t_k = k T, but its outputs are computed from its inputs whenever something evaluates
    them, and every input feeds ``generalized_force`` directly. Connect it straight to a
    discrete plant that steps at T; behind a plant that steps at T/2^k, put
    ``nsdrake.ControlHold(size=n, period=T)`` between ``generalized_force`` and the
    actuation; behind a continuous plant, ``ControlHold(size=n, period=T,
    direct_feedthrough=False)``, which also breaks the algebraic loop that a force
    sensor on the plant's reaction forces closes (Drake's ``ZeroOrderHold`` samples
    after the controller's own updates and so drops the q̈_dⁿ feed-forward). From a
    fresh context q̇_dⁿ blends in from zero over ``selector.blend_time``, and the first
    period has no q̈_dⁿ feed-forward and no torque-rate limit. The constructor raises
    ControllerConfigError (a ValueError) for a configuration the model cannot do, and
    ValueError, FileNotFoundError or Drake's RuntimeError for a model it cannot read,
    and refuses gains whose sampled loops are unstable at the period. docs/own_diagram.md, "Use the
    controller in your own diagram": the measurements, and the wiring for a plant with
    more joints than the arm.
    """

    def __init__(
        self,
        *,
        controller_model: ControllerModel | MultibodyPlant | str | Path,
        config: ControllerConfig,
        normal: Sequence[float] | None = None,
        tool_frame: str = "tool",
        task_axes: Sequence[str] = ("x", "y"),
        wrench_point: Sequence[float] | None = None,
        fused: bool = False,
    ):
        super().__init__()
        model = as_controller_model(controller_model, tool_frame, task_axes)
        # Every argument, before any system is built (nsdrake.control.validation).
        self.normal = validate_controller(
            config=config, model=model, normal=normal, wrench_point=wrench_point
        )
        self.model, self.config, self.fused = model, config, fused
        self.wrench_point = None if wrench_point is None else np.asarray(wrench_point, dtype=float)
        self.plan = ControllerPlan(
            model=model, config=config, normal=self.normal, wrench_point=self.wrench_point
        )
        builder = DiagramBuilder()
        inputs, outputs = (_add_fused if fused else _add_named)(builder, self.plan)
        for name in INPUTS:
            if name in inputs:
                builder.ExportInput(inputs[name], name)
        for name in OUTPUTS:
            builder.ExportOutput(outputs[name], name)
        builder.BuildInto(self)
        self.set_name("controller")


# The controller's ports, in order (the rotational inputs only with rotational task axes).
INPUTS = (
    "estimated_state", "measured_wrench", "desired_position", "desired_velocity", "desired_acceleration",
    "desired_force", "desired_orientation", "desired_angular_velocity", "desired_angular_acceleration",
    "desired_null_space_velocity",
)  # fmt: skip
OUTPUTS = (
    "generalized_force", "saturation", "null_space_torque", "task_torque", "null_space_velocity_error",
    "lyapunov", "desired_null_space_velocity",
    "mode", "speed_scale", "manipulability", "joint_torque_criterion", "joint_limits_criterion",
    "joint_limit_margin", "d_min", "obstacle_potential", "task_position",
)  # fmt: skip
# Diagnostic output → the criterion part it is (nsdrake.control.systems.criteria.criteria_parts).
CRITERION_OUTPUTS = {
    "manipulability": "manipulability_value",
    "joint_torque_criterion": "joint_torque_value",
    "joint_limits_criterion": "joint_limits_value",
    "joint_limit_margin": "joint_limits_switching",
    "d_min": "obstacle_switching",
    "obstacle_potential": "obstacle_value",
}


def as_controller_model(source, tool_frame: str, task_axes: Sequence[str]) -> ControllerModel:
    if isinstance(source, ControllerModel):
        return source
    if isinstance(source, MultibodyPlant):
        return ControllerModel.from_plant(source, tool_frame=tool_frame, task_axes=task_axes)
    if isinstance(source, (str, Path)):
        return ControllerModel.from_urdf(source, tool_frame=tool_frame, task_axes=task_axes)
    raise ControllerConfigError(
        "controller_model",
        "must be a ControllerModel, a URDF path or text, or a finalized MultibodyPlant, "
        f"got {type(source).__name__}",
    )


def _split(builder, name: str, port, sizes: dict[str, int]) -> dict:
    """A packed port's parts as named ports, through Drake's (C++) Demultiplexer."""
    demux = builder.AddNamedSystem(name, Demultiplexer(list(sizes.values())))
    builder.Connect(port, demux.get_input_port())
    return {part: demux.get_output_port(k) for k, part in enumerate(sizes)}


def _add_named(builder, plan: ControllerPlan) -> tuple[dict, dict]:
    """The stages as the paper's named systems, wired in their order (data flows
    terms → criteria → selector → impedance, null space → limits); returns the ports to
    export, by the controller's port names."""
    terms = builder.AddNamedSystem("robot_terms", RobotTermsSystem(plan=plan))
    criteria = builder.AddNamedSystem("criteria", CriteriaSystem(plan=plan))
    selector = builder.AddNamedSystem("priority_selector", PrioritySelector(plan=plan))
    impedance = builder.AddNamedSystem("impedance_controller", ImpedanceController(plan=plan))
    null_space = builder.AddNamedSystem("null_space_controller", NullSpaceController(plan=plan))
    limits = builder.AddNamedSystem("actuator_limits", ActuatorLimitsSystem(plan=plan))
    terms_port = terms.GetOutputPort("robot_terms")
    for system in (criteria, selector, impedance, null_space):
        builder.Connect(terms_port, system.GetInputPort("robot_terms"))
    builder.Connect(criteria.GetOutputPort("criteria"), selector.GetInputPort("criteria"))
    selection = _split(
        builder, "selection_parts", selector.GetOutputPort("selection"), selector.output_parts()
    )
    qdot = selection["desired_null_space_velocity"]
    source = plan.config.desired_null_space.source
    if source in ("sweep", "posture"):  # a prescribed q̇_dⁿ: the sweep's or the posture criterion's
        name = "self_motion_sweep" if source == "sweep" else "posture_objective"
        sweep = builder.AddNamedSystem(name, SelfMotionSweep(plan=plan))
        builder.Connect(terms_port, sweep.GetInputPort("robot_terms"))
        qdot = sweep.get_output_port()
    source = builder.AddNamedSystem(
        "null_space_velocity_source", NullSpaceVelocitySource(plan.n, plan.model.joint_names)
    )
    builder.Connect(qdot, source.GetInputPort("configured"))
    qdot = source.get_output_port()
    builder.Connect(qdot, null_space.GetInputPort("desired_null_space_velocity"))
    ns = _split(
        builder, "null_space_parts", null_space.GetOutputPort("null_space"), null_space.output_parts()
    )
    builder.Connect(impedance.get_output_port(), limits.GetInputPort("task_torque"))
    builder.Connect(ns["generalized_force"], limits.GetInputPort("null_space_torque"))
    limited = _split(builder, "limited_parts", limits.GetOutputPort("limited"), limits.output_parts())
    parts = _split(builder, "criteria_parts", criteria.GetOutputPort("criteria"), criteria.output_parts())
    inputs = {"estimated_state": terms.GetInputPort("estimated_state")}
    impedance_inputs = ("measured_wrench", "x_d", "xdot_d", "xddot_d", "f_d", "R_d", "omega_d", "omegadot_d")
    for name, port in zip(INPUTS[1:], impedance_inputs[: 8 if plan.m_r else 5], strict=False):
        inputs[name] = _optional(builder, plan, name, impedance.GetInputPort(port))
    inputs["desired_null_space_velocity"] = source.GetInputPort("desired_null_space_velocity")
    outputs = {
        "generalized_force": limited["generalized_force"],
        "saturation": limited["saturation"],
        "null_space_torque": limits.GetOutputPort("limited_null_space_torque"),
        "task_torque": impedance.get_output_port(),
        "null_space_velocity_error": ns["null_space_velocity_error"],
        "lyapunov": ns["lyapunov"],
        "desired_null_space_velocity": qdot,
        "mode": selection["mode"],
        "speed_scale": selection["speed_scale"],
        "task_position": terms.GetOutputPort("task_position"),
    }
    return inputs, outputs | {name: parts[part] for name, part in CRITERION_OUTPUTS.items()}


def _add_fused(builder, plan: ControllerPlan) -> tuple[dict, dict]:
    """The stages in one FusedController between a Multiplexer of the inputs other than the
    state and a Demultiplexer of its tick; returns the ports to export."""
    m_t = plan.m_t
    sizes = [6, m_t, m_t, m_t, 1] + ([4, 3, 3] if plan.m_r else [])
    commands = builder.AddNamedSystem("commands", Multiplexer(sizes))
    fused = builder.AddNamedSystem("fused_controller", FusedController(plan=plan))
    builder.Connect(commands.get_output_port(), fused.GetInputPort("commands"))
    parts = _split(builder, "tick_parts", fused.GetOutputPort("tick"), tick_parts(plan.n, m_t))
    inputs = {"estimated_state": fused.GetInputPort("estimated_state")}
    for k, name in enumerate(INPUTS[1 : 1 + len(sizes)]):
        inputs[name] = _optional(builder, plan, name, commands.get_input_port(k))
    inputs["desired_null_space_velocity"] = fused.GetInputPort("desired_null_space_velocity")
    outputs = {name: parts[name] for name in OUTPUTS if name in parts}
    outputs["null_space_torque"] = fused.GetOutputPort("limited_null_space_torque")  # s τ₀, not τ₀
    return inputs, outputs | {name: parts[part] for name, part in CRITERION_OUTPUTS.items()}


# The inputs a task without a force axis may leave unconnected (they then read zero).
FREE_SPACE_OPTIONAL = {"measured_wrench": 6, "desired_force": 1}
# Why desired_force, connected to a controller without a force axis, is refused: it would
# change nothing (the measured wrench still enters Eq. 6's Jᵀ F, so it may be connected).
NO_FORCE_AXIS = (
    "connected, but the controller has no force axis (normal=None), so a desired force would "
    "change nothing: give the controller a normal, or leave desired_force unconnected"
)


def _optional(builder, plan: ControllerPlan, name: str, port):
    """``port``, or with no force axis for the optional inputs, the input of a
    ZeroIfUnconnected in front of it (which refuses a connected ``desired_force``)."""
    if plan.has_force_axis or name not in FREE_SPACE_OPTIONAL:
        return port
    refuse = NO_FORCE_AXIS if name == "desired_force" else None
    zero = builder.AddNamedSystem(
        f"{name}_or_zero", ZeroIfUnconnected(FREE_SPACE_OPTIONAL[name], name=name, refuse=refuse)
    )
    builder.Connect(zero.get_output_port(), port)
    return zero.get_input_port()
