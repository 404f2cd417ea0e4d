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
    # Longest gap between two statuses once running, in control periods; beyond it the
    # controller stops commanding [-].
    status_timeout_periods: float = 3.0
    # Largest distance of any joint of the first status from the scenario's
    # arm.initial_positions; beyond it the run is refused before any command [rad].
    start_tolerance: float = 0.01
    # Largest change of any joint's position from one status to the next, per control
    # period between them: a jump no real arm makes (the Panda's fastest joint, 2.61 rad/s,
    # moves 2.6e-3 rad in 1 ms) [rad].
    max_joint_step: float = 0.01
    # The loop thread in real time on a robot PC (off by default) [-].
    realtime: RealtimeConfig = field(default_factory=RealtimeConfig)


def driver_problems(driver: DriverConfig):
    """Yields (field, problem) for every invalid driver setting."""
    for name in ("status_channel", "command_channel", "force_torque_channel"):
        value = getattr(driver, name)
        if not isinstance(value, str) or not value.strip() or value != value.strip():
            yield name, f"must be a channel name without surrounding spaces, got {value!r}"
    if driver.status_channel == driver.command_channel:
        yield "command_channel", f"must differ from status_channel, both are {driver.command_channel!r}"
    if driver.force_source not in FORCE_SOURCES:
        yield "force_source", f"must be one of {', '.join(FORCE_SOURCES)}, got {driver.force_source!r}"
    for name in ("first_status_timeout", "status_timeout_periods", "start_tolerance", "max_joint_step"):
        value = getattr(driver, name)
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not number or not math.isfinite(value) or value <= 0:
            yield name, f"must be a finite number > 0, got {value!r}"
    if isinstance(driver.first_status_timeout, (int, float)) and driver.first_status_timeout > 600:
        yield (
            "first_status_timeout",
            f"must be at most 600 s (a drive that waits longer hangs), got {driver.first_status_timeout!r}",
        )
    if isinstance(driver.status_timeout_periods, (int, float)) and 0 < driver.status_timeout_periods < 1:
        yield (
            "status_timeout_periods",
            (f"must be >= 1 (a status comes once per period), got {driver.status_timeout_periods!r}"),
        )
    problem = realtime_settings_problem(driver.realtime.priority, driver.realtime.core)
    if problem:
        yield f"realtime.{problem[0]}", problem[1]
