"""``nsdrake sim-driver``: the simulated driver alone on a bus, free-running as
drake-franka-driver runs a Panda in torque mode (its ``franka-driver/franka_driver.cc``,
read, not run here). Each period k, on the driver's own clock at real time, whether or
not commands come:

1. the status of t_k is published, ``utime`` the wall clock [µs] (as the driver stamps
   it: an NTP step moves it), ``robot_utime`` the robot's own clock (t_k, from
   :data:`ROBOT_UP_US`), ``robot_mode``
   2 (kMove, the mode that takes torque commands) and ``control_command_success_rate``
   the fraction of the last 100 periods that applied a fresh command (the robot's figure
   is its own, of the commands that reached it in time: an analogue);
2. the commands that arrived are taken and the newest is applied over [t_k, t_{k+1}): the
   one answering status k−1 when the controller answered within its period (a *fresh*
   command: one period late, as the real driver's next callback applies it; in one
   process over memq:// the answer to status k itself can be in already, also fresh),
   else an older one (*stale*), until its ``utime`` lies more than ``expire_sec`` from the wall
   clock; then (and before the first command) damping −k_d q̇ with the robot's gravity
   compensation, k_d the driver's own (37.5, 50, 37.5, 25, 5, 3.75, 2.5 N m s/rad);
3. optionally, as libfranka does with the driver's ``--low_pass_freq`` (30 Hz by
   default; 1000 turns it off) and its rate limiter, the torque is low-pass filtered and
   its rate limited to 1000 N m/s;
4. the plant steps one period, from the middle of the period on (:data:`PHYSICS_AT`),
   then the driver waits for the wall clock (blocking on the bus, never spinning: a
   spinning driver takes the CPU the controller needs).

Where the physics runs in the period is the stand-in's own choice: a real Panda computes
its physics for free, the simulated one costs the PC its plant's step every period (issue
44 cut the rest: ``python bench/bench_stand_in.py`` measures the stand-in's CPU per period
before and after). Run at once after the status, it competed with the controller for the
CPU exactly while the controller answers that status (on the project's 2-core VM the
controller's status-to-command time had a p99.9 of 1.8 ms, 29 answers over 1 ms in 20 s);
from the middle of the period on, it runs after the answer (p99.9 0.44 ms, 2-9 over 1 ms),
and the command it steps with was taken at the period's start, as the real driver's
callback takes it.

The station's diagram (:func:`nsdrake.driver.simulated_driver.build_simulated_driver`)
gives this loop the messages of each t_k, which it stamps and publishes, and takes the
torque it chose for the period (no bus of its own, no logs: what the PC pays for the
stand-in robot is its plant's step and the messages, issue 44).
"""

from __future__ import annotations

import contextlib
import dataclasses
import gc
import math
import struct
import time
from dataclasses import dataclass, field

import numpy as np
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcmInterface

from nsdrake.driver.panda import NUM_JOINTS, TORQUE_RATE_LIMIT
from nsdrake.driver.realtime import RealtimeSettings, realtime_mode
from nsdrake.driver.simulated_driver import SimulatedDriver
from nsdrake.driver.wire import stamp_status
from nsdrake.experiment.driver_config import driver_problems
from nsdrake.experiment.scenario import Scenario

DAMPING = np.array([37.5, 50.0, 37.5, 25.0, 5.0, 3.75, 2.5])  # [N m s/rad] drake-franka-driver's k_d
ROBOT_MODE_MOVE = 2  # lcmt_panda_status.kMove: the mode in which the robot takes torque commands
NO_FILTER = 1000.0  # [Hz] libfranka's kMaxCutoffFrequency: at or above it the filter is off
# [µs] the robot's clock when the simulation starts: libfranka's RobotState::time counts from
# the robot's start, never 0 at a driver's first status (and 0 means "no robot_utime" to the
# controller side, which would fall back to the wall clock's utime)
ROBOT_UP_US = 60_000_000
# the fraction of the period after the status at which the simulated plant steps (module
# docstring): the first half is the controller's to answer in
PHYSICS_AT = 0.5
_thread_time = time.thread_time  # the serving thread's CPU clock (a test may replace the module's time)


@dataclass
class ServeResult:
    periods: int = 0  # periods simulated after the first command
    commands: int = 0  # commands received
    fresh: int = 0  # periods (after the first command) that applied the command answering the previous status
    stale: int = 0  # … that applied an older command, not yet expired
    expired: int = 0  # … that fell back to damping (no command within expire_sec)
    behind: int = 0  # periods the driver itself started late (its own step overran the period)
    undecodable: int = 0  # messages on the command channel that were not an lcmt_panda_command (dropped)
    # periods, and fresh ones, up to the last command received (the controller's run; after
    # it the driver damps until it is stopped, which is not the controller's doing)
    commanded_periods: int = 0
    commanded_fresh: int = 0
    ages: dict[int, int] = field(default_factory=dict)  # periods between the applied command's status and now
    # the robot's clock [µs] of the statuses the first and the last command received answered
    # (None: not among the last 50 published): the controller's own time should end at their difference
    answered_robot_us: list[int | None] = field(default_factory=lambda: [None, None])
    # the serving thread's scheduling and locked memory, read back (nsdrake.driver.realtime.Applied)
    realtime: dict = field(default_factory=dict)
    cpu_seconds: float = 0.0  # the serving thread's CPU time over its periods [s]
    served: int = 0  # periods served (the first command's wait included)

    @property
    def fresh_fraction(self) -> float:
        """Of the periods up to the last command received, those that applied a fresh one."""
        return self.commanded_fresh / self.commanded_periods if self.commanded_periods else math.nan

    @property
    def cpu_per_period_us(self) -> float:
        """The serving thread's CPU time per period served [µs] (the plant's step, the bus)."""
        return 1e6 * self.cpu_seconds / self.served if self.served else math.nan

    def line(self) -> str:
        return (
            f"{self.commanded_periods} periods from the first command to the last, {self.commanded_fresh} "
            f"of them applied a fresh command ({100 * self.fresh_fraction:.2f}%); in all "
            f"{self.periods} periods after the first command, {self.commands} commands received; "
            f"{self.fresh} applied a fresh command, {self.stale} a stale one, "
            f"{self.expired} fell back to damping; the driver itself started {self.behind} periods late"
            + self._answered()
            + _realtime_note(self.realtime)
            + (f"; its own CPU {self.cpu_per_period_us:.0f} µs per period" if self.served else "")
            + (f"; {self.undecodable} undecodable command messages dropped" if self.undecodable else "")
        )

    def _answered(self) -> str:
        first, last = self.answered_robot_us
        if first is None or last is None:
            return ""
        return f"; the commands answered the statuses from robot time {first} µs to {last} µs"


def _realtime_note(applied: dict) -> str:
    if applied.get("policy") != "SCHED_FIFO":
        return ""
    return (
        f"; real-time: SCHED_FIFO {applied['priority']} on cores {applied['cores']}, "
        f"{applied['memory_locked_kb'] // 1024} MB locked"
    )


class SimulatedDriverStopError(RuntimeError):
    """The simulated driver stopped on a command it cannot apply, as drake-franka-driver
    does (its torque loop throws on a command not in torque mode; libfranka refuses a
    non-finite torque): one line; ``result`` what it served until then."""

    def __init__(self, problem: str, result: ServeResult):
        self.result = result
        super().__init__(problem)


def command_problem(command: lcmt_panda_command) -> str | None:
    """Why the driver cannot apply ``command`` in torque mode (None: it can)."""
    torque = lcmt_panda_status.CONTROL_MODE_TORQUE
    if command.control_mode_expected != torque or command.num_joint_torque != NUM_JOINTS:
        return (
            f"a command that is not a torque command of {NUM_JOINTS} joints (control_mode_expected "
            f"{command.control_mode_expected}, expected {torque}; "
            f"num_joint_torque {command.num_joint_torque})"
        )
    values = np.asarray(command.joint_torque, dtype=float)
    if not np.isfinite(values).all():
        k = int(np.flatnonzero(~np.isfinite(values))[0])
        return f"a command whose joint_torque[{k}] is {float(values[k])!r}"
    return None


def lowpass(previous: np.ndarray, value: np.ndarray, period: float, cutoff: float) -> np.ndarray:
    """libfranka's first-order filter: y = g u + (1 − g) y_prev, g = T / (T + 1/(2π f_c))."""
    if cutoff >= NO_FILTER:
        return value
    gain = period / (period + 1.0 / (2.0 * math.pi * cutoff))
    return gain * value + (1.0 - gain) * previous


def option_problems(scenario: Scenario, expire_sec: float | None, low_pass_freq: float):
    """Yields (option, problem) for ``nsdrake sim-driver``'s options beyond what they may be,
    bounded as the scenario's fields are: ``--expire-sec`` by ``driver.expire_sec``'s own
    rules (:func:`nsdrake.experiment.driver_config.driver_problems`: two periods to 0.1 s:
    the same number on both sides), ``--low-pass-freq`` a cutoff in (0, NO_FILTER] Hz
    (NO_FILTER, libfranka's kMaxCutoffFrequency, turns the filter off; a larger number
    means nothing more, and is most likely a typo for a filter that is on)."""
    if expire_sec is not None:
        driver = dataclasses.replace(scenario.driver, expire_sec=expire_sec)
        for where, problem in driver_problems(driver, scenario.control_period):
            if where == "expire_sec":
                yield "--expire-sec", f"{problem} (as the scenario's driver.expire_sec)"
    if not (isinstance(low_pass_freq, int | float) and 0.0 < low_pass_freq <= NO_FILTER):
        yield (
            "--low-pass-freq",
            f"must be a cutoff in (0, {NO_FILTER:g}] Hz ({NO_FILTER:g}, libfranka's kMaxCutoffFrequency, "
            f"turns the filter off), got {low_pass_freq!r}",
        )


class SimulatedDriverOptionError(ValueError):
    """An option of :func:`serve_simulated_driver` beyond its bounds; one line naming it."""


def serve_simulated_driver(
    scenario: Scenario,
    lcm: DrakeLcmInterface,
    *,
    duration: float | None = None,
    expire_sec: float | None = None,
    low_pass_freq: float = 30.0,
    rate_limit: bool = True,
    progress=None,
    stop=None,
    clock=time.perf_counter,
    wall_utime=lambda: time.time_ns() // 1000,
    realtime: RealtimeSettings | None = None,
) -> ServeResult:
    """The simulated driver on ``lcm`` (module docstring) for ``duration`` [s] (default the
    scenario's) after the first command; ``expire_sec`` [s] default the scenario's
    ``driver.expire_sec`` (the controller's silence bound: the same number on both sides);
    ``stop``: a :class:`nsdrake.driver.stop.StopRequest` that ends it at the next period;
    ``realtime``: the serving thread in real time (:mod:`nsdrake.driver.realtime`:
    SCHED_FIFO, a core, memory locked, the collector off)."""
    for option, problem in option_problems(scenario, expire_sec, low_pass_freq):
        raise SimulatedDriverOptionError(f"{option}: {problem}")
    expire_sec = scenario.driver.expire_sec if expire_sec is None else expire_sec
    server = _Server(scenario, lcm, expire_sec, low_pass_freq, rate_limit, wall_utime)
    duration = scenario.duration if duration is None else duration
    period = server.period
    server.driver.start()
    # everything built so far (Drake's diagram, its Python wrappers) frozen out of the
    # collector: a full collection took 16-69 ms in this loop (measured), more than the
    # controller's silence bound; the loop's own young objects are still collected
    gc.collect()
    gc.freeze()
    with idle_cpus_polling(), realtime_mode(realtime) as applied:
        server.result.realtime = applied.as_dict()
        cpu, k = _thread_time(), 0
        try:
            start = clock()  # deadlines start + k periods: no rounding drift
            while server.first is None or server.driver.time < server.first + duration - 0.5 * period:
                if stop is not None and stop.requested:
                    break
                server.publish_status()
                server.take_command()
                server.wait_until(start + (k + PHYSICS_AT) * period, clock, count=False)
                server.step()
                k += 1
                server.wait_until(start + k * period, clock)
                if progress is not None and server.first is not None and server.result.periods % 1000 == 0:
                    progress((server.driver.time - server.first) / duration)
        finally:
            server.result.cpu_seconds, server.result.served = _thread_time() - cpu, k
            gc.unfreeze()
    return server.result


@contextlib.contextmanager
def idle_cpus_polling():
    """For the block, idle CPUs kept out of their sleep states where the process may ask
    (Linux's PM QoS: 0 µs written to ``/dev/cpu_dma_latency`` and the file held open; root
    only), as real-time loops are run. Measured on this project's 2-core VM (cpuidle
    driver haltpoll): the driver's 0.6 ms wait for its next period overslept by 2-15 ms
    about once a second on an otherwise idle machine, halting its virtual CPU, and each
    oversleep of more than 2 ms is a status late beyond the controller's 3-period
    silence bound; holding the latency at 0 removed them (max gap between statuses
    1.09 ms over 20 s). Where the file cannot be opened the loop runs without it."""
    try:
        handle = open("/dev/cpu_dma_latency", "wb", buffering=0)  # noqa: SIM115 (held for the block)
    except OSError:
        yield False
        return
    try:
        handle.write(struct.pack("i", 0))
        yield True
    finally:
        handle.close()


class _Server:
    """One period of :func:`serve_simulated_driver` at a time (module docstring)."""

    def __init__(self, scenario, lcm, expire_sec, low_pass_freq, rate_limit, wall_utime):
        d = self.channels = scenario.driver
        self.period, self.lcm = scenario.control_period, lcm
        self.expire_us, self.low_pass_freq, self.rate_limit = expire_sec * 1e6, low_pass_freq, rate_limit
        self.wall_utime = wall_utime
        self.driver = SimulatedDriver(scenario, None, adds_gravity=d.robot_adds_gravity, record=False)
        self.plant = self.driver.built.station.plant
        self.plant_context = self.plant.GetMyContextFromRoot(self.driver.context)
        self.received: list[lcmt_panda_command] = []
        lcm.Subscribe(d.command_channel, self._on_command)
        self.result, self.recent = ServeResult(), []
        self.command, self.applied = None, np.zeros(NUM_JOINTS)
        self.published: list[int] = []  # utime of each status published
        self.published_robot: list[int] = []  # … and its robot_utime
        self.first = None

    def _on_command(self, data: bytes) -> None:
        """A command received: kept to apply; bytes that do not decode are dropped and
        counted (as LCM's typed subscription in drake-franka-driver drops them)."""
        try:
            self.received.append(lcmt_panda_command.decode(data))
        except ValueError:
            self.result.undecodable += 1

    def publish_status(self) -> None:
        """The status of t_k and the sensor's message, stamped t_k, sent now (then the
        sensor's): a period's status goes out before the command answering the previous one
        is taken, as the real driver's callback publishes first."""
        d = self.channels
        status, force_torque = self.driver.messages()
        robot_utime, utime = ROBOT_UP_US + round(self.driver.time * 1e6), self.wall_utime()
        rate = float(np.mean(self.recent)) if self.recent else 1.0
        # stamped in place (wire.stamp_status: no decode, no encode)
        self.lcm.Publish(d.status_channel, stamp_status(status, utime, robot_utime, ROBOT_MODE_MOVE, rate))
        self.published.append(utime)
        self.published_robot.append(robot_utime)
        self.lcm.Publish(d.force_torque_channel, force_torque)

    def take_command(self) -> None:
        """The newest command unless expired (else damping), filtered and rate limited,
        counted: the torque of this period (:meth:`step` applies it)."""
        self.lcm.HandleSubscriptions(0)
        got_command = bool(self.received)
        if got_command:
            self.result.commands += len(self.received)
            self.command = self.received[-1]
            self.received.clear()
            problem = command_problem(self.command)
            if problem:
                raise SimulatedDriverStopError(problem, self.result)
            self._answered(self.command.utime)
            if self.first is None:
                self.first = self.driver.time
        if self.command is not None and abs(self.wall_utime() - self.command.utime) > self.expire_us:
            self.command = None
        v = self.plant.GetVelocities(self.plant_context)
        wanted = np.asarray(self.command.joint_torque) if self.command is not None else -DAMPING * v
        torque = lowpass(self.applied, wanted, self.period, self.low_pass_freq)
        if self.rate_limit:
            limit = TORQUE_RATE_LIMIT * self.period
            torque = np.clip(torque, self.applied - limit, self.applied + limit)
        self.applied = torque
        if self.first is not None:
            self._count(got_command)

    def step(self) -> None:
        """The plant stepped one period with the torque :meth:`take_command` chose."""
        self.driver.apply_torque(self.applied, utime=self.published[-1] if self.published else 0)
        self.driver.advance()

    def _answered(self, utime: int) -> None:
        """The robot time of the status a command received answers, kept for the first and the last."""
        recent = self.published[-50:]
        if utime in recent:
            robot = self.published_robot[len(self.published) - len(recent) + recent.index(utime)]
            answered = self.result.answered_robot_us
            answered[0] = robot if answered[0] is None else answered[0]
            answered[1] = robot

    def _count(self, got_command: bool) -> None:
        result, command = self.result, self.command
        result.periods += 1
        if command is None:
            result.expired += 1
            self.recent.append(0.0)
        else:
            recent = self.published[-50:]
            age = len(recent) - 1 - recent.index(command.utime) if command.utime in recent else -1
            result.ages[age] = result.ages.get(age, 0) + 1
            fresh = 0 <= age <= 1  # answers the status just published (in-process) or the one before
            result.fresh += fresh
            result.stale += not fresh
            self.recent.append(float(fresh))
        del self.recent[:-100]
        if got_command:
            result.commanded_periods, result.commanded_fresh = result.periods, result.fresh

    def wait_until(self, when: float, clock, *, count: bool = True) -> None:
        """Until the wall clock reaches ``when``, blocking on the bus (never spinning);
        ``count``: a period's end, counted in ``behind`` when already past."""
        remaining = when - clock()
        if remaining < 0 and count:
            self.result.behind += 1
        while remaining > 0:
            if remaining > 1e-3:
                self.lcm.HandleSubscriptions(int(remaining * 1e3))  # until a message or the time
            else:
                time.sleep(remaining)
            remaining = when - clock()
