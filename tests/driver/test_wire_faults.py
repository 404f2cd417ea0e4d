"""Faults on the wire and the loop's timing rules (issue 27, items 2-4), on a fake clock:
a scripted robot schedules its statuses (and force-torque messages) at chosen arrival
times on a bus whose clock advances only as a wait would (tests/driver/fake_bus.py), so
that each rule is tested at its boundary, deterministically. Each fault stops the
controller with one line, and nothing is sent after it. (The same faults over real UDP
between processes: tests/driver/test_udp.py.)"""

from __future__ import annotations

import dataclasses
import errno
import math

import numpy as np
import pytest
from drake import lcmt_force_torque, lcmt_panda_status
from fake_bus import FakeBus, force_torque_bytes, status_bytes

from nsdrake.driver.controller_side import build_controller_side
from nsdrake.driver.faults import clock_problem, elapsed_periods, jump_problem, start_problem
from nsdrake.driver.loop import ControllerLoop, DriveFaultError
from nsdrake.driver.panda import POSITION_UPPER, VELOCITY_LIMIT, limit_problem
from nsdrake.driver.run import Drive, write_drive_folder
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.traces import Traces

NAMES = tuple(f"panda_joint{k}" for k in range(1, 8))
T = 1e-3
UTIME0 = 1_700_000_000_000_000  # a wall clock's µs, as drake-franka-driver stamps them


@pytest.fixture(scope="module")
def sides():
    """The controller side of panda_wipe with the sensor and with the estimate (built once)."""
    s = load_scenario("panda_wipe", duration=1.0)
    s = dataclasses.replace(s, driver=dataclasses.replace(s.driver, first_status_timeout=0.3))
    external = dataclasses.replace(s, driver=dataclasses.replace(s.driver, force_source="external_torque"))
    return {"sensor": build_controller_side(s), "external_torque": build_controller_side(external)}


class Robot:
    """Schedules a Panda at rest at q0: status k arrives at ``arrival`` [s] with utime and
    (``robot_clock``) robot_utime, and a force-torque message with it (``force_torque``)."""

    def __init__(self, bus: FakeBus, q0, *, force_torque=True, robot_clock=True):
        self.bus, self.q = bus, np.array(q0, dtype=float)
        self.force_torque, self.robot_clock = force_torque, robot_clock
        self.utime, self.robot_utime, self.arrival = UTIME0, 5_000_000, 0.0

    def status(self, *, after=T, clock_step=1000, q=None, v=None, data=None, utime=None):
        """The next status, ``after`` [s] after the previous one, its clocks ``clock_step``
        [µs] on; returns its utime."""
        self.arrival += after
        self.utime += clock_step
        self.robot_utime += clock_step
        stamp = self.utime if utime is None else utime
        if data is None:
            data = status_bytes(
                self.q if q is None else q,
                utime=stamp,
                robot_utime=self.robot_utime if self.robot_clock else 0,
                v=v,
            )
        self.bus.at(self.arrival, "PANDA_STATUS", data)
        if self.force_torque:
            self.bus.at(self.arrival, "PANDA_FORCE_TORQUE", force_torque_bytes())
        return stamp


def start_loop(sides, force_source="sensor", **robot):
    bus = FakeBus()
    loop = ControllerLoop(sides[force_source], bus, clock=bus.clock)
    loop.side.reset()
    robot = Robot(bus, loop.side.station.q0, force_torque=force_source == "sensor", **robot)
    loop.ready()
    return loop, robot, bus


def run_until_fault(loop, robot, bus, fault, sent: int = 5) -> DriveFaultError:
    """Five good statuses answered one by one, then ``fault(robot)`` and ticks until the
    fault (at most 2: a faulty stream may begin with a status that is still fine): returns
    it, after checking that exactly ``sent`` commands went out, one per status answered
    (catches a command, a "safe" zero torque included, sent on the fault) and nothing after."""
    robot.status()
    loop.start()
    for _ in range(4):
        robot.status()
        loop.tick()
    assert len(bus.sent) == 5
    fault(robot)
    with pytest.raises(DriveFaultError) as info:
        for _ in range(2):
            loop.tick()
    assert loop.commands == sent, loop.commands  # one per good status: none sent on the fault
    for _ in range(3):  # the robot keeps talking; the stopped controller does not answer
        robot.status()
    bus.handle(10)
    assert len(bus.sent) == sent
    message = str(info.value)
    assert "\n" not in message and f"stopped commanding after {sent} command(s)" in message
    return info.value


def test_every_good_status_gets_one_command_with_its_utime(sides):
    """Catches a command that does not answer its status (a stale utime, which a real
    driver drops as expired) or a second command per status."""
    loop, robot, bus = start_loop(sides)
    stamps = [robot.status()]
    loop.start()
    for _ in range(9):
        stamps.append(robot.status())
        loop.tick()
    assert [c.utime for _, c in bus.sent] == stamps
    command = bus.sent[-1][1]
    assert (command.num_joint_torque, command.num_joint_position, command.num_joint_velocity) == (7, 0, 0)
    assert command.control_mode_expected == lcmt_panda_status.CONTROL_MODE_TORQUE
    assert loop.time == pytest.approx(9 * T, abs=1e-15) and loop.clock_name == "robot_utime"


def test_the_newest_status_is_answered_and_the_others_counted_skipped(sides):
    """Three statuses arrive while the controller computes (a 2.5 ms tick): the next tick
    answers the newest (its utime, its q) and counts two skipped. Catches the oldest
    queued status answered (DrakeLcm's one-message queue over UDP), or every queued one
    answered in turn."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    bus.tick_cost = 2.5e-3
    robot.status()
    loop.tick()  # publishes at +2.5 ms: three more statuses arrived meanwhile
    bus.tick_cost = 0.0
    robot.status(after=0.5e-3)
    robot.status(after=0.5e-3, q=robot.q + 1e-3)
    newest = robot.status(after=0.5e-3, q=robot.q + 2e-3)
    loop.tick()
    assert bus.sent[-1][1].utime == newest and loop.skipped == 2
    np.testing.assert_allclose(loop.recorder.rows[loop.recorder.count - 1, 1:8], robot.q + 2e-3)
    assert loop.periods == 4  # the robot's clock: four periods since the first status, none replayed


@pytest.mark.parametrize(("step_us", "periods"), [(1900, 2), (1400, 1), (2600, 3), (3000, 3)])
def test_a_gap_is_counted_in_periods_to_the_nearest(sides, step_us, periods):
    """A status 1.9 periods after the previous is two periods on (catches a gap counted as
    one: the controller's clock falls behind the robot's), 1.4 is one, 2.6 and 3 (the
    bound, accepted) are three."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    robot.status(after=step_us * 1e-6, clock_step=step_us)
    loop.tick()
    assert loop.periods == periods and loop.time == pytest.approx(periods * T, abs=1e-15)


def test_the_clock_is_the_robot_s_re_anchored_every_tick(sides):
    """utime from a PC clock running 0.2% fast with ±300 µs of jitter and stepped 2 s
    forward by NTP halfway, robot_utime the robot's own 1 kHz: after 500 statuses the
    controller's clock is the robot's, exactly, and the step is no fault (catches utime
    read instead of robot_utime: the step would stop the drive as a jump)."""
    loop, robot, bus = start_loop(sides)
    rng = np.random.default_rng(0)
    robot.status()
    loop.start()
    utime0 = robot.utime
    for k in range(1, 501):
        step = 2_000_000 if k > 250 else 0
        robot.status(utime=utime0 + 1002 * k + step + int(rng.integers(-300, 301)))
        loop.tick()
    assert loop.clock_name == "robot_utime"
    assert loop.time == pytest.approx(500 * T, abs=1e-12) and loop.skipped == 0


def test_without_robot_utime_the_clock_is_utime_re_anchored(sides):
    """No robot_utime: utime, counted in periods from an anchor re-set every tick. A run
    of 1400 µs gaps: 1.4 periods each, five of them are 7 periods (a sum of rounded gaps
    says 5)."""
    loop, robot, bus = start_loop(sides, robot_clock=False)
    robot.status()
    loop.start()
    assert loop.clock_name == "utime"
    for _ in range(5):
        robot.status(after=1.4e-3, clock_step=1400)
        loop.tick()
    assert loop.periods == 7


def test_utime_jitter_is_taken_around_the_stream_s_phase(sides):
    """No robot_utime, a PC clock whose first stamp is 300 µs late, the next ones +100,
    −250, −280, then ±280 alternating: every status is one period on (500 of them, none
    refused, none skipped), although −250 and −280 lie more than half a period from the
    first stamp (catches the first status's stamp kept as the anchor: the third status
    would be refused as a stream faster than the controller's period)."""
    loop, robot, bus = start_loop(sides, robot_clock=False)
    utime0 = robot.utime + 1000
    robot.status(utime=utime0 + 300)
    loop.start()
    jitter = [100, -250, -280] + [280 if k % 2 else -280 for k in range(497)]
    for k, j in enumerate(jitter, 1):
        robot.status(utime=utime0 + 1000 * k + j)
        loop.tick()
    assert loop.periods == 500 and loop.skipped == 0 and loop.commands == 501


@pytest.mark.parametrize(
    ("clock_step", "words"),
    [
        (0, "repeats the previous status's (a second publisher on the channel?)"),
        (-1000, "went back 1000 µs"),
        (500, "within the same control period: the stream is faster than the controller's period"),
        (4000, "jumped 4.000 ms (4.0 periods)"),
        (3 * 3600 * 10**6, "jumped 10800000.000 ms"),
    ],
    ids=["repeat", "backward", "2 kHz", "250 Hz", "3 h jump (NTP step)"],
)
def test_a_clock_that_is_not_the_robot_s_period_stops_the_controller(sides, clock_step, words):
    loop, robot, bus = start_loop(sides)

    def fault(r):
        if clock_step == 500:  # a 2 kHz stream: two statuses in one period
            r.status(after=0.5e-3, clock_step=500)
            r.status(after=0.5e-3, clock_step=500)
        else:
            r.status(clock_step=clock_step)

    # at 2 kHz the first half-period status rounds to the next period and is answered
    error = run_until_fault(loop, robot, bus, fault, sent=6 if clock_step == 500 else 5)
    assert error.problem.startswith("status refused: its robot_utime") and words in error.problem


def test_a_slower_stream_is_told_from_lost_statuses(sides):
    """driver.status_timeout_periods 5: a status two periods after the previous now and
    then (one lost) is taken, nine in a row too; the tenth in a row at 250 Hz (4 periods
    each, within the bound) stops the controller naming the stream's period (catches a
    250 Hz stream run as a 1 kHz one that loses three statuses in four)."""
    loop, robot, bus = start_loop(sides, **{})
    loop.bound = 5 * T
    loop.config = dataclasses.replace(loop.config, status_timeout_periods=5.0)
    robot.status()
    loop.start()
    for _ in range(5):
        robot.status(after=2e-3, clock_step=2000)
        loop.tick()
        robot.status()
        loop.tick()
    for _ in range(9):
        robot.status(after=4e-3, clock_step=4000)
        loop.tick()
    robot.status(after=4e-3, clock_step=4000)
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    assert "10 statuses in a row came two periods or more apart (the last 4000 µs" in info.value.problem
    assert "the stream's period is not the controller's 1000 µs" in info.value.problem


def test_two_publishers_on_the_status_channel_are_named(sides):
    """A second driver's statuses, on its own clock, between the first's: refused at the
    first one whose clock goes back, named as a second publisher."""
    loop, robot, bus = start_loop(sides)

    def second(r):
        r.status()
        bus.at(r.arrival, "PANDA_STATUS", status_bytes(r.q, utime=1, robot_utime=1000))

    error = run_until_fault(loop, robot, bus, second)
    assert "went back" in error.problem and "a second publisher on the channel?" in error.problem


def test_silence_is_declared_at_the_bound_on_the_wall_clock(sides):
    """driver.status_timeout_periods 3: a status 3 ms after the last is answered, none for
    just over 3 ms stops the controller (catches silence declared a period late, or
    counted from the end of the controller's own tick)."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    robot.status(after=3e-3, clock_step=3000)
    loop.tick()
    assert loop.commands == 2
    bus.tick_cost = 2.5e-3  # a long tick: silence still counts from the status's arrival
    robot.status()
    loop.tick()
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    waited = bus.now - robot.arrival
    assert 3e-3 < waited <= 3e-3 + 1e-5, waited
    assert "no lcmt_panda_status on PANDA_STATUS for 3.0 ms" in info.value.problem


def long_tick_then_five_statuses(loop, robot, bus) -> None:
    """A status answered by a 5 ms tick while the robot goes on at 1 kHz (five statuses),
    then one tick."""
    robot.status()
    bus.tick_cost = 5e-3
    loop.tick()
    bus.tick_cost = 0.0
    for _ in range(5):
        robot.status()
    loop.tick()


def test_a_long_tick_skips_statuses_without_a_fault(sides):
    """A 5 ms tick while the robot goes on at 1 kHz: the next tick answers the newest
    status (arrived < 1 ms ago), four skipped, no silence (catches silence measured from
    the tick's start, which the controller's own compute would trip)."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    long_tick_then_five_statuses(loop, robot, bus)
    assert loop.skipped == 4 and loop.periods == 6


def test_the_longest_silence_is_the_longest_wait_from_the_last_arrival(sides):
    """A status 2.7 ms after the last while the loop waits (from 0.5 ms after that one's
    arrival: its tick's cost), then a 5 ms tick during which statuses go on at 1 kHz: the
    loop's longest silence is 2.7 ms (catches a silence figure measured from the end of
    the tick, 2.2 ms here, instead of the answered status's arrival, and one that counts
    the controller's own long tick, 5 ms here, which the silence rule does not)."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    bus.tick_cost = 0.5e-3  # the wait begins 0.5 ms after the status arrived
    loop.start()
    bus.tick_cost = 0.0
    robot.status(after=2.7e-3, clock_step=3000)
    loop.tick()
    assert math.isclose(loop.longest_silence, 2.7e-3, rel_tol=1e-6), loop.longest_silence
    long_tick_then_five_statuses(loop, robot, bus)
    assert loop.skipped == 4
    assert math.isclose(loop.longest_silence, 2.7e-3, rel_tol=1e-6), loop.longest_silence


def test_the_sensor_s_silence_is_elapsed_time_not_statuses(sides):
    """Force-torque messages stop at t = 1 ms; statuses go on, the next two 2.5 ms and
    1 ms later (one period on each, a late status is not a fault): at 3.5 ms the sensor
    is silent 2.5 ms (< 3, taken), at 4.5 ms 3.5 ms: refused, though only two statuses
    came (catches silence counted in statuses or periods)."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    robot.status()
    loop.tick()
    robot.force_torque = False
    robot.status(after=2.5e-3)
    loop.tick()
    robot.status()
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    assert "no lcmt_force_torque on PANDA_FORCE_TORQUE for 3.5 ms" in info.value.problem
    assert loop.commands == 3


@pytest.mark.parametrize(
    ("fault", "words"),
    [
        (lambda r: r.status(data=b"\x00garbage"), "8 bytes that are not an lcmt_panda_status"),
        (lambda r: r.status(q=np.where(np.arange(7) == 2, math.nan, r.q)), "joint_position[2] is nan"),
        (lambda r: r.status(data=status_bytes(r.q[:6], utime=r.utime + 1, num_joints=6)), "it has 6 joints"),
        (lambda r: r.status(q=r.q + np.where(np.arange(7) == 4, 0.05, 0.0)), "panda_joint5 moved 0.05 rad"),
    ],
    ids=["undecodable", "nan", "joint count", "jump"],
)
def test_a_refused_status_stops_the_controller(sides, fault, words):
    loop, robot, bus = start_loop(sides)
    error = run_until_fault(loop, robot, bus, fault)
    assert error.problem.startswith("status refused: ") and words in error.problem, error.problem


def test_a_joint_beyond_the_panda_s_limits_stops_the_controller(sides):
    """Joint 6 at its published upper limit + 0.02 rad (margin 0.01): refused, reached in
    steps the jump check allows (catches a position creeping past the limit)."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    q = robot.q.copy()
    target = POSITION_UPPER[5] + 0.02
    with pytest.raises(DriveFaultError) as info:
        while True:
            q[5] = min(q[5] + 0.009, target)
            robot.status(q=q)
            loop.tick()
    assert (
        "panda_joint6 is at" in info.value.problem
        and "above the Panda's limit 3.7525 rad" in info.value.problem
    )
    assert q[5] > POSITION_UPPER[5] + 0.01


def test_a_non_finite_force_torque_message_stops_the_controller(sides):
    """A force-torque message with fz NaN (a sensor that saturated or lost its link): one
    line naming the channel and the field, nothing sent after (catches the sensor's values
    taken unchecked, which made the controller step raise a traceback mid-run)."""
    loop, robot, bus = start_loop(sides)
    bad = lcmt_force_torque()
    bad.fz = math.nan

    def fault(r):
        r.force_torque = False
        r.status()
        bus.at(r.arrival, "PANDA_FORCE_TORQUE", bad.encode())

    error = run_until_fault(loop, robot, bus, fault)
    assert error.problem == "force-torque message refused on PANDA_FORCE_TORQUE: fz is nan"


class FailingBus(FakeBus):
    """A bus whose socket fails (ENETUNREACH) at the sixth publish."""

    def publish(self, channel: str, data) -> None:
        if len(self.sent) == 5:
            raise OSError(errno.ENETUNREACH, "Network is unreachable")
        super().publish(channel, data)


def test_an_error_the_checks_do_not_name_still_ends_in_one_line_keeping_the_rows(sides, tmp_path):
    """The bus failing at the sixth command (an OSError from LCM's socket): the drive ends
    with one failure line, the five commands sent recorded and written to traces.csv
    (catches the error escaping Drive.run: a traceback, and the folder with the traces of
    the commands already sent removed)."""
    bus = FailingBus()
    loop = ControllerLoop(sides["sensor"], bus, clock=bus.clock)
    loop.side.reset()
    robot = Robot(bus, loop.side.station.q0)
    for _ in range(10):
        robot.status()
    run = Drive(loop, None).run()
    assert run.failure == (
        "at t = 0.005 s: the LCM bus failed: [Errno 101] Network is unreachable; "
        "stopped commanding after 5 command(s)"
    )
    result = write_drive_folder(run, tmp_path)
    assert result.failure == run.failure
    assert len(Traces.read_csv(tmp_path / "traces.csv")["t"]) == 5


def test_limit_checks_at_their_margins():
    q = np.array([0.0, 0.0, 0.0, -1.0, 0.0, 1.0, 0.0])
    v = np.zeros(7)
    assert limit_problem(q, v, NAMES) is None
    q[3] = -0.0698 + 0.0099  # above joint 4's upper limit, within the margin
    assert limit_problem(q, v, NAMES) is None
    q[3] = -0.0698 + 0.0101
    assert "panda_joint4" in limit_problem(q, v, NAMES)
    q[3] = -1.0
    v[6] = VELOCITY_LIMIT[6] * 1.049
    assert limit_problem(q, v, NAMES) is None
    v[6] = -VELOCITY_LIMIT[6] * 1.051
    assert "panda_joint7 moves at -2.743 rad/s" in limit_problem(q, v, NAMES)


def test_no_first_status_ends_without_sending(sides):
    loop, robot, bus = start_loop(sides)
    with pytest.raises(DriveFaultError) as info:
        loop.start()
    assert str(info.value) == (
        "before the first command: no lcmt_panda_status on PANDA_STATUS within 0.3 s; nothing was sent; "
        "stopped commanding after 0 command(s)"
    )
    assert not bus.sent


def test_a_status_queued_before_the_controller_was_ready_is_not_answered(sides):
    """A status far from the start pose waiting in the queue before ready(), then a good
    one: the first status acted on is the one that arrived after ready (catches the
    start-pose check run on a stale queued status, and its answer)."""
    bus = FakeBus()
    loop = ControllerLoop(sides["sensor"], bus, clock=bus.clock)
    robot = Robot(bus, loop.side.station.q0)
    robot.status(after=0.0, q=robot.q + 0.5)
    bus.handle(0)  # delivered into the inbox before the controller is ready
    loop.ready()
    stamp = robot.status()
    loop.start()
    assert [c.utime for _, c in bus.sent] == [stamp]


def test_without_force_torque_messages_the_line_names_the_sensor(sides):
    """drake-franka-driver publishes no lcmt_force_torque: with force_source sensor the
    start fails naming the silent channel and the statuses that did arrive."""
    loop, robot, bus = start_loop(sides)
    robot.force_torque = False
    for _ in range(10):
        robot.status()
    with pytest.raises(DriveFaultError) as info:
        loop.start()
    assert "no lcmt_force_torque on PANDA_FORCE_TORQUE within 0.3 s although" in info.value.problem
    assert "use driver.force_source: external_torque" in info.value.problem and not bus.sent


def test_first_status_outside_the_start_tolerance_is_refused(sides):
    loop, robot, bus = start_loop(sides)
    q = robot.q.copy()
    q[3] += 0.02  # start_tolerance 0.01 rad
    robot.status(q=q)
    with pytest.raises(DriveFaultError) as info:
        loop.start()
    assert (
        "first status refused: panda_joint4 is at -2.3800 rad, 0.0200 rad from the scenario's start"
        in str(info.value)
    )
    assert not bus.sent


def test_the_estimated_wrench_needs_no_sensor(sides):
    """With force_source external_torque no lcmt_force_torque is awaited."""
    loop, robot, bus = start_loop(sides, "external_torque")
    robot.status()
    loop.start()
    robot.status()
    loop.tick()
    assert len(bus.sent) == 2


def test_pure_checks():
    q0 = np.zeros(7)
    assert start_problem(q0 + 0.01, q0, 0.01, NAMES) is None
    assert "panda_joint7" in start_problem(q0 + np.arange(7) * 0.002, q0, 0.01, NAMES)
    assert jump_problem(q0 + 0.02, q0, 0.01, 2, NAMES) is None
    assert jump_problem(q0 + 0.021, q0, 0.01, 2, NAMES) is not None
    assert clock_problem(2000, 1000, 0, 1000, 3.0, "utime") is None
    assert clock_problem(1500, 1300, 0, 1000, 3.0, "utime") is None  # 200 µs, but periods 1 → 2: jitter
    assert "same control period" in clock_problem(1499, 1000, 0, 1000, 3.0, "utime")
    assert clock_problem(4000, 1000, 0, 1000, 3.0, "utime") is None  # at the bound
    assert "jumped" in clock_problem(4001, 1000, 0, 1000, 3.0, "utime")
    assert elapsed_periods(10_499, 0, 1000) == 10 and elapsed_periods(10_500, 0, 1000) == 11


def test_a_robot_out_of_kmove_stops_the_controller(sides):
    """A status whose robot_mode is kReflex (4): the robot applies no torque command; the
    controller stops naming the mode (catches robot_mode never read)."""
    loop, robot, bus = start_loop(sides)

    def reflex(r):
        r.utime += 1000
        r.robot_utime += 1000
        r.arrival += T
        message = lcmt_panda_status.decode(status_bytes(r.q, utime=r.utime, robot_utime=r.robot_utime))
        message.robot_mode = 4
        bus.at(r.arrival, "PANDA_STATUS", message.encode())
        bus.at(r.arrival, "PANDA_FORCE_TORQUE", force_torque_bytes())

    error = run_until_fault(loop, robot, bus, reflex)
    assert "the robot is in mode kReflex (4), not kMove (2): it applies no torque command" in error.problem


def test_the_robot_s_success_rate_is_reported_once_the_drive_has_run_its_window(sides):
    """The rate libfranka reports is over its last 100 cycles: 0 in the first 100 ticks (no
    command before the drive) is not counted, a later 0.9 is the minimum, named in the
    timing line (catches control_command_success_rate never read, or read from the start)."""
    from nsdrake.driver.timing import timing_line, timing_summary

    loop, robot, bus = start_loop(sides)

    def status_with_rate(rate):
        robot.utime += 1000
        robot.robot_utime += 1000
        robot.arrival += T
        message = lcmt_panda_status.decode(
            status_bytes(robot.q, utime=robot.utime, robot_utime=robot.robot_utime)
        )
        message.control_command_success_rate = rate
        bus.at(robot.arrival, "PANDA_STATUS", message.encode())
        bus.at(robot.arrival, "PANDA_FORCE_TORQUE", force_torque_bytes())

    status_with_rate(0.0)
    loop.start()
    for k in range(150):
        status_with_rate(0.0 if k < 99 else 0.9 if k == 120 else 1.0)
        loop.tick()
    assert loop.success_rate_min == 0.9
    summary = timing_summary(loop.times.seconds, T, control_command_success_rate_min=loop.success_rate_min)
    assert "the robot's control_command_success_rate fell to 0.90" in timing_line(summary)
