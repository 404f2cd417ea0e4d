"""Faults on the wire: each one stops the controller with one line, and nothing is sent
after it (issue 17, item 2). A scripted driver publishes the statuses over memq:// and
counts the commands that answer them."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcm

from nsdrake.driver.controller_side import build_drive_diagram
from nsdrake.driver.faults import clock_steps, jump_problem, start_problem, status_problem
from nsdrake.driver.loop import ControllerLoop, DriveFaultError
from nsdrake.experiment.scenario import load_scenario

NAMES = tuple(f"panda_joint{k}" for k in range(1, 8))


class ScriptedDriver:
    """Publishes statuses of a Panda at rest at q (1 kHz utime) and force-torque messages,
    and records every command on the bus."""

    def __init__(self, lcm: DrakeLcm, q0: np.ndarray, force_torque: bool = True):
        self.lcm, self.q = lcm, np.array(q0, dtype=float)
        self.utime = 1_700_000_000_000_000  # a wall clock's µs, as drake-franka-driver stamps them
        self.force_torque = force_torque
        self.commands: list[lcmt_panda_command] = []
        self._sub = lcm.Subscribe("PANDA_COMMAND", self._on_command)

    def _on_command(self, data: bytes) -> None:
        self.commands.append(lcmt_panda_command.decode(data))

    def publish(self, *, q=None, num_joints: int = 7, utime_step: int = 1000) -> int:
        """One status (and force-torque message); returns its utime."""
        self.utime += utime_step
        q = self.q if q is None else np.asarray(q, dtype=float)
        status = lcmt_panda_status()
        status.utime, status.num_joints = self.utime, num_joints
        for field in (
            "joint_position",
            "joint_position_desired",
            "joint_velocity",
            "joint_velocity_desired",
            "joint_acceleration_desired",
            "joint_torque",
            "joint_torque_desired",
            "joint_torque_external",
        ):
            setattr(status, field, list(q[:num_joints]) if field == "joint_position" else [0.0] * num_joints)
        self.lcm.Publish("PANDA_STATUS", status.encode())
        if self.force_torque:
            self.lcm.Publish("PANDA_FORCE_TORQUE", lcmt_force_torque().encode())
        return self.utime

    def received(self) -> int:
        self.lcm.HandleSubscriptions(0)
        return len(self.commands)


@pytest.fixture(scope="module")
def scenario():
    s = load_scenario("panda_wipe", duration=1.0)
    return dataclasses.replace(s, driver=dataclasses.replace(s.driver, first_status_timeout=0.3))


def start_loop(scenario, **driver_fields):
    s = dataclasses.replace(scenario, driver=dataclasses.replace(scenario.driver, **driver_fields))
    lcm = DrakeLcm("memq://")
    loop = ControllerLoop(build_drive_diagram(s, lcm), lcm)
    robot = ScriptedDriver(lcm, loop.drive.station.q0, force_torque=s.driver.force_source == "sensor")
    return loop, robot


def run_until_fault(loop, robot, fault_status) -> DriveFaultError:
    """Five good statuses answered one by one, then ``fault_status(robot)``: returns the
    fault, after checking that no command answered the refused status or came later."""
    robot.publish()
    loop.start()
    for _ in range(4):
        robot.publish()
        loop.tick()
    assert robot.received() == 5
    fault_status(robot)
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    for _ in range(3):  # the robot keeps talking; the stopped controller does not answer
        robot.publish()
    assert robot.received() == 5 and loop.commands == 5
    message = str(info.value)
    assert "\n" not in message and "stopped commanding after 5 command(s)" in message
    return info.value


def test_every_good_status_gets_one_command_with_its_utime(scenario):
    """Catches a command that does not answer its status (a stale utime, PandaCommandSender's
    context-time stamp, which a real driver drops as expired) or a second command per status."""
    loop, robot = start_loop(scenario)
    stamps = [robot.publish()]
    loop.start()
    for _ in range(9):
        stamps.append(robot.publish())
        loop.tick()
    assert robot.received() == 10
    assert [c.utime for c in robot.commands] == stamps
    command = robot.commands[-1]
    assert (command.num_joint_torque, command.num_joint_position, command.num_joint_velocity) == (7, 0, 0)
    assert command.control_mode_expected == lcmt_panda_status.CONTROL_MODE_TORQUE
    assert loop.time == pytest.approx(9 * scenario.control_period, abs=1e-15)
    wall, cpu = loop.times.seconds, loop.times.cpu_seconds  # each tick's, both clocks
    assert wall.size == 10 and np.all(cpu > 0.0) and np.all(cpu <= wall + 1e-5)  # one thread: CPU ≤ wall


def test_no_first_status_ends_without_sending(scenario):
    loop, robot = start_loop(scenario)
    with pytest.raises(DriveFaultError) as info:
        loop.start()
    assert str(info.value) == (
        "before the first command: no lcmt_panda_status on PANDA_STATUS within 0.3 s; nothing was sent; "
        "stopped commanding after 0 command(s)"
    )
    assert robot.received() == 0


def test_first_status_outside_the_start_tolerance_is_refused(scenario):
    loop, robot = start_loop(scenario)
    q = robot.q.copy()
    q[3] += 0.02  # start_tolerance 0.01 rad
    robot.publish(q=q)
    with pytest.raises(DriveFaultError) as info:
        loop.start()
    words = "first status refused: panda_joint4 is at -2.3800 rad, 0.0200 rad from the scenario's start"
    assert words in str(info.value)
    robot.publish()
    assert robot.received() == 0


def test_first_status_within_the_start_tolerance_is_taken(scenario):
    """The other side of the tolerance: 0.009 rad off starts (catches a check that refuses all)."""
    loop, robot = start_loop(scenario)
    robot.publish(q=robot.q + 0.009)
    loop.start()
    assert robot.received() == 1


@pytest.mark.parametrize("periods", [None, 20.0], ids=["default", "20 periods"])
def test_silence_once_running_stops_the_controller(scenario, periods):
    """The default wait is 3 periods (3 ms); 20 periods waits 20 ms, not 10 times more."""
    loop, robot = start_loop(scenario, **({} if periods is None else {"status_timeout_periods": periods}))
    fault = run_until_fault(loop, robot, lambda r: None)
    assert "no lcmt_panda_status on PANDA_STATUS for" in fault.problem
    expected = 3.0 if periods is None else periods
    assert f"(driver.status_timeout_periods {expected:g} periods)" in fault.problem
    waited_ms = float(fault.problem.split(" for ")[1].split(" ms")[0])
    assert expected <= waited_ms < expected + 40.0


@pytest.mark.parametrize(
    ("fault", "words"),
    [
        (lambda r: r.publish(q=np.where(np.arange(7) == 2, math.nan, r.q)), "joint_position[2] is nan"),
        (lambda r: r.publish(num_joints=6), "it has 6 joints, the arm has 7"),
        (lambda r: r.publish(q=r.q + np.where(np.arange(7) == 4, 0.05, 0.0)), "panda_joint5 moved 0.05 rad"),
        (lambda r: r.publish(utime_step=0), "did not advance"),
    ],
    ids=["nan", "joint count", "jump", "clock"],
)
def test_a_refused_status_stops_the_controller(scenario, fault, words):
    loop, robot = start_loop(scenario)
    error = run_until_fault(loop, robot, fault)
    assert error.problem.startswith("status refused: ") and words in error.problem, error.problem


def test_a_jump_within_the_elapsed_periods_is_taken(scenario):
    """0.015 rad over two periods (a status lost in between) is within 0.01 rad per period:
    catches a jump check that ignores the elapsed time."""
    loop, robot = start_loop(scenario)
    robot.publish()
    loop.start()
    robot.publish(q=robot.q + 0.015, utime_step=2000)
    loop.tick()
    assert robot.received() == 2 and loop.periods == 2


def test_a_silent_force_torque_sensor_stops_the_controller(scenario):
    loop, robot = start_loop(scenario)
    robot.publish()
    loop.start()
    robot.force_torque = False
    for _ in range(3):  # three statuses without a sensor message: still within 3 periods
        robot.publish()
        loop.tick()
    assert robot.received() == 4
    robot.publish()
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    assert "no lcmt_force_torque on PANDA_FORCE_TORQUE for 4 periods" in str(info.value)
    assert robot.received() == 4


def test_the_estimated_wrench_needs_no_sensor(scenario):
    """With force_source external_torque no lcmt_force_torque is awaited."""
    loop, robot = start_loop(scenario, force_source="external_torque")
    robot.force_torque = False
    robot.publish()
    loop.start()
    robot.publish()
    loop.tick()
    assert robot.received() == 2


def test_pure_checks():
    q0 = np.zeros(7)
    assert start_problem(q0 + 0.01, q0, 0.01, NAMES) is None
    assert "panda_joint7" in start_problem(q0 + np.arange(7) * 0.002, q0, 0.01, NAMES)
    assert jump_problem(q0 + 0.02, q0, 0.01, 2, NAMES) is None
    assert jump_problem(q0 + 0.021, q0, 0.01, 2, NAMES) is not None
    assert clock_steps(2000, 1000, 1e-3) == 1
    assert clock_steps(3400, 1000, 1e-3) == 2  # 2.4 periods: the robot's clock jitters, it skipped one
    assert clock_steps(1000, 1000, 1e-3) is None
    status = lcmt_panda_status()
    status.num_joints = 7
    status.joint_position = status.joint_velocity = status.joint_torque_external = [0.0] * 7
    assert status_problem(status, 7) is None
    status.joint_velocity = [0.0] * 6 + [math.inf]
    assert status_problem(status, 7) == "joint_velocity[6] is inf"
