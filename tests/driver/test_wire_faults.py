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
from nsdrake.driver.loop import ControllerLoop, DriveFaultError, DriveInterruptedError
from nsdrake.driver.panda import POSITION_LOWER, POSITION_UPPER, VELOCITY_LIMIT, limit_problem
from nsdrake.driver.run import Drive, _timing, write_drive_folder
from nsdrake.driver.timing import GcPauses, timing_line
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
    robot.status(after=0.5e-3, q=robot.q + 1e-4)
    newest = robot.status(after=0.5e-3, q=robot.q + 2e-4)
    loop.tick()
    assert bus.sent[-1][1].utime == newest and loop.skipped == 2
    np.testing.assert_allclose(loop.recorder.rows[loop.recorder.count - 1, 1:8], robot.q + 2e-4)
    assert loop.periods == 4  # the robot's clock: four periods since the first status, none replayed


@pytest.mark.parametrize(("step_us", "periods"), [(1900, 2), (1400, 1), (2600, 3), (3000, 3)])
def test_a_gap_is_counted_in_periods_to_the_nearest(sides, step_us, periods):
    """A status 1.9 periods after the previous is two periods on (catches a gap counted as
    one: the controller's clock falls behind the robot's), 1.4 is one, 2.6 and 3 are
    three."""
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
        (51000, "jumped 51.000 ms (51.0 periods) from the previous status's (the silence bound: 50 periods"),
        (3 * 3600 * 10**6, "jumped 10800000.000 ms"),
    ],
    ids=["repeat", "backward", "2 kHz", "past the bound", "3 h jump (NTP step)"],
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
    """A silence bound of 5 periods: a status two periods after the previous now and
    then (one lost) is taken, nine in a row too; the tenth in a row at 250 Hz (4 periods
    each, within the bound) stops the controller naming the stream's period (catches a
    250 Hz stream run as a 1 kHz one that loses three statuses in four)."""
    loop, robot, bus = start_loop(sides, **{})
    loop.bound, loop.bound_periods = 5 * T, 5.0
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
    """The shipped bound, driver.expire_sec 0.05 s (50 periods): a status 50 ms after the
    last is answered, none for just over 50 ms stops the controller (catches silence
    declared a period late, counted from the end of the controller's own tick, or the
    bound not following expire_sec: 3 periods before issue 35)."""
    loop, robot, bus = start_loop(sides)
    assert loop.bound_periods == 50.0 and loop.bound == pytest.approx(0.05, abs=1e-15)
    robot.status()
    loop.start()
    robot.status(after=50e-3, clock_step=50000)
    loop.tick()
    assert loop.commands == 2
    bus.tick_cost = 2.5e-3  # a long tick: silence still counts from the status's arrival
    robot.status()
    loop.tick()
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    waited = bus.now - robot.arrival
    assert 50e-3 < waited <= 50e-3 + 1e-5, waited
    assert info.value.problem == (
        "no lcmt_panda_status on PANDA_STATUS for 50.0 ms "
        "(the silence bound: driver.expire_sec 0.05 s, 50 periods)"
    )


def test_the_bound_follows_driver_expire_sec(sides):
    """driver.expire_sec 0.02 s: the silence bound is 20 periods, and a clock 21 periods on
    is refused (catches a bound that ignores the setting)."""
    scenario = sides["sensor"].scenario
    side = dataclasses.replace(
        sides["sensor"], scenario=dataclasses.replace(
            scenario, driver=dataclasses.replace(scenario.driver, expire_sec=0.02)
        )
    )  # fmt: skip
    bus = FakeBus()
    loop = ControllerLoop(side, bus, clock=bus.clock)
    robot = Robot(bus, side.station.q0)
    loop.ready()
    assert loop.bound_periods == pytest.approx(20.0) and loop.bound == pytest.approx(0.02)
    error = run_until_fault(loop, robot, bus, lambda r: r.status(after=20e-3, clock_step=21000))
    assert "jumped 21.000 ms (21.0 periods)" in error.problem and "20 periods" in error.problem


def test_late_statuses_within_the_bound_are_glitches_counted_by_length(sides):
    """Statuses 2, 3, 10, 11, 50 and 2 periods after the previous, each a glitch: answered,
    and counted 2 of 2 periods, 2 of 3-10, 2 of 11-50, the longest 50 (catches an
    off-by-one at a bin's edge, a gap counted in ms or in statuses, and a glitch taken for
    a fault); then one status 51 periods on stops the controller."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    for gap in (2, 3, 10, 11, 50, 2):
        robot.status(after=gap * T, clock_step=gap * 1000)
        loop.tick()
        robot.status()
        loop.tick()
    assert loop.commands == 13 and loop.gap_counts.tolist() == [2, 2, 2, 0] and loop.longest_gap == 50
    timing = _timing(loop, GcPauses(), True)
    assert timing["gaps"] == {"2": 2, "3-10": 2, "11-50": 2, "over 50": 0}
    assert timing["longest_gap_periods"] == 50
    line = timing_line(timing)
    assert "late statuses: 2 of 2, 2 of 3-10, 2 of 11-50 periods, the longest 50 periods" in line
    robot.status(after=51 * T, clock_step=51000)
    with pytest.raises(DriveFaultError):
        loop.tick()


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
    """Force-torque messages stop at t = 1 ms; statuses go on, the next two 49.5 ms and
    1 ms later (one period on each, a late status is not a fault): at 50.5 ms the sensor
    is silent 49.5 ms (< the 50 ms bound, taken), at 51.5 ms 50.5 ms: refused, though only
    two statuses came (catches silence counted in statuses or periods)."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    robot.status()
    loop.tick()
    robot.force_torque = False
    robot.status(after=49.5e-3)
    loop.tick()
    robot.status()
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    assert "no lcmt_force_torque on PANDA_FORCE_TORQUE for 50.5 ms" in info.value.problem
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
    """Joint 6 at its published upper limit + 0.02 rad (margin 0.01): refused, reached at
    2.5 rad/s (its velocity reported: steps the motion checks allow; catches a position
    moving past the limit). The robot adds g: the controller, at joint 6's 12 N m as the
    joint is pushed away, keeps its command within the limit (its window centred on g(q)),
    so the position rule, not the last gate, stops the drive (before the centre, the gate
    met a command 0.04 N m beyond 12 N m first)."""
    loop, robot, bus = start_loop(sides)
    assert loop.side.adds_gravity
    robot.status()
    loop.start()
    q, v = robot.q.copy(), np.zeros(7)
    target = POSITION_UPPER[5] + 0.02
    with pytest.raises(DriveFaultError) as info:
        while True:
            q[5] = min(q[5] + (0.0025 if v[5] else 0.00125), target)
            v[5] = 2.5
            robot.status(q=q, v=v)
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


@pytest.mark.parametrize("sign", [1, -1], ids=["upward", "downward"])
def test_the_start_tolerance_and_the_limits_hold_on_both_sides(sign):
    """Every joint, one at a time, moved upward then downward: start_problem takes a first
    status exactly start_tolerance from the start pose and refuses one 1e-6 further (naming
    the joint); limit_problem takes a position 0.0099 rad beyond the Panda's published
    limit on that side and refuses one 0.0101 rad beyond it ("above" or "below"), and
    likewise a velocity of ±1.049 and ±1.051 times the published limit (issue 46: both
    signs of every symmetric rule, each boundary from both sides; "exactly" to 1e-9
    relative, as q0 + tolerance − q0 rounds). Catches a signed
    distance from the start pose (a joint off by any amount the other way taken), and a
    limit checked on one side only."""
    tolerance, zeros = 0.004, np.zeros(7)
    q0 = np.array([0.0, 0.0, 0.0, -1.5, 0.0, 1.5, 0.0])  # inside every joint's limits
    side = "above" if sign > 0 else "below"
    for j in range(7):
        q = q0.copy()
        q[j] += sign * tolerance * (1 - 1e-9)  # (q0 + tolerance − q0 is not the tolerance to the bit)
        assert start_problem(q, q0, tolerance, NAMES) is None, j
        q[j] += sign * 1e-6
        assert start_problem(q, q0, tolerance, NAMES).startswith(f"{NAMES[j]} is at "), j
        limit = (POSITION_UPPER if sign > 0 else POSITION_LOWER)[j]
        q = q0.copy()
        q[j] = limit + sign * 0.0099
        assert limit_problem(q, zeros, NAMES) is None, j
        q[j] = limit + sign * 0.0101
        words = f"{NAMES[j]} is at {q[j]:.4f} rad, {side} the Panda's limit"
        assert limit_problem(q, zeros, NAMES).startswith(words), j
        v = zeros.copy()
        v[j] = sign * 1.049 * VELOCITY_LIMIT[j]
        assert limit_problem(q0, v, NAMES) is None, j
        v[j] = sign * 1.051 * VELOCITY_LIMIT[j]
        assert limit_problem(q0, v, NAMES).startswith(f"{NAMES[j]} moves at {v[j]:.4g} rad/s"), j


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
    q[3] += 0.02  # start_tolerance 0.004 rad
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
    allowance = np.full(7, 0.02)
    assert jump_problem(q0 + 0.02, q0, allowance, 2, NAMES, "of x") is None
    assert "panda_joint1 moved 0.021 rad in 2 period(s), more than the 0.02 rad of x" in jump_problem(
        q0 + 0.021, q0, allowance, 2, NAMES, "of x"
    )
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


def creeping(joint: int, step: float, v=None):
    """A fault: every status from now on has ``joint`` ``step`` [rad] further on, its
    reported velocity ``v`` (default zeros)."""

    def fault(r):
        r.q = r.q.copy()
        r.q[joint] += step
        r.status(v=v)

    return fault


def test_a_position_creeping_at_5_rad_s_is_refused_at_the_first_status(sides):
    """Issue 35's acceptance: joint 7 creeping 0.005 rad per 1 ms status (5 rad/s, beyond
    its 2.61 rad/s limit) while its velocity reads 0 is refused at the first status that
    shows it, naming the joint (catches the old 0.01 rad-a-period max_joint_step, which
    let it through for 90 commands, and a bound per period from the fastest joint only)."""
    loop, robot, bus = start_loop(sides)
    error = run_until_fault(loop, robot, bus, creeping(6, 0.005))
    assert error.problem.startswith(
        "status refused: panda_joint7 moved 0.005 rad in 1 period(s), more than the 0.00294 rad"
    ), error.problem


@pytest.mark.parametrize(("joint", "speed"), [(0, 2.2), (6, 2.7)])
def test_a_joint_near_its_velocity_limit_is_no_fault(sides, joint, speed):
    """A joint moving steadily at its velocity limit (+ the 5% margin's most), its velocity
    reported: answered (catches bounds tighter than a Panda's own motion)."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    v = np.zeros(7)
    v[joint] = speed
    robot.q = robot.q.copy()
    robot.q[joint] += speed * T / 2  # from rest: the trapezoid of 0 and the speed
    robot.status(v=v)
    loop.tick()
    for _ in range(20):
        robot.q = robot.q.copy()
        robot.q[joint] += speed * T
        robot.status(v=v)
        loop.tick()
    assert loop.commands == 22


@pytest.mark.parametrize(("joint", "speed"), [(0, 2.6), (4, 3.1)])
def test_a_joint_faster_than_its_limit_is_refused_naming_it(sides, joint, speed):
    """Joint 1 at 2.6 rad/s (limit 2.175) and joint 5 at 3.1 (limit 2.61), its velocity
    reading 0: refused at once, by its velocity limit's step, checked first (catches one
    bound for all joints, the fastest's: joint 1 at 2.6 would pass it)."""
    loop, robot, bus = start_loop(sides)
    error = run_until_fault(loop, robot, bus, creeping(joint, speed * T))
    assert error.problem.startswith(f"status refused: panda_joint{joint + 1} moved ")
    assert "its velocity limit allows" in error.problem


def test_a_position_that_its_velocity_does_not_explain_is_refused(sides):
    """Joint 3 creeping 0.001 rad a period (1 rad/s, well within its limit) while its
    velocity reads 0: refused at the first such status by the velocity check (catches the
    check missing or comparing the wrong status's velocity); the same move with the
    velocity reported, 1 rad/s, is answered (the test above)."""
    loop, robot, bus = start_loop(sides)
    error = run_until_fault(loop, robot, bus, creeping(2, 0.001))
    assert error.problem.startswith(
        "status refused: panda_joint3 moved 0.001 rad in 1 ms while its reported velocity (0 then 0 rad/s) "
        "says 0 rad: they disagree by more than 0.000263 rad"
    ), error.problem


def test_max_joint_step_set_is_one_bound_for_every_joint(sides):
    """driver.max_joint_step 0.001 rad: joint 2 starting to move at 1.2 rad/s (its velocity
    reported; within its limit) is answered for its first half step, 0.0006 rad, and
    refused at its first whole one, 0.0012 rad, naming the setting (catches a set value
    ignored)."""
    loop, robot, bus = start_loop(sides)
    loop.config = dataclasses.replace(loop.config, max_joint_step=0.001)
    v = np.zeros(7)
    v[1] = 1.2

    def move(r):
        creeping(1, 0.0006, v)(r)
        creeping(1, 0.0012, v)(r)

    error = run_until_fault(loop, robot, bus, move, sent=6)
    assert error.problem == (
        "status refused: panda_joint2 moved 0.0012 rad in 1 period(s), more than the 0.001 rad "
        "of driver.max_joint_step 0.001 rad per period"
    )


class InterruptedBus(FakeBus):
    """A bus whose wait fails as the ``lcm`` package's does when a signal interrupts
    select() (OSError "lcm_handle_timeout() returned -1"): at the ``at``-th handle call
    with a timeout, ``times`` times in a row, after running ``signal()`` (the handler)."""

    def __init__(self, at: int, times: int, signal=lambda: None):
        super().__init__()
        self.calls, self.fail_at, self.times, self.signal = 0, at, times, signal

    def handle(self, timeout_ms: int) -> int:
        if timeout_ms:
            self.calls += 1
        if self.calls >= self.fail_at and self.times:
            self.times -= 1
            self.signal()
            raise OSError("lcm_handle_timeout() returned -1")
        return super().handle(timeout_ms)


def test_ctrl_c_during_a_wait_is_an_interrupt_not_a_bus_failure(sides):
    """SIGINT while the loop waits for a status (the flag set, the wait failing with
    EINTR's OSError): DriveInterruptedError, at the start and mid-run (catches the OSError
    reported as "the LCM bus failed", exit 1: issue 34)."""
    for at in (1, 4):
        bus = InterruptedBus(at, 1)
        loop = ControllerLoop(sides["sensor"], bus, clock=bus.clock)
        loop.side.reset()
        bus.signal = lambda loop=loop: setattr(loop.stop, "requested", True)
        robot = Robot(bus, loop.side.station.q0)
        loop.ready()
        robot.status()
        with pytest.raises(DriveInterruptedError):
            loop.start()
            for _ in range(10):
                robot.status(after=3 * T, clock_step=3000)
                loop.tick()
        assert (loop.commands == 0) == (at == 1) and len(bus.sent) == loop.commands


def test_another_signal_s_eintr_is_no_fault_and_a_broken_bus_stays_one(sides, tmp_path):
    """The wait failing once without Ctrl-C (another signal's EINTR): retried, no fault; a
    wait failing every time (a broken socket): "the LCM bus failed", not an interrupt
    (catches every OSError taken for Ctrl-C, or every one for a failure)."""
    bus = InterruptedBus(2, 1)
    loop = ControllerLoop(sides["sensor"], bus, clock=bus.clock)
    loop.side.reset()
    robot = Robot(bus, loop.side.station.q0)
    loop.ready()
    robot.status()
    loop.start()
    for _ in range(5):
        robot.status(after=3 * T, clock_step=3000)
        loop.tick()
    assert loop.commands == 6
    bus = InterruptedBus(2, 1000)
    loop = ControllerLoop(sides["sensor"], bus, clock=bus.clock)
    loop.side.reset()
    robot = Robot(bus, loop.side.station.q0)
    for _ in range(10):
        robot.status(after=3 * T, clock_step=3000)
    run = Drive(loop, None).run()
    assert not run.interrupted and "the LCM bus failed: lcm_handle_timeout() returned -1" in run.failure


def test_a_controller_later_than_the_bound_stops(sides):
    """A 52 ms tick while the robot goes on at 1 kHz (each status on time, one period after
    the last): the next status answered would be 52 periods after the one before, past
    the 50-period bound, when the driver has dropped the last command and damped: refused
    (catches only the statuses' own gaps checked: the controller's lateness unbounded)."""
    loop, robot, bus = start_loop(sides)
    robot.status()
    loop.start()
    robot.status()
    bus.tick_cost = 52e-3
    loop.tick()
    bus.tick_cost = 0.0
    for _ in range(52):
        robot.status()
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    assert info.value.problem.startswith(
        "status refused: 52 periods since the status answered before it, beyond the silence bound"
    )
    assert loop.commands == 2
