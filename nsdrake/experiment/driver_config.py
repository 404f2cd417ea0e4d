"""A scenario's ``driver`` section: how ``nsdrake drive`` meets a Franka Panda's LCM driver.

(No ``from __future__ import annotations`` here: Drake's ``yaml_load_typed`` reads
the dataclass field types at run time.)

The controller side (:mod:`nsdrake.driver`) reads ``lcmt_panda_status`` messages,
runs the scenario's reference and controller, and answers each status with one
``lcmt_panda_command`` in torque mode. These settings say which channels, where the
measured force comes from, who adds gravity, and when the controller stops
commanding. They live with the scenario (``driver.force_source: external_torque``
in a ``--config`` file) because they belong to the experiment; only ``nsdrake drive``
and ``nsdrake sim-driver`` read them.
"""

import math
import os
from dataclasses import dataclass, field

FORCE_SOURCES = ("sensor", "external_torque")


@dataclass
class RealtimeConfig:
    """The controller's loop thread in real time on a robot PC (nsdrake/driver/realtime.py;
    ``nsdrake drive --realtime`` sets it too). Off by default: an ordinary PC runs the loop
    as an ordinary thread. Each setting the OS does not allow (a user without the right to a
    real-time priority or to lock memory, a core the process may not run on) is refused in
    one line before anything is sent."""

    # Run the loop thread at SCHED_FIFO `priority`, on `core`, with the process's memory
    # locked and Python's garbage collector off [-].
    enabled: bool = False
    # The loop thread's SCHED_FIFO priority, 1 to 99 (the scheduler's range; the kernel's
    # own watchdogs run at 99) [-].
    priority: int = 80
    # The core the loop thread is pinned to; -1: not pinned [-].
    core: int = -1
    # Lock the process's memory (mlockall): no page of it swapped out or faulted in while a
    # command is due [-].
    lock_memory: bool = True


def realtime_settings_problem(priority, core) -> tuple[str, str] | None:
    """(field, problem) when ``priority`` or ``core`` is no real-time setting at all,
    whatever the OS allows (None: they are): the priority an integer in SCHED_FIFO's range,
    the core an integer ≥ -1."""
    low, high = os.sched_get_priority_min(os.SCHED_FIFO), os.sched_get_priority_max(os.SCHED_FIFO)
    if not isinstance(priority, int) or isinstance(priority, bool) or not low <= priority <= high:
        return "priority", f"must be an integer from {low} to {high} (SCHED_FIFO's range), got {priority!r}"
    if not isinstance(core, int) or isinstance(core, bool) or core < -1:
        return "core", f"must be a core's number (0, 1, ...), or -1 for none, got {core!r}"
    return None


@dataclass
class DriverConfig:
    """The controller behind a Franka Panda's LCM driver (docs/real_arm.md: "On a real arm")."""

    # LCM channel of the driver's lcmt_panda_status messages (drake-franka-driver's default) [-].
    status_channel: str = "PANDA_STATUS"
    # LCM channel the controller's lcmt_panda_command messages go to (the driver's default) [-].
    command_channel: str = "PANDA_COMMAND"
    # Where the measured contact wrench comes from: sensor, lcmt_force_torque messages on
    # force_torque_channel (force and moment the tool exerts on the work piece, world axes,
    # moment about the plate's sensor origin, as the simulated station's table sensor
    # publishes them); external_torque, estimated from each status's joint_torque_external
    # as the wrench at the tool W = (J Jᵀ)⁻¹ J τ_ext (nsdrake/driver/wrench.py) [-].
    force_source: str = "sensor"
    # LCM channel of the force-torque sensor's lcmt_force_torque messages [-].
    force_torque_channel: str = "PANDA_FORCE_TORQUE"
    # The robot adds gravity to every torque command, as Franka's torque interface does (and
    # drake-franka-driver in --control_mode=torque without --remove_gravity_compensation):
    # the controller's law includes g(q), and the command it sends is τ − g(q). false: the
    # command is τ itself, g included, for a driver that subtracts its own g(q) before the
    # robot adds it back (--remove_gravity_compensation) [-].
    robot_adds_gravity: bool = True
    # Longest wait for the first status before the controller gives up, sending nothing [s].
    first_status_timeout: float = 5.0
    # The driver's command expiry, the same number as its --expire_sec (drake-franka-driver's
    # torque recipe: 0.05; nsdrake sim-driver reads this field unless given --expire-sec):
    # a command older than this is dropped and the robot damps by itself. It is also the
    # controller's silence bound, in periods expire_sec / control_period (50 at 1 kHz): a
    # status (or force-torque message) later than that, or a status clock that jumps
    # further, stops the controller; a late status within it is a glitch, counted in
    # timing.json. Why one number for both sides: a bound shorter than the driver's expiry
    # protects nothing more (the robot applies the last command until its driver expires
    # it, whatever the controller does) and stops every PC without a real-time kernel; a
    # longer one would let the controller resume on a robot that has been damping, a torque
    # step its rate limiter never saw. At most 0.1 s: in 0.1 s a joint accelerated by the
    # held torque at Franka's published acceleration limit (up to 20 rad/s²) reaches
    # 2 rad/s, near the velocity limits (2.175-2.61 rad/s); held longer, the last torque can
    # run a joint past them before the driver damps [s].
    expire_sec: float = 0.05
    # Largest distance of any joint of the first status from the scenario's
    # arm.initial_positions; beyond it the run is refused before any command. At most what
    # the Panda's slowest joints move in two control periods at their velocity limit
    # (2 × 2.175 rad/s × 1 ms = 4.35e-3 rad at 1 kHz): the first command then pulls the arm
    # no farther than the law's own reference moves between two ticks of a fast motion; a
    # pose farther off gets its full impedance torque at once [rad].
    start_tolerance: float = 0.004
    # Largest change of every joint's position from one status to the next, per control
    # period between them; 0 (the default): each joint's own, from Franka's published
    # velocity limit (nsdrake/driver/panda.py: the limit + 5%, times the period, + twice
    # the sensing noise 1e-4 rad: 2.48e-3 rad a period for joints 1–4, 2.94e-3 for 5–7 at
    # 1 kHz). A positive value is one bound for every joint, at most the smallest of
    # those [rad].
    max_joint_step: float = 0.0
    # The loop thread in real time on a robot PC (off by default) [-].
    realtime: RealtimeConfig = field(default_factory=RealtimeConfig)


# Fields that were removed, and the one line that says what replaced them.
REMOVED_FIELDS = {
    "status_timeout_periods": (
        "removed: the silence bound is now driver.expire_sec [s], the driver's own command expiry "
        "(default 0.05 s, 50 periods at 1 kHz; set it to your driver's --expire_sec)"
    ),
}
MAX_EXPIRE_SEC = 0.1  # [s] (the field's comment)


def silence_bound_periods(driver: DriverConfig, control_period: float) -> float:
    """The controller's silence bound in control periods: the driver's command expiry
    (``driver.expire_sec``) over the period."""
    return driver.expire_sec / control_period


def _number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def driver_problems(driver: DriverConfig, control_period: float | None = None):
    """Yields (field, problem) for every invalid driver setting; with ``control_period``
    [s], also a silence bound of at least two periods. (The bounds that come from the
    Panda's limits, on start_tolerance and max_joint_step, are checked where the drive
    is built: nsdrake.driver.panda.panda_driver_problems.)"""
    yield from _channel_problems(driver)
    if driver.force_source not in FORCE_SOURCES:
        yield "force_source", f"must be one of {', '.join(FORCE_SOURCES)}, got {driver.force_source!r}"
    for name in ("first_status_timeout", "expire_sec", "start_tolerance"):
        value = getattr(driver, name)
        if not _number(value) or value <= 0:
            yield name, f"must be a finite number > 0, got {value!r}"
    if not _number(driver.max_joint_step) or driver.max_joint_step < 0:
        yield (
            "max_joint_step",
            f"must be a finite number >= 0 (0: from the velocity limits), got {driver.max_joint_step!r}",
        )
    if _number(driver.first_status_timeout) and driver.first_status_timeout > 600:
        yield (
            "first_status_timeout",
            f"must be at most 600 s (a drive that waits longer hangs), got {driver.first_status_timeout!r}",
        )
    if _number(driver.expire_sec) and driver.expire_sec > MAX_EXPIRE_SEC:
        yield (
            "expire_sec",
            f"must be at most {MAX_EXPIRE_SEC:g} s (a stale torque held longer can run a joint past its "
            f"velocity limit before the driver damps), got {driver.expire_sec!r}",
        )
    if _number(control_period) and control_period > 0 and _number(driver.expire_sec):
        if driver.expire_sec < 2 * control_period:
            yield (
                "expire_sec",
                f"must be at least two control periods ({2 * control_period:g} s; a status comes once a "
                f"period), got {driver.expire_sec!r}",
            )
    problem = realtime_settings_problem(driver.realtime.priority, driver.realtime.core)
    if problem:
        yield f"realtime.{problem[0]}", problem[1]


def _channel_problems(driver: DriverConfig):
    names = ("status_channel", "command_channel", "force_torque_channel")
    for name in names:
        value = getattr(driver, name)
        if not isinstance(value, str) or not value.strip() or value != value.strip():
            yield name, f"must be a channel name without surrounding spaces, got {value!r}"
    for i, name in enumerate(names):  # three channels, three names: a shared one mixes two message types
        for earlier in names[:i]:
            if getattr(driver, name) == getattr(driver, earlier):
                yield name, f"must differ from {earlier}, both are {getattr(driver, name)!r}"
