"""The controller loop's timing rules, each at its boundary on both sides, and the process
left as the drive found it (issue 37). A scripted robot schedules statuses at chosen
arrival times and clocks on a fake bus (tests/driver/fake_bus.py); every figure a rule
compares with (the period, the silence bound, the slow-stream count, max_joint_step) is
read from the loop and its configuration, not written here, so that the tests follow the
rules' contract when their numbers change.

The families: a count of periods at its boundary (a gap of exactly two periods is a slow
stream's; a status exactly at the silence bound, on the wall clock and on its own clock,
is answered and one just past it is not), the periods a jump is allowed over (those since
the status answered last, skipped statuses included), which end of a queue is answered
(the newest, at the start too), and state restored after the loop (the collector, its
callbacks, Ctrl-C's handler).
"""

from __future__ import annotations

import dataclasses
import gc
import signal

import numpy as np
import pytest
from drake import lcmt_panda_status
from fake_bus import FakeBus, force_torque_bytes, status_bytes

from nsdrake.driver.controller_side import build_controller_side
from nsdrake.driver.faults import SLOW_STREAM
from nsdrake.driver.loop import SUCCESS_RATE_WINDOW, ControllerLoop, DriveFaultError
from nsdrake.driver.run import Drive
from nsdrake.experiment.scenario import load_scenario

UTIME0 = 1_700_000_000_000_000  # [µs] a wall clock's, as drake-franka-driver stamps them
ROBOT_UTIME0 = 5_000_000  # [µs] the robot's own clock
MAX_JOINT_STEP = 2e-3  # [rad per period] set for the jump tests: below every joint's velocity limit × 1 ms
DURATION = 0.05  # [s] the scenario's: a drive that runs to its end takes 50 ticks


@pytest.fixture(scope="module")
def side():
    """panda_wipe's controller side with the sensor, a 0.3 s first wait and an explicit
    max_joint_step (built once: the tests reset it)."""
    s = load_scenario("panda_wipe", duration=DURATION)
    driver = dataclasses.replace(s.driver, first_status_timeout=0.3, max_joint_step=MAX_JOINT_STEP)
    return build_controller_side(dataclasses.replace(s, driver=driver))


class Robot:
    """A Panda at q (``v`` its reported velocity) that schedules status after status on
    ``bus``: each ``after`` [s] of arrival time after the previous, its clocks ``periods``
    periods on, with a force-torque message at the same instant (``force_torque``)."""

    def __init__(self, bus: FakeBus, loop: ControllerLoop):
        self.bus, self.period_us = bus, loop.period_us
        self.q = np.array(loop.side.station.q0, dtype=float)
        self.v = np.zeros(7)
        self.arrival, self.utime, self.robot_utime = 0.0, UTIME0, ROBOT_UTIME0
        self.force_torque = True

    def status(
        self, after: float, periods: float = 1, *, q=None, clock_us: int | None = None, rate=1.0
    ) -> int:
        """The next status (``rate``: its control_command_success_rate); returns its utime."""
        step = round(periods * self.period_us) if clock_us is None else clock_us
        self.arrival += after
        self.utime += step
        self.robot_utime += step
        q = self.q if q is None else q
        message = lcmt_panda_status.decode(
            status_bytes(q, utime=self.utime, robot_utime=self.robot_utime, v=self.v)
        )
        message.control_command_success_rate = rate
        self.bus.at(self.arrival, "PANDA_STATUS", message.encode())
        if self.force_torque:
            self.bus.at(self.arrival, "PANDA_FORCE_TORQUE", force_torque_bytes())
        return self.utime


def make_loop(side, capacity: int = 200):
    """A loop on a fake bus, ready, its robot scripted; (loop, robot, bus)."""
    bus = FakeBus()
    side.reset()
    loop = ControllerLoop(side, bus, clock=bus.clock, capacity=capacity)
    loop.ready()
    return loop, Robot(bus, loop), bus


def started(side):
    """A loop that answered its first status (one period after the bus's start)."""
    loop, robot, bus = make_loop(side)
    robot.status(loop.period)
    loop.start()
    return loop, robot, bus


# --- a gap counted in periods: the slow stream ------------------------------------------


def test_gaps_of_exactly_two_periods_are_a_slow_stream_s(side):
    """SLOW_STREAM statuses in a row each exactly two periods after the previous: the last
    of them stops the controller, none before it (catches gaps counted from more than
    two periods: a 500 Hz stream against a 1 kHz controller never refused)."""
    loop, robot, bus = started(side)
    T = loop.period
    for _ in range(SLOW_STREAM - 1):
        robot.status(2 * T, 2)
        loop.tick()
    assert loop.commands == SLOW_STREAM
    robot.status(2 * T, 2)
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    assert f"{SLOW_STREAM} statuses in a row came two periods or more apart" in info.value.problem
    assert loop.commands == SLOW_STREAM


def test_a_status_one_period_on_ends_a_run_of_two_period_gaps(side):
    """SLOW_STREAM − 1 gaps of two periods, one of a period, SLOW_STREAM − 1 of two again:
    no fault (lost statuses now and then; catches a count that is not reset, or one that
    takes 1.5 periods, rounded to 2 by the clock but not a gap of two, as two)."""
    loop, robot, bus = started(side)
    T = loop.period
    for periods in [2] * (SLOW_STREAM - 1) + [1] + [2] * (SLOW_STREAM - 1):
        robot.status(periods * T, periods)
        loop.tick()
    assert loop.commands == 2 * SLOW_STREAM and loop.periods == 4 * (SLOW_STREAM - 1) + 1


# --- the silence bound, on the wall clock and on the status's own clock ----------------


def test_a_status_exactly_at_the_silence_bound_is_answered(side):
    """A status that arrives exactly the silence bound after the last one, its clock that
    many periods on: answered (a late status within the bound is a glitch, not a fault),
    its time that many periods on."""
    loop, robot, bus = started(side)
    periods = loop.bound / loop.period
    robot.status(loop.bound, periods)
    loop.tick()
    assert loop.commands == 2 and loop.periods == round(periods)


def test_a_status_clock_one_microsecond_past_the_bound_is_refused(side):
    """The same status with its clock 1 µs further: refused as a clock that jumped (catches
    a bound compared with ≥ on the wrong side, or in other units than the silence's)."""
    loop, robot, bus = started(side)
    robot.status(loop.bound, clock_us=round(loop.bound * 1e6) + 1)
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    assert "jumped" in info.value.problem and loop.commands == 1


def test_silence_just_past_the_bound_stops_the_controller(side):
    """No status for just over the bound after the last one's arrival: a fault, declared
    within 10 µs of the bound on the fake clock (catches silence a period late)."""
    loop, robot, bus = started(side)
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    waited = bus.now - robot.arrival
    assert loop.bound < waited <= loop.bound + 1e-5, waited
    assert info.value.problem.startswith("no lcmt_panda_status on PANDA_STATUS")


SECOND_PERIOD = 2e-3  # [s] a control period other than panda_wipe's 1 ms (issue 46)


def at_period(side, period: float):
    """``side`` with its scenario's control period ``period`` [s]: the loop's timing rules
    read the period from the scenario (as test_wire_faults.py's expire_sec test does)."""
    return dataclasses.replace(side, scenario=dataclasses.replace(side.scenario, control_period=period))


@pytest.mark.parametrize("period", [1e-3, SECOND_PERIOD], ids=["1 ms", "2 ms"])
def test_the_silence_bound_is_driver_expire_sec_at_any_control_period(side, period):
    """At 1 ms and at 2 ms (issue 46, mistake 2): a status that arrives driver.expire_sec
    after the last, its clock expire_sec / period periods on, is answered; then, with no
    status, silence is declared within 10 µs after expire_sec, a figure read from the
    configuration (not from the loop's own bound). Catches the bound computed as its
    periods × 1 ms (at 2 ms, half the driver's expiry: the status at 50 ms refused as
    silence at 25 ms), or its periods taken as seconds."""
    loop, robot, bus = started(at_period(side, period))
    expire = loop.config.expire_sec
    assert loop.period == period and expire == 0.05
    periods = round(expire / period)
    robot.status(expire, periods)
    loop.tick()
    assert loop.commands == 2 and loop.periods == periods
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    waited = bus.now - robot.arrival
    assert expire < waited <= expire + 1e-5, waited
    assert info.value.problem.startswith("no lcmt_panda_status on PANDA_STATUS for 50.0 ms")


@pytest.mark.parametrize("period", [1e-3, SECOND_PERIOD], ids=["1 ms", "2 ms"])
def test_the_sensor_s_silence_bound_is_driver_expire_sec_at_any_control_period(side, period):
    """The force-torque messages stop with the first status; statuses go on every period.
    At 1 ms and at 2 ms every status that arrives less than driver.expire_sec after the
    sensor's last message is answered, and the first one past it (expire_sec + half a
    period) stops the controller naming the sensor. Catches the sensor's bound in periods
    × 1 ms (at 2 ms refused after 25 ms, at the 13th status)."""
    loop, robot, bus = started(at_period(side, period))
    expire = loop.config.expire_sec
    robot.force_torque = False
    before = round(expire / period) - 1  # statuses at 1 … before periods: all within expire_sec
    for _ in range(before):
        robot.status(period)
        loop.tick()
    assert loop.commands == 1 + before
    robot.status(expire + 0.5 * period - before * period, 1)
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    silent_ms = (expire + 0.5 * period) * 1e3  # 50.5 ms at 1 ms, 51.0 ms at 2 ms
    assert info.value.problem.startswith(
        f"no lcmt_force_torque on PANDA_FORCE_TORQUE for {silent_ms:.1f} ms"
    ), info.value.problem
    assert loop.commands == 1 + before


class RecordingBus(FakeBus):
    """A FakeBus that keeps every wait the loop asked of it (its timeouts [ms])."""

    def __init__(self):
        super().__init__()
        self.waits: list[int] = []

    def handle(self, timeout_ms: int) -> int:
        self.waits.append(timeout_ms)
        return super().handle(timeout_ms)


@pytest.mark.parametrize("when", ["early", "exact", "late"])
def test_the_first_status_is_awaited_exactly_first_status_timeout(side, when):
    """The first status arrives half the first wait (0.3 s here) in, exactly at its end,
    or 1 µs after it, on a clock that only the loop's waits advance: early and exact are
    answered when they arrive; late ends the wait at the timeout (to 1 µs), nothing sent,
    in one line naming the channel and the timeout. And what the loop asked of the bus:
    waits of 1 to 100 ms, never one that ends past the timeout (issue 46: fake clocks late,
    early and exact). Catches the timeout taken in other units, a wait that sleeps past it,
    or a status exactly at it refused."""
    bus = RecordingBus()
    side.reset()
    loop = ControllerLoop(side, bus, clock=bus.clock)
    loop.ready()
    robot, timeout = Robot(bus, loop), loop.config.first_status_timeout
    began = bus.now  # start() reads the clock here (ready() has drained the bus: 1 µs)
    arrival = began + {"early": 0.5 * timeout, "exact": timeout, "late": timeout + 1e-6}[when]
    robot.status(arrival)
    waits_from = len(bus.waits)
    if when == "late":
        with pytest.raises(DriveFaultError) as info:
            loop.start()
        assert str(info.value) == (
            f"before the first command: no lcmt_panda_status on PANDA_STATUS within {timeout:g} s; nothing "
            "was sent; stopped commanding after 0 command(s)"
        )
        assert timeout <= bus.now - began < timeout + 1e-6 and not bus.sent
    else:
        loop.start()
        assert bus.now == arrival and len(bus.sent) == 1 and bus.sent[0][1].utime == robot.utime
    asked = [w for w in bus.waits[waits_from:] if w]
    assert asked and all(1 <= w <= 100 for w in asked), asked
    assert sum(asked) * 1e-3 <= timeout + 1e-9, asked  # no wait asked past the timeout


# --- a jump, over the periods since the status answered last --------------------------


@pytest.mark.parametrize("how", ["one status two periods on", "two statuses queued in one tick"])
def test_a_joint_may_move_max_joint_step_per_period_since_the_answered_status(side, how):
    """Joint 7 moves steadily at 0.95 max_joint_step a period (its velocity reported to
    match). Two periods pass before the next answer: as one status two periods on, or as
    two statuses, one period apart, that arrive during one tick (the older skipped). The
    newest moved 1.9 steps from the answered one: taken; a newest 2.1 steps from it is
    refused, naming 2 periods. Catches the allowance taken over the newest status's own
    gap (one period when statuses were skipped: 1.9 steps refused), or over one period."""
    loop, robot, bus = make_loop(side)
    T, step = loop.period, loop.config.max_joint_step
    robot.v[6] = 0.95 * step / T
    robot.status(T)
    bus.tick_cost = T  # each tick ends a period after its status arrived: the next ones are in
    loop.start()

    def two_periods(last_q):
        if how == "one status two periods on":
            robot.q[6] += 2 * 0.95 * step
            robot.status(2 * T, 2, q=last_q)
        else:
            robot.q[6] += 0.95 * step
            robot.status(0.5 * T)
            robot.q[6] += 0.95 * step
            robot.status(0.1 * T, q=last_q)
        loop.tick()

    two_periods(None)
    assert loop.commands == 2 and loop.periods == 2
    answered = robot.q.copy()
    jump = answered.copy()
    jump[6] += 2.1 * step
    with pytest.raises(DriveFaultError) as info:
        two_periods(jump)
    assert "panda_joint7 moved" in info.value.problem and "in 2 period(s)" in info.value.problem


@pytest.mark.parametrize("sign", [1, -1], ids=["forward", "backward"])
def test_a_jump_is_refused_whichever_way_the_joint_moves(side, sign):
    """Joint 7 moves sign × 0.95 max_joint_step in a period, its reported velocity saying
    so: taken; then sign × 1.05 steps in the next, its velocity reported to match (the
    position/velocity rule sees nothing): refused, naming the joint, one period and the
    setting, forward and backward alike (issue 46, mistake 1). Catches the signed step
    compared with the allowance (a joint that moves backward any distance is answered)."""
    loop, robot, bus = make_loop(side)
    T, step = loop.period, loop.config.max_joint_step
    robot.v[6] = sign * 0.95 * step / T
    robot.status(T)
    loop.start()
    robot.q[6] += sign * 0.95 * step
    robot.status(T)
    loop.tick()
    assert loop.commands == 2
    robot.q[6] += sign * 1.05 * step
    robot.v[6] = sign * 1.15 * step / T  # the trapezoid of 0.95 and 1.15 steps a period: 1.05
    robot.status(T)
    with pytest.raises(DriveFaultError) as info:
        loop.tick()
    assert info.value.problem == (
        f"status refused: panda_joint7 moved {1.05 * step:.4g} rad in 1 period(s), more than the "
        f"{step:.4g} rad of driver.max_joint_step {step:g} rad per period"
    )
    assert loop.commands == 2


# --- which end of the queue: the newest, at the start too -------------------------------


@pytest.mark.parametrize("how", ["queued before start() was called", "waiting for the sensor"])
def test_start_answers_the_newest_status_queued_while_it_waited(side, how):
    """Three statuses, one period apart, arrive after ready() and before start() answers:
    queued on the bus before start() is called, or arriving while it waits for the
    sensor's first message (which comes with the third). start() answers the newest (its
    utime, its q), counts the others skipped, and the controller's clock starts there: the
    next status, a period later, is one period on. Catches the oldest queued status
    answered: a command for a status the robot no longer is in, which a real driver drops
    as stale."""
    loop, robot, bus = make_loop(side)
    T = loop.period
    robot.force_torque = how == "queued before start() was called"
    stamps = []
    for k in range(3):
        robot.force_torque = robot.force_torque or k == 2
        stamps.append(robot.status(T, q=robot.q + np.array([0, 0, 0, 0, 0, 0, 1e-3 * k])))
    if how == "queued before start() was called":
        bus.now = robot.arrival + 0.5 * T  # all three in the bus's queue, none handled
    loop.start()
    assert [c.utime for _, c in bus.sent] == [stamps[2]] and loop.skipped == 2
    np.testing.assert_allclose(loop.recorder.rows[0, 1:8], robot.q + np.array([0, 0, 0, 0, 0, 0, 2e-3]))
    robot.status(T, q=robot.q + np.array([0, 0, 0, 0, 0, 0, 2e-3]))
    loop.tick()
    assert loop.periods == 1 and loop.commands == 2


# --- the robot's success rate, counted once the drive has filled its window ------------


def test_the_success_rate_counts_from_the_status_after_the_window_s_last_command(side):
    """libfranka's control_command_success_rate is over its last SUCCESS_RATE_WINDOW
    cycles: the statuses loaded while the drive had sent fewer commands carry cycles
    before it (0.0 here, and 0.2 on the last of them: not counted); the one loaded when
    it has sent exactly that many carries 0.5 and is the minimum; later ones 1.0. Catches
    the window's boundary moved by one either way (0.2 counted, or 0.5 missed), or the
    figures of the first commands kept."""
    loop, robot, bus = make_loop(side, capacity=2 * SUCCESS_RATE_WINDOW)
    robot.status(loop.period, rate=0.0)
    loop.start()
    for sent in range(1, SUCCESS_RATE_WINDOW + 20):  # commands sent before this status is loaded
        rates = {SUCCESS_RATE_WINDOW - 1: 0.2, SUCCESS_RATE_WINDOW: 0.5}
        robot.status(loop.period, rate=rates.get(sent, 0.0 if sent < SUCCESS_RATE_WINDOW else 1.0))
        loop.tick()
    assert loop.success_rate_min == 0.5


# --- the process as the drive found it ---------------------------------------------------


def process_state() -> dict:
    return {
        "frozen": gc.get_freeze_count(),
        "gc enabled": gc.isenabled(),
        "gc callbacks": list(gc.callbacks),
        "SIGINT handler": signal.getsignal(signal.SIGINT),
    }


@pytest.mark.parametrize("end", ["to the scenario's end", "no first status", "silence after five"])
def test_a_drive_leaves_the_collector_and_signals_as_it_found_them(side, end):
    """Drive.run (the collector frozen and disabled for the loop, Ctrl-C caught) to its end,
    or stopped by a fault before the first command or after five: afterwards nothing
    stays frozen that was not, the collector is enabled as before, its callbacks and the
    SIGINT handler are the ones before. Catches gc.freeze() without gc.unfreeze()
    (everything allocated before the loop stays in the permanent generation), a
    collector left disabled, a GcPauses callback or a Ctrl-C handler left installed,
    on any of the ways out."""
    bus = FakeBus()
    side.reset()
    loop = ControllerLoop(side, bus, clock=bus.clock)
    robot = Robot(bus, loop)
    statuses = {"to the scenario's end": round(DURATION / loop.period) + 1, "no first status": 0}.get(end, 5)
    for _ in range(statuses):
        robot.status(loop.period)
    before = process_state()
    run = Drive(loop, None).run()
    assert process_state() == before
    assert (run.failure is None) == (end == "to the scenario's end"), run.failure
    assert loop.commands == statuses
