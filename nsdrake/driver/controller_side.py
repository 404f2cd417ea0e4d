"""The controller side of ``nsdrake drive``: the scenario's reference and controller
behind a Franka Panda's LCM driver, as one Drake Diagram.

::

    status_subscriber ─► status_receiver ─► position, velocity ─┐
      (lcmt_panda_status)  (PandaStatusReceiver)   torque_external ─► [wrench_estimator]
    [force_torque_subscriber ─► force_torque_receiver] ─► wrench ─┤
                                                                   ▼
                         measurement_hold ([q; q̇; W], sampled once per control period)
                           │ state ───────────────────► controller.estimated_state
                           │ wrench ──► reference ────► controller.desired_*
                           │        └─────────────────► controller.measured_wrench
                           ▼
    controller.generalized_force τ ─► command_torque = τ − g(q) (robot_adds_gravity)
      ─► command_sender (PandaCommandSender, torque) ─► command_stamp (the status's utime)
      ─► command_publisher (lcmt_panda_command, forced publish only)

Every LCM system is Drake's (``pydrake.systems.lcm``, ``pydrake.manipulation``).
:func:`build_drive_diagram` builds it for a user's own script;
:class:`nsdrake.driver.loop.ControllerLoop` runs it, one command per status.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcmInterface
from pydrake.manipulation import PandaCommandSender, PandaControlMode, PandaStatusReceiver
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import Diagram, DiagramBuilder, TriggerType
from pydrake.systems.lcm import LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import Adder, Gain, Multiplexer, VectorLogSink

from nsdrake.control.controller import NullSpaceImpedanceController
from nsdrake.driver.panda import NUM_JOINTS, PandaLimitError, panda_actuator_limits
from nsdrake.driver.systems import CommandStamp, MeasurementHold
from nsdrake.driver.wrench import ExternalWrenchEstimator, ForceTorqueReceiver
from nsdrake.experiment.checks import check_with_model
from nsdrake.experiment.diagram import (
    add_orientation_reference,
    add_reference,
    build_controller,
    connect_reference,
    controller_signals,
    controller_structure,
    log_signals,
)
from nsdrake.experiment.scenario import Scenario, ScenarioError
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.station.plant import Station, desired_tool_orientation, has_joint_limits


@dataclass
class DriveDiagram:
    """What :func:`build_drive_diagram` returns (``station``, ``controller``, ``loggers``,
    ``scenario`` and ``desired_orientation`` as :class:`nsdrake.experiment.diagram.ControlledStation`
    has them, so that the traces are collected the same way)."""

    diagram: Diagram
    scenario: Scenario  # with the Panda's published actuator limits filled in
    station: Station  # the scenario's station, never simulated here: the model's geometry
    station_diagram: Diagram  # the diagram holding ``station`` (a context of it for geometry queries)
    controller: NullSpaceImpedanceController
    hold: MeasurementHold
    status_subscriber: LcmSubscriberSystem
    force_torque_subscriber: LcmSubscriberSystem | None  # None: the wrench is estimated
    command_publisher: LcmPublisherSystem
    loggers: dict[str, VectorLogSink]
    desired_orientation: np.ndarray | None = None
    wrench_point: np.ndarray | None = None  # the point the measured moment is about; None: the tool


def drive_scenario(scenario: Scenario, station: Station) -> Scenario:
    """``scenario`` with the Panda's published torque and torque-rate limits wherever it
    gives none (:func:`nsdrake.driver.panda.panda_actuator_limits`); one-line ScenarioError
    for limits above them or an arm that is not a 7-joint one."""
    try:
        limits = panda_actuator_limits(scenario.actuator_limits, station.arm_model.joint_names)
    except PandaLimitError as e:
        raise ScenarioError(f"{scenario.source or 'scenario'}: {e}") from None
    return dataclasses.replace(scenario, actuator_limits=limits)


def add_controller(
    builder: DiagramBuilder, scenario: Scenario, station: Station, wrench_point
) -> NullSpaceImpedanceController:
    """The scenario's controller, on its own model of the arm and obstacles: the one place
    the controller side builds it: fused (one LeafSystem, the cheapest way to run the tick
    in a Diagram) unless the scenario's controller_structure asks for the named systems."""
    controller = build_controller(
        scenario, station, wrench_point, structure=controller_structure(scenario, "fused")
    )
    builder.AddSystem(controller)
    return controller


def build_drive_diagram(scenario: Scenario, lcm: DrakeLcmInterface) -> DriveDiagram:
    """The controller side for ``scenario`` on ``lcm`` (module docstring); the channels,
    the force source and the gravity setting come from ``scenario.driver``. Every problem
    with the scenario is a one-line ScenarioError, before anything listens or sends."""
    if scenario.realism.any:
        raise ScenarioError(
            f"{scenario.source or 'scenario'}: realism: nsdrake drive runs the controller against a robot "
            "(or the simulated driver, which models none of the realism rungs); turn them off"
        )
    station_builder = DiagramBuilder()
    station = add_scenario_station(station_builder, scenario)
    check_with_model(scenario, station)
    station_diagram = station_builder.Build()
    scenario = drive_scenario(scenario, station)
    d = scenario.driver
    builder = DiagramBuilder()
    status = builder.AddNamedSystem(
        "status_subscriber",
        LcmSubscriberSystem.Make(d.status_channel, lcmt_panda_status, lcm, use_cpp_serializer=True),
    )
    receiver = builder.AddNamedSystem("status_receiver", PandaStatusReceiver(NUM_JOINTS))
    builder.Connect(status.get_output_port(), receiver.get_input_port())
    sensor = d.force_source == "sensor"
    wrench_point = station.sensor.p_WSo if sensor else None
    controller = add_controller(builder, scenario, station, wrench_point)
    wrench, force_torque = _add_wrench_source(builder, scenario, lcm, receiver, controller)
    hold, state, held_wrench = _add_measurement_hold(builder, receiver, wrench, scenario.control_period)
    reference = add_reference(builder, scenario, station, wrench=held_wrench)
    builder.Connect(state, controller.GetInputPort("estimated_state"))
    builder.Connect(held_wrench, controller.GetInputPort("measured_wrench"))
    connect_reference(builder, controller, reference)
    R_d = None
    if station.arm_model.m_r:
        R_d = desired_tool_orientation(station, scenario.reference.orientation)
        add_orientation_reference(builder, controller, R_d)
    command = _add_command_torque(builder, controller, state, d.robot_adds_gravity)
    publisher = _add_command_path(builder, command, status, lcm, d.command_channel)
    signals = controller_signals(controller, reference, joint_limits=has_joint_limits(station))
    signals.update({"state": state, "wrench": held_wrench, "command": command})
    loggers = log_signals(builder, signals, scenario.control_period)
    diagram = builder.Build()
    diagram.set_name("nsdrake_drive")
    return DriveDiagram(
        diagram=diagram,
        scenario=scenario,
        station=station,
        station_diagram=station_diagram,
        controller=controller,
        hold=hold,
        status_subscriber=status,
        force_torque_subscriber=force_torque,
        command_publisher=publisher,
        loggers=loggers,
        desired_orientation=R_d,
        wrench_point=wrench_point,
    )


def _add_wrench_source(builder, scenario, lcm, receiver, controller):
    """The measured wrench's port and, for the sensor, its subscriber (else None)."""
    d = scenario.driver
    if d.force_source == "sensor":
        subscriber = LcmSubscriberSystem.Make(
            d.force_torque_channel, lcmt_force_torque, lcm, use_cpp_serializer=True
        )
        builder.AddNamedSystem("force_torque_subscriber", subscriber)
        ft = builder.AddNamedSystem("force_torque_receiver", ForceTorqueReceiver())
        builder.Connect(subscriber.get_output_port(), ft.get_input_port())
        return ft.GetOutputPort("wrench"), subscriber
    estimator = builder.AddNamedSystem("wrench_estimator", ExternalWrenchEstimator(model=controller.model))
    builder.Connect(receiver.get_position_measured_output_port(), estimator.GetInputPort("position_measured"))
    builder.Connect(receiver.get_torque_external_output_port(), estimator.GetInputPort("torque_external"))
    return estimator.GetOutputPort("wrench"), None


def _add_measurement_hold(builder, receiver, wrench, period):
    """[q; q̇; W] sampled and held (MeasurementHold); returns it and its state and wrench ports."""
    n = NUM_JOINTS
    measurements = builder.AddNamedSystem("measurements", Multiplexer([n, n, 6]))
    builder.Connect(receiver.get_position_measured_output_port(), measurements.get_input_port(0))
    builder.Connect(receiver.get_velocity_measured_output_port(), measurements.get_input_port(1))
    builder.Connect(wrench, measurements.get_input_port(2))
    hold = MeasurementHold(parts={"state": 2 * n, "wrench": 6}, period=period)
    builder.AddNamedSystem("measurement_hold", hold)
    builder.Connect(measurements.get_output_port(), hold.get_input_port())
    return hold, hold.GetOutputPort("state"), hold.GetOutputPort("wrench")


def _add_command_torque(builder, controller, state, robot_adds_gravity: bool):
    """The torque to send: τ − g(q) when the robot adds g itself, else τ. g is the
    controller model's (Drake's gravity compensation on the model's own plant)."""
    tau = controller.GetOutputPort("generalized_force")
    if not robot_adds_gravity:
        return tau
    gravity = builder.AddNamedSystem(
        "gravity",
        InverseDynamics(controller.model.plant, InverseDynamics.InverseDynamicsMode.kGravityCompensation),
    )
    builder.Connect(state, gravity.get_input_port_estimated_state())
    minus = builder.AddNamedSystem("minus_gravity", Gain(-1.0, NUM_JOINTS))
    builder.Connect(gravity.get_output_port_generalized_force(), minus.get_input_port())
    torque = builder.AddNamedSystem("command_torque", Adder(2, NUM_JOINTS))
    builder.Connect(tau, torque.get_input_port(0))
    builder.Connect(minus.get_output_port(), torque.get_input_port(1))
    return torque.get_output_port()


def _add_command_path(builder, torque, status, lcm, channel: str) -> LcmPublisherSystem:
    sender = builder.AddNamedSystem(
        "command_sender", PandaCommandSender(NUM_JOINTS, int(PandaControlMode.kTorque))
    )
    builder.Connect(torque, sender.get_torque_input_port())
    stamp = builder.AddNamedSystem("command_stamp", CommandStamp())
    builder.Connect(sender.get_output_port(), stamp.GetInputPort("lcmt_panda_command"))
    builder.Connect(status.get_output_port(), stamp.GetInputPort("lcmt_panda_status"))
    publisher = builder.AddNamedSystem(
        "command_publisher",
        LcmPublisherSystem.Make(
            channel,
            lcmt_panda_command,
            lcm,
            use_cpp_serializer=True,
            publish_triggers={TriggerType.kForced},
        ),
    )
    builder.Connect(stamp.get_output_port(), publisher.get_input_port())
    return publisher
