"""The simulated driver: the scenario's station behind a Franka Panda's LCM interface.

::

    command_subscriber ─► command_receiver (PandaCommandReceiver, torque) ─► τ_cmd ─┐
    gravity (g(q) of the robot's own model, when the robot adds it) ─────────────────┤
                                                      applied_torque = τ_cmd + g ─► station.actuation
    station: plant, table on its sensor, post
      state ─► q, q̇ ─► status_sender (PandaStatusSender) ─► status_publisher (every period)
      generalized contact forces on the arm ─► τ_ext = −(them) ─┘
      sensor wrench ─► force_torque_sender ─► force_torque_publisher (every period)

**The robot's gravity** is g(q) of the robot's own model, not of the physics: the arm and
the payload its load settings declare (Franka's end-effector and load settings in Desk or
libfranka's ``setLoad``, which its gravity compensation adds). The scenario's
``arm.payload`` with ``declared: true`` stands for a payload set there as well as told to
the controller; with ``declared: false`` neither knows it, and only the physics carries
it. So the model is the controller's own (:func:`nsdrake.experiment.diagram.controller_model`:
the arm's model file, the scenario's gravity, the payload when declared), and the
controller, which subtracts g(q) of that same model, subtracts exactly what the robot
adds (docs/real_arm.md, "Gravity"; ``tests/driver/test_payload_gravity.py``).

The status carries q, q̇, the last command (``joint_torque_desired``), the torque applied
(``joint_torque``) and τ_ext = Jᵀ W_T, the torque with which the arm holds the contact
wrench (the exact external torque: a perfect estimator). It publishes at the driver's
1 kHz (the scenario's control period), and the plant steps once per period.

**Lockstep.** Before each plant step the driver takes the command that answers the
status it published last; the torque computed from the state at t_k acts over
[t_k, t_{k+1}), as in the direct simulation. (A real Panda behind drake-franka-driver
applies the latest command at its next 1 kHz callback, one period later: docs/real_arm.md.)
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcmInterface
from pydrake.manipulation import PandaCommandReceiver, PandaControlMode, PandaStatusSender
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.lcm import LcmPublisherSystem, LcmSubscriberSystem
from pydrake.systems.primitives import Adder, Demultiplexer, Gain, MatrixGain, VectorLogSink

from nsdrake.driver.panda import NUM_JOINTS
from nsdrake.driver.wrench import ForceTorqueSender
from nsdrake.experiment.diagram import controller_model, log_signals
from nsdrake.experiment.scenario import Scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.station.plant import Station


@dataclass
class SimulatedDriverDiagram:
    diagram: Diagram
    station: Station
    command_subscriber: LcmSubscriberSystem
    # "wrench" (the sensor's), "forbidden_contacts", "state" (the links'), "applied" (the joint
    # torque the plant applied over the period that ends at the sample; zero at t = 0)
    loggers: dict[str, VectorLogSink]
    # the model whose g(q) the robot adds (a ControllerModel: held, its plant is the gravity's)
    robot_model: object | None = None


def _robot_torque(builder, station, receiver, robot_model):
    """The torque the simulated robot applies: the command, plus g(q) of ``robot_model`` (a
    plant of the arm alone, the robot's own model; None: the robot adds no gravity)."""
    applied = receiver.get_commanded_torque_output_port()
    if robot_model is None:
        return applied
    gravity = builder.AddNamedSystem(
        "gravity", InverseDynamics(robot_model, InverseDynamics.InverseDynamicsMode.kGravityCompensation)
    )
    builder.Connect(station.ports.state, gravity.get_input_port_estimated_state())
    adder = builder.AddNamedSystem("applied_torque", Adder(2, NUM_JOINTS))
    builder.Connect(applied, adder.get_input_port(0))
    builder.Connect(gravity.get_output_port_generalized_force(), adder.get_input_port(1))
    return adder.get_output_port()


def build_simulated_driver(
    scenario: Scenario, lcm: DrakeLcmInterface, *, adds_gravity: bool = True
) -> SimulatedDriverDiagram:
    """The simulated driver's diagram (module docstring) on ``lcm``, with the channels of
    ``scenario.driver``. ``adds_gravity``: the robot adds g(q) to every command (Franka's
    torque interface does, of its own model: the module docstring); False applies the
    command alone."""
    d, period = scenario.driver, scenario.control_period
    builder = DiagramBuilder()
    station = add_scenario_station(builder, scenario)
    plant = station.plant
    state = builder.AddNamedSystem("measured_state", Demultiplexer([NUM_JOINTS, NUM_JOINTS]))
    builder.Connect(station.ports.state, state.get_input_port())
    subscriber = builder.AddNamedSystem(
        "command_subscriber",
        LcmSubscriberSystem.Make(d.command_channel, lcmt_panda_command, lcm, use_cpp_serializer=True),
    )
    receiver = builder.AddNamedSystem(
        "command_receiver", PandaCommandReceiver(NUM_JOINTS, int(PandaControlMode.kTorque))
    )
    builder.Connect(subscriber.get_output_port(), receiver.get_message_input_port())
    builder.Connect(state.get_output_port(0), receiver.get_position_measured_input_port())
    robot_model = controller_model(scenario, station) if adds_gravity else None
    applied = _robot_torque(builder, station, receiver, robot_model and robot_model.plant)
    builder.Connect(applied, station.ports.actuation)
    external = builder.AddNamedSystem("torque_external", Gain(-1.0, NUM_JOINTS))
    builder.Connect(plant.get_generalized_contact_forces_output_port(station.arm), external.get_input_port())
    sender = builder.AddNamedSystem("status_sender", PandaStatusSender(NUM_JOINTS))
    builder.Connect(state.get_output_port(0), sender.get_position_measured_input_port())
    builder.Connect(state.get_output_port(1), sender.get_velocity_measured_input_port())
    builder.Connect(receiver.get_commanded_torque_output_port(), sender.get_torque_commanded_input_port())
    builder.Connect(applied, sender.get_torque_measured_input_port())
    builder.Connect(external.get_output_port(), sender.get_torque_external_input_port())
    status_port = sender.get_output_port()
    _publish(builder, "status_publisher", status_port, d.status_channel, lcmt_panda_status, lcm, period)
    ft = builder.AddNamedSystem("force_torque_sender", ForceTorqueSender())
    builder.Connect(station.ports.wrench, ft.get_input_port())
    ft_port, ft_channel = ft.get_output_port(), d.force_torque_channel
    _publish(builder, "force_torque_publisher", ft_port, ft_channel, lcmt_force_torque, lcm, period)
    loggers = log_signals(
        builder,
        {
            "wrench": station.ports.wrench,
            "forbidden_contacts": station.monitor.get_output_port(),
            "state": station.ports.link_state,
            "applied": _net_joint_torque(builder, plant),
        },
        period,
    )
    diagram = builder.Build()
    diagram.set_name("simulated_driver")
    return SimulatedDriverDiagram(
        diagram=diagram,
        station=station,
        command_subscriber=subscriber,
        loggers=loggers,
        robot_model=robot_model,
    )


def _net_joint_torque(builder, plant):
    """The joint torque B u the plant applied over its last step (its sampled net actuation)."""
    joint_torque = builder.AddNamedSystem("net_joint_torque", MatrixGain(plant.MakeActuationMatrix()))
    builder.Connect(plant.get_net_actuation_output_port(), joint_torque.get_input_port())
    return joint_torque.get_output_port()


def _publish(builder, name, port, channel, lcm_type, lcm, period):
    """``port`` published on ``channel`` once per ``period``."""
    publisher = LcmPublisherSystem.Make(
        channel, lcm_type, lcm, publish_period=period, use_cpp_serializer=True
    )
    builder.AddNamedSystem(name, publisher)
    builder.Connect(port, publisher.get_input_port())


class SimulatedDriver:
    """Runs the simulated driver one period at a time (lockstep, module docstring).

    ``start()`` publishes the status of t = 0; each ``step()`` takes the latest command
    received on ``lcm`` and advances the plant one period, which publishes the next
    status. ``realtime_rate`` > 0 paces the steps against the wall clock (1: the robot's
    real time); 0 runs as fast as the computer allows.
    """

    def __init__(
        self,
        scenario: Scenario,
        lcm: DrakeLcmInterface,
        *,
        adds_gravity: bool = True,
        realtime_rate: float = 0.0,
    ):
        self.scenario = scenario
        self.lcm = lcm
        self.period = scenario.control_period
        self.built = build_simulated_driver(scenario, lcm, adds_gravity=adds_gravity)
        self.simulator = Simulator(self.built.diagram)
        self.simulator.set_target_realtime_rate(realtime_rate)
        self.context = self.simulator.get_mutable_context()
        station = self.built.station
        plant_context = station.plant.GetMyMutableContextFromRoot(self.context)
        station.plant.SetPositions(plant_context, station.q0)
        station.plant.SetVelocities(plant_context, station.v0)
        self._subscriber_context = self.built.command_subscriber.GetMyMutableContextFromRoot(self.context)
        self.steps = 0

    @property
    def time(self) -> float:
        return self.context.get_time()

    def start(self) -> None:
        """Publishes the status (and the sensor's wrench) of t = 0."""
        self.simulator.Initialize()

    def step(self) -> None:
        """Takes the latest command on the bus, then advances one period (publishing the
        next status)."""
        self.lcm.HandleSubscriptions(0)
        self.built.command_subscriber.ExecuteForcedEvents(self._subscriber_context, True)
        self.advance()

    def apply_torque(self, torque: np.ndarray, utime: int = 0) -> None:
        """The torque command for the next period, given directly (``nsdrake sim-driver``
        chooses it itself: nsdrake/driver/serve.py): a command message on this driver's
        bus, taken at once."""
        command = lcmt_panda_command()
        command.utime, command.control_mode_expected = utime, lcmt_panda_status.CONTROL_MODE_TORQUE
        command.num_joint_torque, command.joint_torque = NUM_JOINTS, [float(x) for x in torque]
        self.lcm.Publish(self.scenario.driver.command_channel, command.encode())
        self.lcm.HandleSubscriptions(0)
        self.built.command_subscriber.ExecuteForcedEvents(self._subscriber_context, True)

    def advance(self) -> None:
        """Advances one period (publishing the next status)."""
        self.steps += 1
        self.simulator.AdvanceTo(self.steps * self.period)

    def logs(self) -> dict:
        return {name: logger.FindLog(self.context) for name, logger in self.built.loggers.items()}


def wait_for_command(lcm: DrakeLcmInterface, received, deadline: float) -> bool:
    """Handles LCM until ``received()`` is true or the wall clock (``time.perf_counter``)
    passes ``deadline``; whether it became true."""
    while not received():
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            return False
        lcm.HandleSubscriptions(max(1, int(np.ceil(remaining * 1e3))) if remaining > 1e-3 else 0)
    return True
