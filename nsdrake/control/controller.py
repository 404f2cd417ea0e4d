"""NullSpaceImpedanceController: the paper's whole controller as one Drake component."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from pydrake.multibody.plant import MultibodyPlant
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import ConstantVectorSource, Demultiplexer

from nsdrake.control.config import ControllerConfig
from nsdrake.control.impedance import ImpedanceGains
from nsdrake.control.model import ControllerModel
from nsdrake.control.priority import Criterion, SelectorLimits
from nsdrake.control.pseudo_inverse import GeneralizedInverse, PseudoInverseKind
from nsdrake.control.systems import (
    ActuatorLimitsSystem,
    ImpedanceController,
    JointLimitsCriterionSystem,
    JointTorqueCriterionSystem,
    ManipulabilityCriterionSystem,
    NullSpaceController,
    ObstacleCriterionSystem,
    PrioritySelector,
    RobotTermsSystem,
    SelfMotionSweep,
)
from nsdrake.control.systems.criteria import criterion_parts, pack_criterion
from nsdrake.control.validation import (  # noqa: F401 (ControllerConfigError, check_task_span: re-exported)
    ControllerConfigError,
    check_task_span,
    validate_controller,
)


def generalized_inverse(config: ControllerConfig) -> GeneralizedInverse:
    ns = config.null_space
    return GeneralizedInverse(PseudoInverseKind(ns.pseudo_inverse), ns.damping)


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
    return dataclasses.replace(
        config, desired_null_space=dataclasses.replace(d, criteria=criteria, sweep=sweep)
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
    period. With an exact model the closed loop is

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
        output_ports:
        - generalized_force
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

    Inputs: ``estimated_state`` [q; q̇] (2n) [rad, rad/s] in the controller model's
    velocity order; ``measured_wrench`` [M; f] (6) [N m, N], the wrench the tool
    exerts on the environment, world frame, moment about ``wrench_point``;
    ``desired_position``, ``desired_velocity``, ``desired_acceleration`` x_d, ẋ_d,
    ẍ_d (m_t, one per translational task axis) [m, m/s, m/s²]; ``desired_force``
    f_d (1) [N] along n. With rotational task axes (``rx``, ``ry``, ``rz``, after the
    translational ones): ``desired_orientation`` R_d as a unit quaternion [w, x, y, z]
    (4), ``desired_angular_velocity`` ω_d and ``desired_angular_acceleration`` ω̇_d
    (3 each, world frame) [rad/s, rad/s²]; the law uses their task rows.

    Outputs: ``generalized_force`` τ (n) [N m], velocity order (map it to the
    plant's actuation with Bᵀ); ``null_space_velocity_error`` eⁿ (n) [rad/s];
    ``lyapunov`` ν (1) [J]; ``desired_null_space_velocity`` q̇_dⁿ (n) [rad/s];
    ``mode`` (1): 0 none, 1 obstacle avoidance, 2 joint torque, 3 manipulability, 4
    joint limits on level 2; ``speed_scale`` (1) the joint-speed limits' factor on q̇_dⁿ;
    ``manipulability`` w = √det(J Jᵀ) (1); ``d_min`` (1) [m] smallest link–obstacle
    distance; ``joint_torque_criterion`` ‖Jᵀ F_d‖² (1) [N² m²];
    ``obstacle_potential`` (1) [m³]; ``joint_limits_criterion`` (1) [rad³] and
    ``joint_limit_margin`` (1) [rad], the smallest distance of a joint to a limit of
    the controller model (:mod:`nsdrake.control.criteria.joint_limits`); ``task_position`` x
    (m_t) [m]; ``saturation`` (2):
    the share s of τ₀ kept under the actuator limits and the number of joints whose
    task torque had to be clipped (:mod:`nsdrake.control.actuator_limits`: τ = τ_task + s τ₀
    within each joint's torque and torque-rate window, τ₀ reduced first).

    Args:
        controller_model: a :class:`nsdrake.ControllerModel`, a URDF path (the arm
            alone, welded to the world by the file), or a finalized MultibodyPlant
            of the arm that the controller may own — never the simulated plant.
        tool_frame: the frame whose origin is the task point (URDF/plant input only).
        task_axes: world axes of x, e.g. ("x", "y"), ("x", "y", "z") or the full pose
            ("x", "y", "z", "rx", "ry", "rz") (URDF/plant input only).
        normal: (m_t,) direction on the translational task axes in which the tool
            pushes: any finite non-zero vector, normalised here.
        config: gains, inverse, switches, criteria, selector and speed limits.
        wrench_point: p_WSo (3,), the point the measured moment is about [m];
            None: the tool point itself.

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
    ValueError, FileNotFoundError or Drake's RuntimeError for a model it cannot read; it
    does not judge the gains' stability. README, "Use the controller in your own
    diagram": the measurements, and the wiring for a plant with more joints than the arm.
    """

    def __init__(
        self,
        *,
        controller_model: ControllerModel | MultibodyPlant | str | Path,
        normal: Sequence[float],
        config: ControllerConfig,
        tool_frame: str = "tool",
        task_axes: Sequence[str] = ("x", "y"),
        wrench_point: Sequence[float] | None = None,
    ):
        super().__init__()
        model = as_controller_model(controller_model, tool_frame, task_axes)
        # Every argument, before any system is built (nsdrake.control.validation).
        self.normal = validate_controller(
            config=config, model=model, normal=normal, wrench_point=wrench_point
        )
        self.model = model
        self.config = config
        # n on every task axis: zero on the rotational rows.
        task_normal = np.concatenate([self.normal, np.zeros(model.arm.m_r)])
        builder = DiagramBuilder()
        terms = _add_robot_terms(builder, model, config)
        model_terms = model.terms(model.create_scratch(), np.zeros(model.n), np.zeros(model.n), True)
        impedance = _add_impedance(builder, terms, config, self.normal, wrench_point, model, model_terms)
        qdot_ns, diagnostics = _add_desired_null_space(
            builder, terms, config, task_normal, model, model_terms
        )
        null_space = _add_null_space(builder, terms, qdot_ns, config, model_terms)
        limits = _add_actuator_limits(builder, impedance, null_space["generalized_force"], config, model)
        builder.ExportInput(terms.GetInputPort("estimated_state"), "estimated_state")
        builder.ExportInput(impedance.GetInputPort("measured_wrench"), "measured_wrench")
        for name, port in (
            ("desired_position", "x_d"),
            ("desired_velocity", "xdot_d"),
            ("desired_acceleration", "xddot_d"),
            ("desired_force", "f_d"),
        ):
            builder.ExportInput(impedance.GetInputPort(port), name)
        if model.arm.m_r:
            for name, port in (
                ("desired_orientation", "R_d"),
                ("desired_angular_velocity", "omega_d"),
                ("desired_angular_acceleration", "omegadot_d"),
            ):
                builder.ExportInput(impedance.GetInputPort(port), name)
        builder.ExportOutput(limits["generalized_force"], "generalized_force")
        builder.ExportOutput(limits["saturation"], "saturation")
        builder.ExportOutput(null_space["null_space_velocity_error"], "null_space_velocity_error")
        builder.ExportOutput(null_space["lyapunov"], "lyapunov")
        builder.ExportOutput(qdot_ns, "desired_null_space_velocity")
        for name, port in diagnostics.items():
            builder.ExportOutput(port, name)
        builder.ExportOutput(terms.GetOutputPort("task_position"), "task_position")
        builder.BuildInto(self)
        self.set_name("controller")


def torque_limits(config: ControllerConfig, model: ControllerModel) -> np.ndarray:
    """|τ| limit per joint (velocity order): the configuration's, else the model's
    actuator effort limit, else unlimited. [N m]."""
    plant = model.plant
    effort = {}
    for index in plant.GetJointActuatorIndices():
        actuator = plant.get_joint_actuator(index)
        effort[actuator.joint().name()] = actuator.effort_limit()
    return np.array([config.actuator_limits.torque.get(j, effort.get(j, np.inf)) for j in model.joint_names])


def speed_limits(config: ControllerConfig, model: ControllerModel) -> np.ndarray:
    """Joint-speed limit per joint (velocity order) for q̇_dⁿ's scaling: the configuration's,
    else the model's velocity limit (URDF ``<limit velocity>``; zero or none counts as
    unlimited, as URDF writers use 0 for "not given"). [rad/s]."""
    model_limits = model.plant.GetVelocityUpperLimits()
    table = config.desired_null_space.joint_speed_limits
    return np.array(
        [
            table.get(j, limit if limit > 0 else np.inf)
            for j, limit in zip(model.joint_names, model_limits, strict=True)
        ]
    )


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


def _add_robot_terms(builder, model: ControllerModel, config: ControllerConfig):
    ns = config.null_space
    return builder.AddNamedSystem(
        "robot_terms",
        RobotTermsSystem(
            model=model,
            coriolis_matrix=ns.task_velocity_compensation or ns.coriolis_compensation,
            max_task_inertia=config.impedance.max_task_inertia,
        ),
    )


def _add_impedance(builder, terms, config, normal, wrench_point, model, model_terms):
    imp = config.impedance
    impedance = builder.AddNamedSystem(
        "impedance_controller",
        ImpedanceController(
            gains=ImpedanceGains.along_surface(
                normal,
                imp.K_p_tangent,
                imp.K_p_normal,
                imp.K_v_tangent,
                imp.K_v_normal,
                imp.K_f,
                imp.K_p_rotation,
                imp.K_v_rotation,
                model.arm.m_r,
            ),
            task_rows=model.arm.rows,
            p_WSo=wrench_point,
            gravity_compensation=imp.gravity_compensation,
            model_terms=model_terms,
            rot_rows=model.arm.rot_rows,
        ),
    )
    builder.Connect(terms.GetOutputPort("robot_terms"), impedance.GetInputPort("robot_terms"))
    return impedance


def _add_criteria(builder, terms_port, config, normal, model, model_terms) -> dict:
    crit = config.desired_null_space.criteria
    systems = {
        Criterion.joint_torque: JointTorqueCriterionSystem(
            F_d=config.nominal_force * normal, model_terms=model_terms
        ),
        Criterion.manipulability: ManipulabilityCriterionSystem(model_terms=model_terms),
    }
    if model.has_geometry:
        systems[Criterion.obstacle] = ObstacleCriterionSystem(
            model=model, influence_distance=crit.obstacle.influence_distance, model_terms=model_terms
        )
    lower, upper = model.plant.GetPositionLowerLimits(), model.plant.GetPositionUpperLimits()
    if np.isfinite(lower).any() or np.isfinite(upper).any():
        systems[Criterion.joint_limits] = JointLimitsCriterionSystem(
            lower=lower, upper=upper, influence=crit.joint_limits.influence, model_terms=model_terms
        )
    added = {}
    for c in Criterion:
        if c in systems:
            added[c] = builder.AddNamedSystem(f"{c.value}_criterion", systems[c])
            builder.Connect(terms_port, added[c].GetInputPort("robot_terms"))
    return added


def _split(builder, name: str, port, sizes: dict[str, int]) -> dict:
    """A packed port's parts as named ports, through Drake's (C++) Demultiplexer."""
    demux = builder.AddNamedSystem(name, Demultiplexer(list(sizes.values())))
    builder.Connect(port, demux.get_input_port())
    return {part: demux.get_output_port(k) for k, part in enumerate(sizes)}


def _add_desired_null_space(builder, terms, config, normal, model, model_terms):
    """Criteria → priority selector (or a prescribed sweep) → q̇_dⁿ; returns its port and
    the diagnostic ports to export."""
    n = model.n
    terms_port = terms.GetOutputPort("robot_terms")
    criteria = {
        c: system.GetOutputPort("criterion")
        for c, system in _add_criteria(builder, terms_port, config, normal, model, model_terms).items()
    }
    # No obstacle geometry (d_min = ∞), no joint limits (margin = ∞): the criterion's
    # constant value, without a system to evaluate at every tick.
    for c in (Criterion.obstacle, Criterion.joint_limits):
        if c not in criteria:
            criteria[c] = builder.AddNamedSystem(
                f"no_{c.value}", ConstantVectorSource(pack_criterion(np.zeros(n), 0.0, np.inf, 0.0))
            ).get_output_port()
    selector = _add_selector(builder, config, model, model_terms)
    builder.Connect(terms_port, selector.GetInputPort("robot_terms"))
    parts = {}
    for c, port in criteria.items():
        builder.Connect(port, selector.GetInputPort(c.value))
        parts[c] = _split(builder, f"{c.value}_parts", port, criterion_parts(n))
    selection = _split(
        builder, "selection_parts", selector.GetOutputPort("selection"), selector.output_parts()
    )
    diagnostics = {
        "mode": selection["mode"],
        "speed_scale": selection["speed_scale"],
        "manipulability": parts[Criterion.manipulability]["value"],
        "joint_torque_criterion": parts[Criterion.joint_torque]["value"],
        "joint_limits_criterion": parts[Criterion.joint_limits]["value"],
        "joint_limit_margin": parts[Criterion.joint_limits]["switching"],
        "d_min": parts[Criterion.obstacle]["switching"],
        "obstacle_potential": parts[Criterion.obstacle]["value"],
    }
    if config.desired_null_space.source != "sweep":
        return selection["desired_null_space_velocity"], diagnostics
    sweep = _add_sweep(builder, config, model, model_terms)
    builder.Connect(terms_port, sweep.get_input_port())
    return sweep.get_output_port(), diagnostics


def _add_selector(builder, config, model, model_terms) -> PrioritySelector:
    d = config.desired_null_space
    sel = d.selector
    return builder.AddNamedSystem(
        "priority_selector",
        PrioritySelector(
            inverse=generalized_inverse(config),
            gains={
                Criterion.obstacle: d.criteria.obstacle.gain,
                Criterion.joint_torque: d.criteria.joint_torque.gain,
                Criterion.manipulability: d.criteria.manipulability.gain,
                Criterion.joint_limits: d.criteria.joint_limits.gain,
            },
            limits=SelectorLimits(
                d_lim=sel.d_lim,
                w_lim=sel.w_lim,
                d_band=sel.d_band,
                w_band=sel.w_band,
                q_lim=sel.q_lim,
                q_band=sel.q_band,
            ),
            blend_time=sel.blend_time,
            rotate_gradient=d.rotate_gradient,
            speed_limits=speed_limits(config, model),
            speed_headroom=d.speed_headroom,
            period=config.period,
            model_terms=model_terms,
        ),
    )


def _add_sweep(builder, config, model, model_terms) -> SelfMotionSweep:
    """A prescribed self-motion in place of the selector's q̇_dⁿ (``source: sweep``)."""
    sw = config.desired_null_space.sweep
    return builder.AddNamedSystem(
        "self_motion_sweep",
        SelfMotionSweep(
            inverse=generalized_inverse(config),
            direction=np.array([sw.direction.get(j, 0.0) for j in model.joint_names]),
            amplitude=sw.amplitude,
            frequency=sw.frequency,
            start_time=sw.start_time,
            ramp_time=sw.ramp_time,
            model_terms=model_terms,
        ),
    )


def _add_actuator_limits(builder, impedance, null_space_torque, config, model) -> dict:
    """τ = τ_task + s τ₀ within the actuator limits; returns the generalized_force and
    saturation ports."""
    rates = config.actuator_limits.torque_rate
    limits = builder.AddNamedSystem(
        "actuator_limits",
        ActuatorLimitsSystem(
            torque_limits=torque_limits(config, model),
            rate_limits=np.array([rates.get(j, np.inf) for j in model.joint_names]),
            period=config.period,
        ),
    )
    builder.Connect(impedance.get_output_port(), limits.GetInputPort("task_torque"))
    builder.Connect(null_space_torque, limits.GetInputPort("null_space_torque"))
    return _split(builder, "limited_parts", limits.GetOutputPort("limited"), limits.output_parts())


def _add_null_space(builder, terms, qdot_ns, config, model_terms) -> dict:
    """The null-space controller; returns its τ₀, eⁿ and ν ports."""
    ns = config.null_space
    null_space = builder.AddNamedSystem(
        "null_space_controller",
        NullSpaceController(
            inverse=generalized_inverse(config),
            K_n=ns.K_n,
            period=config.period,
            task_velocity_compensation=ns.task_velocity_compensation,
            coriolis_compensation=ns.coriolis_compensation,
            acceleration_feedforward=ns.acceleration_feedforward,
            model_terms=model_terms,
        ),
    )
    builder.Connect(terms.GetOutputPort("robot_terms"), null_space.GetInputPort("robot_terms"))
    builder.Connect(qdot_ns, null_space.GetInputPort("desired_null_space_velocity"))
    return _split(
        builder, "null_space_parts", null_space.GetOutputPort("null_space"), null_space.output_parts()
    )
