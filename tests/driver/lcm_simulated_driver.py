"""The simulated driver as it was before issue 44 (nsdrake/driver/simulated_driver.py at
6395e08): the station inside a Drake diagram of LCM systems (a subscriber and Drake's
PandaCommandReceiver for the command, Drake's PandaStatusSender and publishers for the
status and the sensor's message, loggers), advanced by a Simulator. The reference the lean
driver is compared with, bit for bit (tests/driver/test_stand_in.py), and measured against
(bench/bench_stand_in.py). Kept for those only; not part of nsdrake.
"""

from __future__ import annotations

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
class LcmSimulatedDriverDiagram:
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


def build_lcm_simulated_driver(
    scenario: Scenario, lcm: DrakeLcmInterface, *, adds_gravity: bool = True
) -> LcmSimulatedDriverDiagram:
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
    return LcmSimulatedDriverDiagram(
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


class LcmSimulatedDriver:
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
        self.built = build_lcm_simulated_driver(scenario, lcm, adds_gravity=adds_gravity)
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
