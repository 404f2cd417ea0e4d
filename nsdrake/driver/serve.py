"""``nsdrake sim-driver``: the simulated driver alone on a bus, free-running as
drake-franka-driver runs a Panda in torque mode (its ``franka-driver/franka_driver.cc``,
read, not run here). Each period k, on the driver's own clock at real time, whether or
not commands come:

1. the status of t_k is published, ``utime`` the wall clock [µs] (as the driver stamps
   it: an NTP step moves it), ``robot_utime`` the robot's own clock (t_k), ``robot_mode``
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
4. the plant steps one period, then the driver waits for the wall clock (blocking on the
   bus, never spinning: a spinning driver takes the CPU the controller needs).

The station's diagram (:func:`nsdrake.driver.simulated_driver.build_simulated_driver`)
runs on a private in-process bus; this loop forwards its statuses and sensor messages
to the real bus, and feeds it the torque it chose.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcm, DrakeLcmInterface

from nsdrake.driver.panda import NUM_JOINTS, TORQUE_RATE_LIMIT
from nsdrake.driver.simulated_driver import SimulatedDriver
from nsdrake.experiment.scenario import Scenario

DAMPING = np.array([37.5, 50.0, 37.5, 25.0, 5.0, 3.75, 2.5])  # [N m s/rad] drake-franka-driver's k_d
ROBOT_MODE_MOVE = 2  # lcmt_panda_status.kMove: the mode in which the robot takes torque commands
NO_FILTER = 1000.0  # [Hz] libfranka's kMaxCutoffFrequency: at or above it the filter is off


@dataclass
class ServeResult:
    periods: int = 0  # periods simulated after the first command
    commands: int = 0  # commands received
    fresh: int = 0  # periods (after the first command) that applied the command answering the previous status
    stale: int = 0  # … that applied an older command, not yet expired
    expired: int = 0  # … that fell back to damping (no command within expire_sec)
    behind: int = 0  # periods the driver itself started late (its own step overran the period)
    # periods, and fresh ones, up to the last command received (the controller's run; after
    # it the driver damps until it is stopped, which is not the controller's doing)
    commanded_periods: int = 0
    commanded_fresh: int = 0
    ages: dict[int, int] = field(default_factory=dict)  # periods between the applied command's status and now

    @property
    def fresh_fraction(self) -> float:
        """Of the periods up to the last command received, those that applied a fresh one."""
        return self.commanded_fresh / self.commanded_periods if self.commanded_periods else math.nan

    def line(self) -> str:
        return (
            f"{self.commanded_periods} periods from the first command to the last, {self.commanded_fresh} "
            f"of them applied a fresh command ({100 * self.fresh_fraction:.2f}%); in all "
            f"{self.periods} periods after the first command, {self.commands} commands received; "
            f"{self.fresh} applied a fresh command, {self.stale} a stale one, "
            f"{self.expired} fell back to damping; the driver itself started {self.behind} periods late"
        )


def lowpass(previous: np.ndarray, value: np.ndarray, period: float, cutoff: float) -> np.ndarray:
    """libfranka's first-order filter: y = g u + (1 − g) y_prev, g = T / (T + 1/(2π f_c))."""
    if cutoff >= NO_FILTER:
        return value
    gain = period / (period + 1.0 / (2.0 * math.pi * cutoff))
    return gain * value + (1.0 - gain) * previous


def serve_simulated_driver(
    scenario: Scenario,
    lcm: DrakeLcmInterface,
    *,
    duration: float | None = None,
    expire_sec: float = 0.05,
    low_pass_freq: float = 30.0,
    rate_limit: bool = True,
    progress=None,
    stop=None,
    clock=time.perf_counter,
    wall_utime=lambda: time.time_ns() // 1000,
) -> ServeResult:
    """The simulated driver on ``lcm`` (module docstring) for ``duration`` [s] (default the
    scenario's) after the first command; ``stop``: a :class:`nsdrake.driver.stop.StopRequest`
    that ends it at the next period."""
    d, period = scenario.driver, scenario.control_period
    inner = DrakeLcm("memq://")
    driver = SimulatedDriver(scenario, inner, adds_gravity=d.robot_adds_gravity)
    plant, plant_context = driver.built.station.plant, None
    plant_context = plant.GetMyContextFromRoot(driver.context)
    received: list[lcmt_panda_command] = []
    outgoing: list[tuple[str, bytes]] = []
    inner_subscriptions = [  # noqa: F841 (kept alive)
        inner.Subscribe(d.status_channel, lambda data: outgoing.append((d.status_channel, data))),
        inner.Subscribe(d.force_torque_channel, lambda data: outgoing.append((d.force_torque_channel, data))),
    ]
    subscription = lcm.Subscribe(  # noqa: F841
        d.command_channel, lambda data: received.append(lcmt_panda_command.decode(data))
    )
    result, recent = ServeResult(), []
    duration = scenario.duration if duration is None else duration
    command, applied = None, np.zeros(NUM_JOINTS)
    published: list[int] = []  # utime of each status published
    first = None
    driver.start()
    next_time = clock()
    while first is None or driver.time < first + duration - 0.5 * period:
        if stop is not None and stop.requested:
            break
        # 1. the status of t_k (published by the station's diagram when it reached t_k)
        for channel, data in outgoing:
            if channel == d.status_channel:
                status = lcmt_panda_status.decode(data)
                status.robot_utime = round(driver.time * 1e6)
                status.utime = wall_utime()
                status.robot_mode = ROBOT_MODE_MOVE
                status.control_command_success_rate = float(np.mean(recent)) if recent else 1.0
                published.append(status.utime)
                data = status.encode()
            lcm.Publish(channel, data)
        outgoing.clear()
        # 2. the newest command that arrived, unless expired
        lcm.HandleSubscriptions(0)
        got_command = bool(received)
        if received:
            result.commands += len(received)
            command = received[-1]
            received.clear()
            if first is None:
                first = driver.time
        if command is not None and abs(wall_utime() - command.utime) > expire_sec * 1e6:
            command = None
        q, v = plant.GetPositions(plant_context), plant.GetVelocities(plant_context)
        wanted = np.asarray(command.joint_torque) if command is not None else -DAMPING * v
        # 3. libfranka's filter and rate limiter
        torque = lowpass(applied, wanted, period, low_pass_freq)
        if rate_limit:
            step = TORQUE_RATE_LIMIT * period
            torque = np.clip(torque, applied - step, applied + step)
        applied = torque
        if first is not None:
            result.periods += 1
            if command is None:
                result.expired += 1
                recent.append(0.0)
            else:
                age = (
                    len(published) - 1 - published.index(command.utime)
                    if command.utime in published[-50:]
                    else -1
                )
                result.ages[age] = result.ages.get(age, 0) + 1
                fresh = 0 <= age <= 1  # answers the status just published (in-process) or the one before
                result.fresh += fresh
                result.stale += not fresh
                recent.append(float(fresh))
            del recent[:-100]
            if got_command:
                result.commanded_periods, result.commanded_fresh = result.periods, result.fresh
        # 4. step the plant one period with this torque, then wait for the wall clock
        driver.apply_torque(torque, utime=published[-1] if published else 0)
        driver.advance()
        del q
        next_time += period
        remaining = next_time - clock()
        if remaining < 0:
            result.behind += 1
        while remaining > 0:
            if remaining > 1e-3:
                lcm.HandleSubscriptions(int(remaining * 1e3))  # blocks until a message or the time
            else:
                time.sleep(remaining)
            remaining = next_time - clock()
        if progress is not None and first is not None and result.periods % 1000 == 0:
            progress((driver.time - first) / duration)
    return result
