"""The simulated driver: the scenario's station behind a Franka Panda's LCM interface.

::

    command (fixed for the period) ─► τ_cmd ─────────────────────────────────────────┐
    gravity (g(q) of the robot's own model, when the robot adds it) ─────────────────┤
                                                      applied_torque = τ_cmd + g ─► station.actuation
    station: plant, table on its sensor, post
    at each t_k, read off the diagram's ports and encoded in place (nsdrake/driver/wire.py):
      lcmt_panda_status: q, q̇, τ_cmd, applied, τ_ext = −(generalized contact forces on the arm)
      lcmt_force_torque: the sensor's wrench

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
wrench (the exact external torque: a perfect estimator), with the fields Drake's
``PandaStatusSender`` fills (the others zero, ``utime`` the simulation's time). It
publishes at the driver's 1 kHz (the scenario's control period), and the plant steps once
per period.

**What it costs the PC** (issue 44): the diagram holds only what the physics needs and the
systems whose outputs the messages carry; the command is an input port fixed once a period
(no LCM subscriber, receiver, sender or publisher systems in the diagram, whose events
ran every period), the messages are encoded in place from the ports' values, and the
loggers are rows this class records only where a caller reads them (``record``: the
lockstep drive's ground truth). The physics is the same plant, contact model and step as
the Drake diagram of LCM systems it replaces: tests/driver/test_stand_in.py drives both
with the same commands and compares every state and every message bit for bit.

**Lockstep.** Before each plant step the driver takes the command that answers the
status it published last; the torque computed from the state at t_k acts over
[t_k, t_{k+1}), as in the direct simulation. (A real Panda behind drake-franka-driver
applies the latest command at its next 1 kHz callback, one period later: docs/real_arm.md.)
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.analysis import Simulator
from pydrake.systems.controllers import InverseDynamics
from pydrake.systems.framework import Diagram, DiagramBuilder
from pydrake.systems.primitives import Adder, MatrixGain

from nsdrake.driver.panda import NUM_JOINTS
from nsdrake.driver.rows import Rows
from nsdrake.driver.wire import ForceTorqueWriter, StatusWriter, command_torque
from nsdrake.experiment.diagram import controller_model
from nsdrake.experiment.scenario import Scenario
from nsdrake.experiment.scenario_station import add_scenario_station
from nsdrake.station.plant import Station

LOGS = ("wrench", "forbidden_contacts", "state", "applied")  # what record=True keeps (logs())


@dataclass
class SimulatedDriverDiagram:
    diagram: Diagram
    station: Station
    # the ports each period reads: the commanded torque's input (fixed), and the outputs of
    # "applied" (the torque the plant applies: τ_cmd, + g(q) when the robot adds it),
    # "contact" (the generalized contact forces on the arm) and, for the logs,
    # "net_joint_torque" (B u: the joint torque the plant applied over its last step)
    command: object
    outputs: dict
    # the model whose g(q) the robot adds (a ControllerModel: held, its plant is the gravity's)
    robot_model: object | None = None


def _robot_torque(builder, station, robot_model):
    """(the command's input port, the torque the simulated robot applies): the command,
    plus g(q) of ``robot_model`` (a plant of the arm alone, the robot's own model; None:
    the robot adds no gravity)."""
    if robot_model is None:
        return station.ports.actuation, None
    gravity = builder.AddNamedSystem(
        "gravity", InverseDynamics(robot_model, InverseDynamics.InverseDynamicsMode.kGravityCompensation)
    )
    builder.Connect(station.ports.state, gravity.get_input_port_estimated_state())
    adder = builder.AddNamedSystem("applied_torque", Adder(2, NUM_JOINTS))
    builder.Connect(gravity.get_output_port_generalized_force(), adder.get_input_port(1))
    builder.Connect(adder.get_output_port(), station.ports.actuation)
    return adder.get_input_port(0), adder.get_output_port()


def build_simulated_driver(scenario: Scenario, *, adds_gravity: bool = True) -> SimulatedDriverDiagram:
    """The simulated driver's diagram (module docstring). ``adds_gravity``: the robot adds
    g(q) to every command (Franka's torque interface does, of its own model: the module
    docstring); False applies the command alone."""
    builder = DiagramBuilder()
    station = add_scenario_station(builder, scenario)
    plant = station.plant
    robot_model = controller_model(scenario, station) if adds_gravity else None
    command, applied = _robot_torque(builder, station, robot_model and robot_model.plant)
    builder.ExportInput(command, "command")
    joint_torque = builder.AddNamedSystem("net_joint_torque", MatrixGain(plant.MakeActuationMatrix()))
    builder.Connect(plant.get_net_actuation_output_port(), joint_torque.get_input_port())
    diagram = builder.Build()
    diagram.set_name("simulated_driver")
    outputs = {
        "applied": applied,  # None: the command itself
        "contact": plant.get_generalized_contact_forces_output_port(station.arm),
        "net_joint_torque": joint_torque.get_output_port(),
    }
    return SimulatedDriverDiagram(
        diagram=diagram,
        station=station,
        command=diagram.get_input_port(0),
        outputs=outputs,
        robot_model=robot_model,
    )


class SimulatedDriver:
    """Runs the simulated driver one period at a time (lockstep, module docstring).

    ``start()`` publishes the status of t = 0 on ``lcm``; each ``step()`` takes the latest
    command received on ``lcm`` and advances the plant one period, which publishes the next
    status. ``realtime_rate`` > 0 paces the steps against the wall clock (1: the robot's
    real time); 0 runs as fast as the computer allows. ``lcm`` None: nothing is published or
    received (``nsdrake sim-driver`` takes :meth:`messages` and gives :meth:`apply_torque`
    itself). ``record``: each period's wrench, forbidden contacts, state and applied torque
    kept for :meth:`logs`.
    """

    def __init__(
        self,
        scenario: Scenario,
        lcm: DrakeLcmInterface | None,
        *,
        adds_gravity: bool = True,
        realtime_rate: float = 0.0,
        record: bool = True,
    ):
        self.scenario = scenario
        self.lcm = lcm
        self.period = scenario.control_period
        self.built = built = build_simulated_driver(scenario, adds_gravity=adds_gravity)
        self.simulator = Simulator(built.diagram)
        self.simulator.set_target_realtime_rate(realtime_rate)
        self.context = self.simulator.get_mutable_context()
        station = built.station
        plant_context = station.plant.GetMyMutableContextFromRoot(self.context)
        station.plant.SetPositions(plant_context, station.q0)
        station.plant.SetVelocities(plant_context, station.v0)
        self.torque = np.zeros(NUM_JOINTS)  # the command applied over the current period [N m]
        self._command = built.command.FixValue(self.context, self.torque)
        self._ports = self._reading_ports()
        self._status, self._force_torque = StatusWriter(), ForceTorqueWriter()
        self._received: bytes | None = None
        self._logs = None
        if record:
            n = station.plant.num_positions() + station.plant.num_velocities()
            capacity = int(round(scenario.duration / self.period)) + 2
            self._logs = Rows(
                {"wrench": 6, "forbidden_contacts": 1, "state": n, "applied": NUM_JOINTS}, capacity
            )
        if lcm is not None:
            d = scenario.driver
            self._channels = (d.status_channel, d.force_torque_channel)
            lcm.Subscribe(d.command_channel, self._on_command)
        self.steps = 0

    def _reading_ports(self) -> list:
        """(port, its system's context) for each value a period reads: [q; q̇], the applied
        torque (None: the command), the contact forces on the arm, the sensor's wrench, the
        contact monitor, the links' state, B u."""
        station, outputs = self.built.station, self.built.outputs
        ports = [
            station.ports.state, outputs["applied"], outputs["contact"], station.ports.wrench,
            station.monitor.get_output_port(), station.ports.link_state, outputs["net_joint_torque"],
        ]  # fmt: skip
        return [
            None if port is None else (port, port.get_system().GetMyContextFromRoot(self.context))
            for port in ports
        ]

    def _on_command(self, data: bytes) -> None:
        self._received = data

    @property
    def time(self) -> float:
        return self.context.get_time()

    def start(self) -> None:
        """Publishes the status (and the sensor's wrench) of t = 0 (without a bus, computes
        the sensor's wrench: its first evaluation loads the sensor's compiled kernel, 8.5 ms
        of CPU here, which must not fall in a period that ``nsdrake sim-driver`` times)."""
        self.simulator.Initialize()
        wrench, at = self._ports[3]
        wrench.Eval(at)
        self._sampled()

    def messages(self) -> tuple[bytes, bytes]:
        """The status and the sensor's lcmt_force_torque of the current time (module docstring)."""
        (state, at), applied, (contact, contact_at), (wrench, wrench_at) = self._ports[:4]
        x = state.Eval(at)
        torque = self.torque if applied is None else applied[0].Eval(applied[1])
        t = self.context.get_time()
        status = self._status.set(
            int(t * 1e6),
            x[:NUM_JOINTS],
            x[NUM_JOINTS:],
            torque,
            self.torque,
            np.negative(contact.Eval(contact_at)),
        )
        return status, self._force_torque.set(t, wrench.Eval(wrench_at))

    def _sampled(self) -> None:
        """The messages of the current time published, its logs recorded."""
        if self.lcm is not None:
            status, force_torque = self.messages()
            self.lcm.Publish(self._channels[0], status)
            self.lcm.Publish(self._channels[1], force_torque)
        if self._logs is not None:
            (wrench, wrench_at), (monitor, monitor_at), (links, links_at), (net, net_at) = (
                self._ports[3],
                self._ports[4],
                self._ports[5],
                self._ports[6],
            )
            self._logs.add(
                self.context.get_time(),
                {
                    "wrench": wrench.Eval(wrench_at),
                    "forbidden_contacts": monitor.Eval(monitor_at),
                    "state": links.Eval(links_at),
                    "applied": net.Eval(net_at),
                },
            )

    def step(self) -> None:
        """Takes the latest command on the bus, then advances one period (publishing the
        next status)."""
        self.lcm.HandleSubscriptions(0)
        if self._received is not None:
            torque = command_torque(self._received)
            if torque is None:
                raise ValueError(f"the simulated driver received {len(self._received)} bytes that are not a "
                                 f"torque command of {NUM_JOINTS} joints")  # fmt: skip
            self.apply_torque(torque)
            self._received = None
        self.advance()

    def apply_torque(self, torque: np.ndarray, utime: int = 0) -> None:
        """The torque command for the next period, given directly (``nsdrake sim-driver``
        chooses it itself: nsdrake/driver/serve.py). ``utime``: unused (the command's stamp)."""
        self.torque[:] = torque
        self._command.GetMutableData().get_mutable_value().SetFromVector(self.torque)  # dependents told

    def advance(self) -> None:
        """Advances one period (publishing the next status)."""
        self.steps += 1
        self.simulator.AdvanceTo(self.steps * self.period)
        self._sampled()

    def logs(self) -> dict:
        """{name: log} of :data:`LOGS` (``sample_times()``, ``data()``), one sample per period
        from t = 0; empty without ``record``."""
        return {} if self._logs is None else self._logs.logs()


def wait_for_command(lcm: DrakeLcmInterface, received, deadline: float) -> bool:
    """Handles LCM until ``received()`` is true or the wall clock (``time.perf_counter``)
    passes ``deadline``; whether it became true."""
    while not received():
        remaining = deadline - time.perf_counter()
        if remaining <= 0:
            return False
        lcm.HandleSubscriptions(max(1, int(np.ceil(remaining * 1e3))) if remaining > 1e-3 else 0)
    return True
