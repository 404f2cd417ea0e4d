"""Assembly: a scenario flows one way through the diagram it builds::

    scenario ─► station (plant, plate on its sensor, contact monitor, actuation map)
             ─► realism rungs plugged into the station's ports (nsdrake.realism.wiring)
             ─► reference (reads the station's wrench)
             ─► controller (station.ports.state, .wrench, the reference ─► .actuation)
             ─► loggers (once per control period)

    ┌──────────────── station ────────────────┐
    │ plant ──state───────────── ports.state ──┼──► controller.estimated_state
    │   ▲  └─reaction_forces─► force_sensor ───┼──► controller.measured_wrench
    │   │                       ports.wrench ──┼──► reference.measured_wrench
    │   └── actuation ◄─ actuation_map ◄───────┼─── controller.generalized_force
    └─────────────────────────────────────────┘
    reference ─► controller.desired_position / _velocity / _acceleration / _force
    orientation_reference ─► controller.desired_orientation / _angular_velocity /
                             _angular_acceleration  (pose tasks only)

The controller (:class:`nsdrake.NullSpaceImpedanceController`) is a diagram of its
own — robot_terms, impedance_controller, the criteria, priority_selector,
null_space_controller — built on its own model of the arm and of the obstacles,
never on the simulated plant. Every signal the traces need is logged once per
control period by a ``VectorLogSink``.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydrake.geometry import Meshcat
from pydrake.systems.framework import Diagram, DiagramBuilder, OutputPort
from pydrake.systems.primitives import (
    ConstantVectorSource,
    LogVectorOutput,
    VectorLogSink,
)

from nsdrake.control.config import ControllerConfig
from nsdrake.control.controller import (
    ControllerConfigError,
    NullSpaceImpedanceController,
    without_null_space_task,
)
from nsdrake.control.dynamics import ArmModel
from nsdrake.control.model import ControllerModel
from nsdrake.control.orientation import rotation_to_quaternion
from nsdrake.experiment.push import add_push, unknown_body_problem
from nsdrake.experiment.reference import CircleOnSurface, SlideAndPress
from nsdrake.experiment.reference_system import SurfaceReference
from nsdrake.experiment.scenario import Scenario, ScenarioError, controller_fields
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.realism.model_error import scale_urdf_masses
from nsdrake.realism.wiring import add_realism_loggers, plug_realism
from nsdrake.station.plant import (
    Station,
    desired_tool_orientation,
    has_joint_limits,
    initial_task_position,
    station_obstacles,
)
from nsdrake.station.visualization import Visualizers, add_visualizers, visualizer_period


@dataclass
class ControlledStation:
    """What :func:`build_diagram` returns."""

    diagram: Diagram
    station: Station
    controller: NullSpaceImpedanceController
    loggers: dict[str, VectorLogSink]
    scenario: Scenario
    visualizers: Visualizers | None = None  # when built with a Meshcat
    # Pose tasks: the desired tool orientation R_d (3, 3), held throughout; None otherwise.
    desired_orientation: np.ndarray | None = None

    def system(self, name: str):
        """The subsystem called ``name``, in the diagram or inside the controller."""
        if self.diagram.HasSubsystemNamed(name):
            return self.diagram.GetSubsystemByName(name)
        return self.controller.GetSubsystemByName(name)


def speed_limit_vector(scenario: Scenario, arm: ArmModel) -> np.ndarray:
    """Each joint's speed limit (velocity order): the scenario's, else the arm model's
    velocity limit (zero or none: unlimited), as the controller uses them. [rad/s]."""
    limits = scenario.desired_null_space.joint_speed_limits
    model = arm.plant.GetVelocityUpperLimits()
    return np.array(
        [limits.get(name, m if m > 0 else np.inf) for name, m in zip(arm.joint_names, model, strict=True)]
    )


def controller_config(scenario: Scenario, *, null_space_task: bool = True) -> ControllerConfig:
    """The controller's part of the scenario."""
    config = ControllerConfig(**controller_fields(scenario))
    return config if null_space_task else without_null_space_task(config)


def simulated_damping_time(scenario: Scenario, station: Station) -> float:
    """T_D [s], the time over which the controller's model takes the file's joint damping D to
    act on a held command (the inertia T_D D: :class:`nsdrake.control.dynamics.ArmModel`), for
    the station's simulated plant: it steps h = T / substeps per control period T and
    integrates the damping implicitly, so T_D = (T + h)/2: exactly h = T at one step per
    period, to first order in T D H⁻¹ with more."""
    return (scenario.control_period + station.plant.time_step()) / 2


def controller_model(
    scenario: Scenario, station: Station, damping_time: float | None = None
) -> ControllerModel:
    """The controller's own model: the arm's model file (its packages as the station's), the
    gravity of the scenario, the payload when it is declared, and the plate and obstacles
    where the station put them. With ``realism.model_error``, the URDF's link and tool
    masses (and inertias) scaled by (1 + mass_error). ``damping_time``: T_D of the model's
    joint damping (:class:`nsdrake.control.model.ControllerModel`); None: the simulated
    plant's (:func:`simulated_damping_time`); a real arm's is about half the period."""
    payload = station.payload if station.payload_declared else None
    common = dict(
        tool_frame=scenario.arm.tool_frame,
        task_axes=scenario.task.axes,
        gravity=station.gravity,
        obstacles=station_obstacles(station),
        payload=payload,
        damping_time=simulated_damping_time(scenario, station) if damping_time is None else damping_time,
    )
    if scenario.realism.model_error.enabled:
        text = scale_urdf_masses(
            Path(station.arm_file).read_text(), 1.0 + scenario.realism.model_error.mass_error
        )
        return ControllerModel.from_urdf(text, **common)
    arm = scenario.arm
    return ControllerModel.from_file(
        station.arm_file, packages=station.packages, joints=arm.joints or None, locked=arm.locked, **common
    )


def controller_structure(scenario: Scenario, auto: str = "systems") -> str:
    """ "systems" or "fused": the scenario's ``controller_structure``, with ``auto`` the
    command's default (nsdrake run: the named systems; compare and sweep: fused)."""
    return auto if scenario.controller_structure == "auto" else scenario.controller_structure


def build_controller(
    scenario: Scenario,
    station: Station,
    wrench_point,
    *,
    null_space_task: bool = True,
    structure: str = "systems",
) -> NullSpaceImpedanceController:
    """The scenario's controller, on its own model of the station's arm and obstacles;
    ``wrench_point`` is the point the measured moment is about (the sensor origin);
    ``structure`` "systems" or "fused" (:func:`controller_structure`)."""
    try:
        return NullSpaceImpedanceController(
            controller_model=controller_model(scenario, station),
            normal=station.normal,
            config=controller_config(scenario, null_space_task=null_space_task),
            wrench_point=wrench_point,
            fused=structure == "fused",
        )
    except ControllerConfigError as e:
        raise ScenarioError(f"{scenario.source or 'scenario'}: {e}") from None


# arm_reach's discs by what determines them: (URDF content hash, tool frame, task axes, samples).
_REACH: dict[tuple[str, str, tuple[str, ...], int], tuple[np.ndarray, float]] = {}


def arm_reach(station: Station, samples: int = 2000) -> tuple[np.ndarray, float]:
    """(centre, radius) on the task axes of the disc the tool point can reach: centred on
    the first joint, radius the farthest tool distance over seeded random poses within
    the joint limits (and the zero pose). [m].

    Computed once per arm model in a process (every run, compare variant and sweep run
    builds its diagrams in a process that may have built the same arm before): the disc
    depends only on the arm's kinematics and limits (the URDF's content), the tool frame
    and the task axes, which key the cache, and the sampling is seeded, so a cached disc
    is the one a new computation would give."""
    arm = station.arm_model
    key = (
        hashlib.sha256(Path(station.arm_file).read_bytes()).hexdigest(),
        arm.tool_frame.name(),
        arm.task_axes,
        samples,
    )
    if key not in _REACH:
        _REACH[key] = sampled_reach(arm, samples)
    centre, radius = _REACH[key]
    return centre.copy(), radius


def sampled_reach(arm: ArmModel, samples: int) -> tuple[np.ndarray, float]:
    """:func:`arm_reach`'s disc, computed: the zero pose and ``samples`` poses drawn with
    seed 0, uniform within the joint limits (±π where a joint has none)."""
    plant = arm.plant
    context = plant.CreateDefaultContext()
    lower = np.maximum(plant.GetPositionLowerLimits(), -np.pi)
    upper = np.minimum(plant.GetPositionUpperLimits(), np.pi)
    centre = arm.joints[0].frame_on_child().CalcPoseInWorld(context).translation()[arm.rows]
    rng = np.random.default_rng(0)
    farthest = 0.0
    for q in np.vstack([np.clip(np.zeros(arm.n), lower, upper), rng.uniform(lower, upper, (samples, arm.n))]):
        plant.SetPositions(context, q)
        farthest = max(farthest, float(np.linalg.norm(arm.task_position(context) - centre)))
    return centre, farthest


def surface_path(scenario: Scenario, station: Station):
    """The scenario's task path (a :class:`CircleOnSurface` or a :class:`SlideAndPress`)
    and the contact detection's settings (task_rows, contact_threshold, period,
    loss_time): what :class:`SurfaceReference` and the drive's plain reference
    (:class:`nsdrake.experiment.reference.PlainSurfaceReference`) are built from."""
    r = scenario.reference
    common = {
        "task_rows": station.arm_model.rows,
        "contact_threshold": r.contact_threshold,
        "period": scenario.control_period,
        "loss_time": r.loss_time,
    }
    if r.path == "circle":
        path = CircleOnSurface(
            x0=initial_task_position(station),
            tangent=station.tangent,
            normal=station.normal,
            radius=r.radius,
            laps=r.laps,
            speed=r.tangent_speed,
            start_angle=r.start_angle,
            delay=r.delay,
            approach_speed=r.approach_speed,
            blend_time=r.blend_time,
            force=r.force,
            force_ramp_time=r.force_ramp_time,
            max_overtravel=r.max_overtravel,
            touch_speed=r.touch_speed,
            slow_down_distance=r.slow_down_distance,
            stop_time=r.stop_time,
        )
    else:
        centre, reach = arm_reach(station)
        path = SlideAndPress(
            x0=initial_task_position(station),
            tangent=station.tangent,
            normal=station.normal,
            tangent_speed=r.tangent_speed,
            approach_speed=r.approach_speed,
            blend_time=r.blend_time,
            force=r.force,
            force_ramp_time=r.force_ramp_time,
            step_time=r.step_time if r.step_time > 0 else math.inf,
            step_force=r.step_force,
            max_overtravel=r.max_overtravel,
            touch_speed=r.touch_speed,
            slow_down_distance=r.slow_down_distance,
            stop_time=r.stop_time,
            centre=centre,
            reach=(1.0 - r.reach_margin) * reach,
        )
    return path, common


def add_reference(
    builder: DiagramBuilder, scenario: Scenario, station: Station, wrench: OutputPort | None = None
) -> SurfaceReference:
    """The task reference the scenario's ``reference.path`` names, fed by the station's
    measured wrench (or by ``wrench``)."""
    path, common = surface_path(scenario, station)
    reference = builder.AddNamedSystem("reference", SurfaceReference(reference=path, **common))
    builder.Connect(wrench or station.ports.wrench, reference.GetInputPort("measured_wrench"))
    return reference


def add_orientation_reference(builder, controller, R_d: np.ndarray) -> None:
    """A pose task's desired orientation R_d (held), zero desired angular velocity and
    acceleration, into the controller's rotational ports."""
    for name, port, value in (
        ("orientation_reference", "desired_orientation", rotation_to_quaternion(R_d)),
        ("angular_velocity_reference", "desired_angular_velocity", np.zeros(3)),
        ("angular_acceleration_reference", "desired_angular_acceleration", np.zeros(3)),
    ):
        source = builder.AddNamedSystem(name, ConstantVectorSource(value))
        builder.Connect(source.get_output_port(), controller.GetInputPort(port))


def connect_reference(builder, controller, reference) -> None:
    for port, ref in (
        ("desired_position", "x_d"),
        ("desired_velocity", "xdot_d"),
        ("desired_acceleration", "xddot_d"),
        ("desired_force", "f_d"),
    ):
        builder.Connect(reference.GetOutputPort(ref), controller.GetInputPort(port))


def add_loggers(builder, station, controller, reference, period) -> dict[str, VectorLogSink]:
    """The traces' signals, logged once per control period: the measured wrench and the
    link state from the station's ports, the reference, the controller's outputs."""
    signals = {
        "wrench": station.ports.wrench,
        "state": station.ports.link_state,
        "forbidden_contacts": station.monitor.get_output_port(),
    }
    signals.update(controller_signals(controller, reference, joint_limits=has_joint_limits(station)))
    return log_signals(builder, signals, period)


def controller_signals(controller, reference, *, joint_limits: bool) -> dict[str, OutputPort]:
    """The traces' signals that the reference and the controller give, by trace name."""
    signals = {
        "x_d": reference.GetOutputPort("x_d"),
        "f_d": reference.GetOutputPort("f_d"),
        "in_contact": reference.GetOutputPort("in_contact"),
    }
    for name, port in {
        "tau": "generalized_force",
        "qns": "desired_null_space_velocity",
        "mode": "mode",
        "speed_scale": "speed_scale",
        "w": "manipulability",
        "d_min": "d_min",
        "p_obstacle": "obstacle_potential",
        "en": "null_space_velocity_error",
        "nu": "lyapunov",
        "p_tau": "joint_torque_criterion",
        "saturation": "saturation",
    }.items():
        signals[name] = controller.GetOutputPort(port)
    if joint_limits:
        signals["p_joint_limits"] = controller.GetOutputPort("joint_limits_criterion")
    return signals


def log_signals(builder, signals: dict[str, OutputPort], period: float) -> dict[str, VectorLogSink]:
    """A logger named log_<name> on each port, sampling once per ``period``."""
    loggers = {}
    for name, port in signals.items():
        logger = LogVectorOutput(port, builder, publish_period=period)
        logger.set_name(f"log_{name}")
        loggers[name] = logger
    return loggers


def connect_controller(builder, station: Station, controller, reference) -> None:
    """The controller between the station's ports and the reference."""
    ports = station.ports
    builder.Connect(ports.state, controller.GetInputPort("estimated_state"))
    builder.Connect(ports.wrench, controller.GetInputPort("measured_wrench"))
    connect_reference(builder, controller, reference)
    builder.Connect(controller.GetOutputPort("generalized_force"), ports.actuation)


def build_diagram(
    scenario: Scenario,
    *,
    null_space_task: bool = True,
    meshcat: Meshcat | None = None,
    auto_structure: str = "systems",
) -> ControlledStation:
    """The Fig. 3 diagram for ``scenario``: station, reference, controller, loggers.

    ``null_space_task`` False sets every criterion gain and the sweep to zero
    (q̇_dⁿ = 0): the null-space controller then only damps self-motion. With a
    ``meshcat``, the diagram also has the Meshcat visualizers. The controller's
    structure is the scenario's ``controller_structure``, ``auto_structure`` ("systems"
    or "fused") when that is auto.
    """
    builder = DiagramBuilder()
    station = add_scenario_station(builder, scenario)
    if scenario.realism.any:
        plug_realism(builder, station, scenario.realism, scenario.control_period)
    reference = add_reference(builder, scenario, station)
    problem = unknown_body_problem(station.plant, scenario.push)
    if problem:
        raise ScenarioError(f"{scenario.source or 'scenario'}: push.body: {problem}")
    add_push(builder, station.plant, scenario.push)
    structure = controller_structure(scenario, auto_structure)
    controller = build_controller(
        scenario, station, station.sensor.p_WSo, null_space_task=null_space_task, structure=structure
    )
    builder.AddSystem(controller)
    connect_controller(builder, station, controller, reference)
    R_d = None
    if station.arm_model.m_r:
        R_d = desired_tool_orientation(station, scenario.reference.orientation)
        add_orientation_reference(builder, controller, R_d)
    loggers = add_loggers(builder, station, controller, reference, scenario.control_period)
    if scenario.report.null_space_torque:
        loggers.update(log_signals(builder, {"tau0": controller.GetOutputPort("null_space_torque")},
                                   scenario.control_period))  # fmt: skip
    if scenario.realism.any:
        loggers.update(add_realism_loggers(builder, station, scenario.control_period))
    visualizers = None
    if meshcat is not None:
        visualizers = add_visualizers(
            builder,
            station,
            meshcat,
            period=visualizer_period(scenario.control_period),
            camera=(scenario.report.camera_position, scenario.report.camera_target),
        )
    diagram = builder.Build()
    diagram.set_name("nsdrake")
    return ControlledStation(
        diagram=diagram,
        station=station,
        controller=controller,
        loggers=loggers,
        scenario=scenario,
        visualizers=visualizers,
        desired_orientation=R_d,
    )
