"""The controller side's loop: one command per status, driven by the robot's messages.

Why a loop on ``DrakeLcm.HandleSubscriptions`` and not a Drake ``Simulator`` paced with
``set_target_realtime_rate(1)`` and an ``LcmInterfaceSystem``: the robot owns the clock.
A paced simulator advances on the controller's own clock and looks for messages only
when it takes a step, so a status waits up to a step before it is seen, the controller's
periodic events drift against the robot's ticks (two updates for one status, or none),
and a publisher on the controller's clock answers no status in particular. Drake's own
controller example (``examples/kuka_iiwa_arm/iiwa_controller.cc``) does what this loop
does: block until a status arrives, set the diagram's time from it, advance, and force
the command's publish. Here each status k:

1. arrives (``HandleSubscriptions``; the time of arrival starts the tick's clock) and is
   checked (:mod:`nsdrake.driver.faults`); a refused status ends the run before it
   reaches the diagram;
2. is taken into the status subscriber (its forced update), as the force-torque message;
3. the diagram advances to t_k = t_{k−1} + (periods between the two statuses' utime) T:
   the periodic updates of t_{k−1} run, the measurement hold samples status k
   (:class:`nsdrake.driver.systems.MeasurementHold` says why that order);
4. the command publisher is forced: one command, stamped with status k's utime.

A fault (:class:`DriveFaultError`) stops commanding at once: nothing is sent after it.
"""

from __future__ import annotations

import time

import numpy as np
from drake import lcmt_panda_status
from pydrake.lcm import DrakeLcmInterface
from pydrake.systems.analysis import Simulator

from nsdrake.driver.controller_side import DriveDiagram
from nsdrake.driver.faults import clock_steps, jump_problem, start_problem, status_problem
from nsdrake.driver.panda import NUM_JOINTS
from nsdrake.driver.stop import StopRequest
from nsdrake.driver.timing import TickTimes


class DriveFaultError(RuntimeError):
    """The controller stopped commanding; the message is one line saying why."""

    def __init__(self, t: float | None, problem: str, commands: int):
        self.t, self.problem, self.commands = t, problem, commands
        where = "before the first command" if t is None else f"at t = {t:.3f} s"
        super().__init__(f"{where}: {problem}; stopped commanding after {commands} command(s)")


class DriveInterruptedError(DriveFaultError):
    """Ctrl-C stopped the controller (:mod:`nsdrake.driver.stop`): nothing was sent after it."""

    def __init__(self, t: float | None, commands: int):
        super().__init__(t, "interrupted (Ctrl-C)", commands)


def warm_up(drive: DriveDiagram) -> None:
    """Evaluates every output of the controller once at the scenario's start pose, in a
    context of its own: the first evaluation in a process loads the compiled kernels from
    numba's cache (about 0.1 s for the Panda's), which must not happen inside the first
    tick, where the driver's command deadline runs."""
    controller = drive.controller
    context = controller.CreateDefaultContext()
    station = drive.station
    for i in range(controller.num_input_ports()):
        controller.get_input_port(i).FixValue(context, np.zeros(controller.get_input_port(i).size()))
    controller.GetInputPort("estimated_state").FixValue(context, np.concatenate([station.q0, station.v0]))
    if controller.HasInputPort("desired_orientation"):
        controller.GetInputPort("desired_orientation").FixValue(context, np.array([1.0, 0.0, 0.0, 0.0]))
    for i in range(controller.num_output_ports()):
        controller.get_output_port(i).Eval(context)


class ControllerLoop:
    """Runs a :class:`nsdrake.driver.controller_side.DriveDiagram` on ``lcm`` (module docstring).

    ``start()`` waits for the first status and answers it; each ``tick()`` answers the
    next; ``run(duration)`` does both until the controller's clock reaches ``duration``.
    ``times`` holds each tick's compute time from the status's arrival to the command's
    publish [s], wall clock and the thread's CPU time; ``commands`` counts the commands sent.
    """

    def __init__(self, drive: DriveDiagram, lcm: DrakeLcmInterface, *, capacity: int = 0):
        self.drive = drive
        self.lcm = lcm
        scenario = drive.scenario
        self.config = scenario.driver
        self.period = scenario.control_period
        self.simulator = Simulator(drive.diagram)
        self.context = self.simulator.get_mutable_context()
        self.commands = 0
        self.periods = 0  # control periods since the first status: the clock is periods × T, never a sum
        self.skipped = 0  # statuses that arrived while the controller was busy, superseded by a newer one
        self.times = TickTimes(capacity or int(round(scenario.duration / self.period)) + 2)
        self._names = drive.station.arm_model.joint_names
        self._inbox: list[tuple[float, float, bytes]] = []  # (arrival, CPU clock, message) since last tick
        self._arrival_cpu = 0.0  # the thread's CPU clock when the status being answered arrived
        self._force_torque_messages = 0
        self._statuses_since_force_torque = 0
        self._last: lcmt_panda_status | None = None
        self._last_arrival = 0.0
        self._subscriptions = [lcm.Subscribe(self.config.status_channel, self._on_status)]
        if drive.force_torque_subscriber is not None:
            self._subscriptions.append(lcm.Subscribe(self.config.force_torque_channel, self._on_force_torque))
        self._absorb = [
            (system, system.GetMyMutableContextFromRoot(self.context))
            for system in (drive.status_subscriber, drive.force_torque_subscriber)
            if system is not None
        ]
        self._publisher_context = drive.command_publisher.GetMyContextFromRoot(self.context)
        self.stop = StopRequest()  # Ctrl-C's flag, read at each status (Drive.run sets it)
        warm_up(drive)

    @property
    def time(self) -> float:
        return self.context.get_time()

    def _on_status(self, data: bytes) -> None:
        self._inbox.append((time.perf_counter(), time.thread_time(), data))

    def _on_force_torque(self, data: bytes) -> None:
        self._force_torque_messages += 1

    def _check_stop(self, started: bool = True) -> None:
        if self.stop.requested:
            raise DriveInterruptedError(self.time if started else None, self.commands)

    def _fault(self, problem: str, started: bool = True) -> DriveFaultError:
        return DriveFaultError(self.time if started else None, problem, self.commands)

    def start(self) -> None:
        """Waits (up to ``driver.first_status_timeout``) for the first status, checks it
        against the scenario's start pose, and answers it. DriveFaultError otherwise."""
        c = self.config
        deadline = time.perf_counter() + c.first_status_timeout
        while not self._inbox or (self._needs_force_torque() and time.perf_counter() < deadline):
            self._check_stop(started=False)
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                raise self._fault(self._silence_at_start(), started=False)
            self.lcm.HandleSubscriptions(max(1, min(100, int(remaining * 1e3))))
        self._check_stop(started=False)
        arrival, status = self._newest_status()
        problem = status_problem(status, NUM_JOINTS)
        q = np.asarray(status.joint_position)
        problem = problem or start_problem(q, self.drive.station.q0, c.start_tolerance, self._names)
        if problem:
            raise self._fault(f"first status refused: {problem}", started=False)
        if self._needs_force_torque():
            raise self._fault(self._silence_at_start(), started=False)
        self._absorb_messages()
        hold, hold_context = self.drive.hold, self.drive.hold.GetMyMutableContextFromRoot(self.context)
        hold.set_held(hold_context, hold.get_input_port().Eval(hold_context))
        self.simulator.Initialize()
        self._last, self._last_arrival = status, arrival
        self._command(arrival)

    def tick(self) -> None:
        """Waits (up to ``driver.status_timeout_periods``) for the next status and answers
        it. DriveFaultError for a silence, a refused status or a silent force-torque sensor."""
        if not self._inbox:
            self.lcm.HandleSubscriptions(0)
        deadline = self._last_arrival + self.config.status_timeout_periods * self.period
        while not self._inbox:
            self._check_stop()
            remaining = deadline - time.perf_counter()
            if remaining <= 0:
                raise self._fault(
                    f"no lcmt_panda_status on {self.config.status_channel} for "
                    f"{(time.perf_counter() - self._last_arrival) * 1e3:.1f} ms "
                    f"(driver.status_timeout_periods {self.config.status_timeout_periods:g} periods)"
                )
            self.lcm.HandleSubscriptions(1 if remaining > 1e-3 else 0)
        self.lcm.HandleSubscriptions(0)  # the force-torque message of the same instant, if queued
        self._check_stop()
        arrival, status = self._newest_status()
        steps = self._check(status)
        self._absorb_messages()
        self.periods += steps
        self.simulator.AdvanceTo(self.periods * self.period)
        self._last, self._last_arrival = status, arrival
        self._command(arrival)

    def run(self, duration: float, progress=None) -> None:
        """start(), then tick() until the controller's clock reaches ``duration`` [s]."""
        self.start()
        while self.time < duration - 0.5 * self.period:
            self.tick()
            if progress is not None and self.commands % 1000 == 0:
                progress(min(1.0, self.time / duration))

    def _check(self, status: lcmt_panda_status) -> int:
        """The periods since the last status, or DriveFaultError for a status to refuse."""
        problem = status_problem(status, NUM_JOINTS)
        if problem:
            raise self._fault(f"status refused: {problem}")
        steps = clock_steps(status.utime, self._last.utime, self.period)
        if steps is None:
            raise self._fault(
                f"status refused: its utime {status.utime} µs did not advance from {self._last.utime} µs"
            )
        problem = jump_problem(
            status.joint_position, self._last.joint_position, self.config.max_joint_step, steps, self._names
        )
        if problem:
            raise self._fault(f"status refused: {problem}")
        if self.drive.force_torque_subscriber is not None:
            if self._force_torque_messages:
                self._statuses_since_force_torque = 0
            else:
                self._statuses_since_force_torque += steps
            if self._statuses_since_force_torque > self.config.status_timeout_periods:
                raise self._fault(
                    f"no lcmt_force_torque on {self.config.force_torque_channel} for "
                    f"{self._statuses_since_force_torque} periods (driver.status_timeout_periods "
                    f"{self.config.status_timeout_periods:g})"
                )
        return steps

    def _newest_status(self) -> tuple[float, lcmt_panda_status]:
        """The newest status received (older ones counted as skipped) and its arrival time."""
        arrival, self._arrival_cpu, data = self._inbox[-1]
        self.skipped += len(self._inbox) - 1
        self._inbox.clear()
        return arrival, lcmt_panda_status.decode(data)

    def _needs_force_torque(self) -> bool:
        return self.drive.force_torque_subscriber is not None and self._force_torque_messages == 0

    def _silence_at_start(self) -> str:
        c = self.config
        if not self._inbox:
            return (
                f"no lcmt_panda_status on {c.status_channel} within {c.first_status_timeout:g} s; "
                "nothing was sent"
            )
        return (
            f"no lcmt_force_torque on {c.force_torque_channel} within {c.first_status_timeout:g} s "
            "(driver.force_source: sensor); nothing was sent"
        )

    def _absorb_messages(self) -> None:
        """The latest status and force-torque message into their subscribers' state."""
        for system, context in self._absorb:
            system.ExecuteForcedEvents(context, True)
        self._force_torque_messages = 0

    def _command(self, arrival: float) -> None:
        self.drive.command_publisher.ForcedPublish(self._publisher_context)
        self.commands += 1
        self.times.record(time.perf_counter() - arrival, time.thread_time() - self._arrival_cpu)
