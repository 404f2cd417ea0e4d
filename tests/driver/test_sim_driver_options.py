"""``nsdrake sim-driver``'s options against references nsdrake did not write (issue 37):
the torque low-pass (``low_pass_freq`` [Hz]) against SciPy's discretisation of the
first-order low-pass at that cutoff, the torque-rate limit against Franka's 1000 N m/s
times the period, the command expiry (``expire_sec`` [s]) and the reported
``control_command_success_rate`` (the fraction of the last 100 periods that applied a
fresh command) against hand-built sequences, and the newest of several commands applied.

The driver runs as ``nsdrake sim-driver`` runs it (:func:`serve_simulated_driver`) on
``memq://``, on a fake clock that reaches each period's deadline at once (no wait, no
real time: deterministic and fast), with a scripted controller in the same process that
answers the statuses it is told to. The torque the driver commanded over period k comes
back in the next status's ``joint_torque_desired``.
"""

from __future__ import annotations

import gc
import math

import numpy as np
import pytest
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcm
from scipy.signal import cont2discrete, dlsim

from nsdrake.driver.panda import TORQUE_RATE_LIMIT
from nsdrake.driver.serve import PHYSICS_AT, serve_simulated_driver
from nsdrake.experiment.scenario import load_scenario

UTIME0 = 1_700_000_000_000_000  # [µs] the fake wall clock's start
JOINT = 6  # the joint the step commands drive (panda_joint7: the lightest, it barely moves the arm)


@pytest.fixture(scope="module")
def scenario():
    return load_scenario("panda_wipe")


class FakeClock:
    """The driver's clock [s]: at each reading the next deadline the driver waits for (it
    reads the clock once at the start and twice a period: waiting for the period's middle,
    where the plant steps, and for its end), so that every deadline is met at once;
    ``utime`` the wall clock's µs on it."""

    def __init__(self, period: float):
        self.period, self.now, self._reads = period, 0.0, 0

    def __call__(self) -> float:
        # the driver's deadlines as it writes them (start + (k + PHYSICS_AT) periods, then
        # start + (k + 1) periods), to the bit, whatever PHYSICS_AT is
        k, middle = divmod(self._reads, 2)
        self.now = (k + PHYSICS_AT) * self.period if middle else k * self.period
        self._reads += 1
        return self.now

    def utime(self) -> int:
        return UTIME0 + round(self.now * 1e6)


class ScriptedController:
    """Answers status k (counted from 0) with ``torque(k)`` (7 values) when that is not
    None, carrying the status's utime; ``extra(k)``: a command sent just before it (an
    older one the driver must not prefer). Keeps every status."""

    def __init__(self, lcm, torque, extra=None):
        self.lcm, self.torque, self.extra, self.statuses = lcm, torque, extra, []
        self._subscription = lcm.Subscribe("PANDA_STATUS", self._on_status)

    def _send(self, utime: int, torque) -> None:
        command = lcmt_panda_command()
        command.utime, command.control_mode_expected = utime, lcmt_panda_status.CONTROL_MODE_TORQUE
        command.num_joint_torque, command.joint_torque = 7, [float(x) for x in torque]
        self.lcm.Publish("PANDA_COMMAND", command.encode())

    def _on_status(self, data: bytes) -> None:
        status = lcmt_panda_status.decode(data)
        k = len(self.statuses)
        self.statuses.append(status)
        if self.extra is not None and self.extra(k) is not None:
            utime, torque = self.extra(k)
            self._send(utime, torque)
        torque = self.torque(k)
        if torque is not None:
            self._send(status.utime, torque)

    def commanded(self) -> np.ndarray:
        """The torque the driver commanded over each period from the first: the next
        status's joint_torque_desired. (periods, 7) [N m]."""
        return np.array([s.joint_torque_desired for s in self.statuses[1:]])


def serve(scenario, periods: int, torque, *, extra=None, **options):
    """The simulated driver answered by ``ScriptedController(torque, extra)`` for
    ``periods`` periods after the first command, and one more, whose status carries the
    last of their torques back; (the driver's result, the controller)."""
    lcm = DrakeLcm("memq://")
    controller = ScriptedController(lcm, torque, extra)
    clock = FakeClock(scenario.control_period)
    result = serve_simulated_driver(
        scenario,
        lcm,
        duration=(periods + 1) * scenario.control_period,
        clock=clock,
        wall_utime=clock.utime,
        **options,
    )
    assert result.behind == 0 and result.periods == periods + 1, result.line()
    return result, controller


def step(value: float):
    """A step command on :data:`JOINT` from the first status on."""
    torque = np.zeros(7)
    torque[JOINT] = value
    return lambda k: torque


@pytest.mark.parametrize("cutoff", [30.0, 100.0, 7.5])
def test_the_torque_low_pass_is_the_first_order_filter_at_its_cutoff_in_hz(scenario, cutoff):
    """A 1 N m step through the driver's low-pass at ``cutoff`` Hz (30: drake-franka-
    driver's default), rate limit off: the torque commanded each period is SciPy's
    backward-difference discretisation of 1/(τ s + 1), τ = 1/(2π f_c) (libfranka's
    y = g u + (1 − g) y_prev, g = T/(T + τ), is exactly that), to 1e-12; and the step
    response's time constant, from its decay, is that filter's to 1%. Catches the cutoff
    taken in rad/s (τ = 1/f_c: 2π times slower), a filter on the wrong previous value, or
    one a period late."""
    T = scenario.control_period
    periods = 60
    _, controller = serve(scenario, periods, step(1.0), low_pass_freq=cutoff, rate_limit=False)
    got = controller.commanded()[:, JOINT]
    tau = 1.0 / (2.0 * math.pi * cutoff)
    filter_d = cont2discrete(([1.0], [tau, 1.0]), T, method="backward_diff")
    _, expected = dlsim(filter_d, np.ones(periods), t=np.arange(periods) * T)
    np.testing.assert_allclose(got, expected[:, 0], rtol=0, atol=1e-12)
    # the time constant, from the decay of u − y over 30 periods, against the filter's pole
    slope = np.polyfit(np.arange(30) * T, np.log(1.0 - got[:30]), 1)[0]
    measured = -1.0 / slope
    (pole,) = np.roots(filter_d[1]).real  # z = τ / (τ + T)
    assert measured == pytest.approx(-T / math.log(pole), rel=0.01)


def test_with_the_low_pass_off_the_command_is_applied_as_sent(scenario):
    """low_pass_freq 1000 Hz (libfranka's kMaxCutoffFrequency): no filter; a 0.4 N m step
    is commanded in full from the first period (the rate limit allows 1 N m a period)."""
    _, controller = serve(scenario, 10, step(0.4), low_pass_freq=1000.0, rate_limit=True)
    np.testing.assert_array_equal(controller.commanded()[:, JOINT], np.full(10, 0.4))


@pytest.mark.parametrize("cutoff", [999.0, 1000.0])
def test_the_filter_is_off_from_1000_hz_on_and_on_just_below(scenario, cutoff):
    """low_pass_freq 1000 Hz is libfranka's kMaxCutoffFrequency, the value that means "no
    filter" (and any above it); the value beside it, 999 Hz, filters: its first period
    commands g = T / (T + 1/(2π 999)) = 0.863 of a 0.4 N m step, then SciPy's
    backward-difference filter, where 1000 Hz commands the step at once (issue 46: the value
    beside each sentinel; above 1000 Hz the option is refused, test_drive_cli.py). Catches
    the filter switched off below 1000 Hz, or left on at it."""
    T = scenario.control_period
    _, controller = serve(scenario, 5, step(0.4), low_pass_freq=cutoff, rate_limit=False)
    got = controller.commanded()[:, JOINT]
    if cutoff >= 1000.0:
        np.testing.assert_array_equal(got, np.full(5, 0.4))
        return
    filter_d = cont2discrete(([1.0], [1.0 / (2.0 * math.pi * cutoff), 1.0]), T, method="backward_diff")
    _, expected = dlsim(filter_d, np.full(5, 0.4), t=np.arange(5) * T)
    np.testing.assert_allclose(got, expected[:, 0], rtol=0, atol=1e-12)
    assert got[0] < 0.9 * 0.4


def test_the_torque_rate_limit_is_1000_n_m_per_second(scenario):
    """Filter off, rate limit on: a 5.5 N m step then a step back to 0 at the 20th status.
    Each period the commanded torque moves by at most 1000 N m/s × T (1 N m at 1 kHz), and
    by exactly that while it has not reached the command: 1, 2, …, 5, 5.5, then down
    4.5, …, 0. Catches the limit applied per period (1000 N m a period: the step at once),
    per millisecond of the wrong clock, or not at all."""
    T = scenario.control_period
    limit = TORQUE_RATE_LIMIT * T
    up = step(5.5)
    _, controller = serve(scenario, 40, lambda k: up(k) if k < 20 else np.zeros(7), low_pass_freq=1000.0)
    got = controller.commanded()[:, JOINT]
    k = np.arange(40)
    expected = np.where(k < 20, np.minimum(5.5, (k + 1) * limit), np.maximum(0.0, 5.5 - (k - 19) * limit))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert np.abs(np.diff(np.concatenate([[0.0], got]))).max() <= limit * (1 + 1e-12)


def test_filter_and_rate_limit_together_stay_within_the_rate_bound(scenario):
    """Both on (the driver's defaults): a 10 N m step at 30 Hz would take 1.59 N m in the
    first period; the rate limit holds every period's change to 1000 N m/s × T, and the
    torque still approaches the command."""
    T = scenario.control_period
    _, controller = serve(scenario, 60, step(10.0), low_pass_freq=30.0, rate_limit=True)
    got = controller.commanded()[:, JOINT]
    steps = np.diff(np.concatenate([[0.0], got]))
    assert steps.max() <= TORQUE_RATE_LIMIT * T * (1 + 1e-12) and steps[0] == pytest.approx(
        TORQUE_RATE_LIMIT * T
    )
    assert np.all(steps >= 0.0) and got[-1] > 9.0


def test_the_newest_of_several_commands_is_applied(scenario):
    """Each status answered by two commands in one period: an old one (another torque,
    the previous status's utime) then the answer: the driver applies the newest received
    (catches the first of the queued commands taken)."""
    old = np.full(7, 0.3)
    _, controller = serve(
        scenario,
        10,
        step(0.2),
        extra=lambda k: (UTIME0 + (k - 1) * 1000, old) if k else None,
        low_pass_freq=1000.0,
    )
    np.testing.assert_array_equal(controller.commanded()[:, JOINT], np.full(10, 0.2))


@pytest.mark.parametrize("expire_sec", [0.02, 0.005])
def test_a_command_expires_after_expire_sec_of_the_wall_clock(scenario, expire_sec):
    """The controller answers the first 10 statuses (0-9) and falls silent: the driver
    applies the answer to status 9 while the wall clock is within ``expire_sec`` of its
    utime, counting it fresh one period on (status 10: the command answering the status
    before) and stale after, then damps (expired). On the fake wall clock, at period k
    the command is (k − 9) ms old: taken up to k = 9 + expire_sec / T inclusive (exactly
    expire_sec old is not older than it). Catches expire_sec taken in ms or in periods of
    another length, the boundary moved by one, or a command never expired."""
    T = scenario.control_period
    periods = 60
    result, _ = serve(scenario, periods, lambda k: np.zeros(7) if k < 10 else None, expire_sec=expire_sec)
    last_taken = 9 + round(expire_sec / T)
    assert (result.fresh, result.stale) == (11, last_taken - 10), result.line()
    assert result.expired == periods - last_taken and result.commands == 10


def test_the_success_rate_is_over_the_last_100_periods(scenario):
    """A hand-built sequence: the controller answers statuses 0-119, then only one in
    three (120, 123, …). Period k applies the answer to the newest answered status j ≤ k,
    fresh when k − j ≤ 1 (the answer to status k itself, in one process, or to k − 1): so
    from 120 on two periods in three are fresh. The rate each status reports is the mean
    of the flags of the last 100 periods before it (1.0 before any): 1.0 up to 120, then
    falling to about 2/3 by 220. Checked at every status. Catches the first 100 periods
    kept instead of the last 100 (the rate stays 1.0), or a window of another length."""
    periods = 220
    answered = lambda k: k < 120 or (k - 120) % 3 == 0  # noqa: E731
    _, controller = serve(
        scenario, periods, lambda k: np.zeros(7) if answered(k) else None, low_pass_freq=1000.0
    )
    last, flags = -1, []
    for k in range(periods):
        last = k if answered(k) else last
        flags.append(1.0 if k - last <= 1 else 0.0)
    expected = [1.0] + [float(np.mean(flags[max(0, n - 100) : n])) for n in range(1, periods + 1)]
    reported = [s.control_command_success_rate for s in controller.statuses]
    np.testing.assert_allclose(reported[: periods + 1], expected, rtol=0, atol=1e-12)
    assert reported[periods] == pytest.approx(2.0 / 3.0, abs=0.01)


def test_the_collector_is_left_as_it_was_found(scenario):
    """The driver freezes what it built out of the collector for its loop: after it, the
    permanent generation holds what it held before (catches gc.freeze() without
    gc.unfreeze(): everything allocated before the loop stays uncollectable afterwards)."""
    frozen, enabled = gc.get_freeze_count(), gc.isenabled()
    serve(scenario, 5, step(0.0), low_pass_freq=1000.0)
    assert (gc.get_freeze_count(), gc.isenabled()) == (frozen, enabled)


# ---------------------------------------------------------- the driver's own clock (issue 46)


class WaitedClock:
    """The driver's clock [s], on which time passes only as the driver waits (its bus's
    wait and ``time.sleep``, each advancing it by what was asked) and as its own work
    costs: ``work_ends(what, k)`` gives the time [s] at which the status's publish
    ("status") or the plant's step ("step") of period k ends (None: at once). So the
    clock is early (the driver must wait for each deadline), exact (work that ends on a
    deadline) or late (work that overruns one), as the test chooses. Records when each
    status went out and each plant step began, on this clock."""

    def __init__(self, work_ends=lambda what, k: None):
        self.now, self.work_ends = 0.0, work_ends
        self.statuses: list[float] = []
        self.steps: list[float] = []

    def __call__(self) -> float:
        return self.now

    def sleep(self, seconds: float) -> None:
        self.now += max(seconds, 0.0)

    def work(self, what: str, k: int) -> None:
        end = self.work_ends(what, k)
        if end is not None:
            self.now = max(self.now, end)

    def utime(self) -> int:
        return UTIME0 + round(self.now * 1e6)


class WaitingBus:
    """``memq://`` as the driver's bus, its waits on :class:`WaitedClock`: a wait that
    delivers nothing lasts its whole timeout; a status published costs its work."""

    def __init__(self, clock: WaitedClock):
        self.inner, self.clock = DrakeLcm("memq://"), clock

    def Subscribe(self, channel, handler):  # noqa: N802 (DrakeLcm's names)
        return self.inner.Subscribe(channel, handler)

    def Publish(self, channel, data):  # noqa: N802
        if channel == "PANDA_STATUS":
            k = len(self.clock.statuses)
            self.clock.statuses.append(self.clock.now)
            self.clock.work("status", k)
        self.inner.Publish(channel, data)

    def HandleSubscriptions(self, timeout_millis):  # noqa: N802
        handled = self.inner.HandleSubscriptions(0)
        if not handled:
            self.clock.now += timeout_millis * 1e-3
        return handled


def serve_on(scenario, clock: WaitedClock, periods: int, monkeypatch):
    """serve_simulated_driver for ``periods`` periods after the first command on
    ``clock`` (a scripted controller answering every status with zero torque); each
    plant step recorded and costed on the clock. The driver's result."""
    import types

    import nsdrake.driver.serve as serve_module
    from nsdrake.driver.simulated_driver import SimulatedDriver

    advance = SimulatedDriver.advance

    def recorded_advance(driver):
        k = len(clock.steps)
        clock.steps.append(clock.now)
        advance(driver)
        clock.work("step", k)

    monkeypatch.setattr(SimulatedDriver, "advance", recorded_advance)
    monkeypatch.setattr(serve_module, "time", types.SimpleNamespace(sleep=clock.sleep))
    bus = WaitingBus(clock)
    ScriptedController(bus.inner, lambda k: np.zeros(7))
    return serve_simulated_driver(
        scenario, bus, duration=periods * scenario.control_period, clock=clock, wall_utime=clock.utime
    )


LATE_STATUS, LATE_STEP = 3, 6  # the periods whose status's work, and whose step, run late


@pytest.mark.parametrize("timing", ["early", "exact", "late"])
def test_the_driver_steps_mid_period_and_counts_the_periods_it_started_late(scenario, timing, monkeypatch):
    """The simulated driver on a clock that only its waits and its work advance (not one
    that hands it its own deadlines). Early (its work costs nothing): status k goes out at
    k T and the plant steps at (k + PHYSICS_AT) T, each after a wait; exact (the status's
    work ends at (k + PHYSICS_AT) T, the step's at (k + 1) T): the same times without a
    wait, and no period counted late (a deadline met exactly is met); late (status 3's
    work ends 0.8 T into its period, past the middle; step 6 ends 0.8 T into period 7):
    step 3 begins at 3.8 T, status 7 goes out at 7.8 T and status 8 at 8 T again (deadlines
    from the start, no drift), step 7 at once after status 7 (its middle is past), and
    ``behind`` counts one period, period 7's start, not the middles that steps 3 and 7
    missed. Catches the plant stepped at once after the status instead
    of mid-period, the mid-period wait counted in ``behind``, a deadline met exactly
    counted late, and deadlines that drift after a late period."""
    T, periods = scenario.control_period, 12

    def work_ends(what, k):
        if timing == "exact":
            return (k + PHYSICS_AT) * T if what == "status" else (k + 1) * T
        if timing == "late" and what == "status" and k == LATE_STATUS:
            return (k + 0.8) * T
        if timing == "late" and what == "step" and k == LATE_STEP:
            return (k + 1.8) * T
        return None

    clock = WaitedClock(work_ends)
    result = serve_on(scenario, clock, periods, monkeypatch)
    n = len(clock.steps)
    assert n >= periods and len(clock.statuses) == n
    status_at = np.arange(n) * T
    step_at = (np.arange(n) + PHYSICS_AT) * T
    if timing == "late":
        step_at[LATE_STATUS] = (LATE_STATUS + 0.8) * T
        status_at[LATE_STEP + 1] = step_at[LATE_STEP + 1] = (LATE_STEP + 1.8) * T  # its middle passed too
    np.testing.assert_allclose(clock.statuses, status_at, rtol=0, atol=1e-12)
    np.testing.assert_allclose(clock.steps, step_at, rtol=0, atol=1e-12)
    assert result.behind == (1 if timing == "late" else 0), result.line()
