"""What the controller side refuses on the wire: each check a pure function that returns
the problem in words (None: fine), so that the loop can stop with one line."""

from __future__ import annotations

import numpy as np
from drake import lcmt_panda_status

STATUS_FIELDS = ("joint_position", "joint_velocity", "joint_torque_external")


def status_problem(status: lcmt_panda_status, num_joints: int) -> str | None:
    """A status the controller cannot use: the wrong joint count, or a position,
    velocity or external torque that is not finite."""
    if status.num_joints != num_joints:
        return f"it has {status.num_joints} joints, the arm has {num_joints}"
    fields = [getattr(status, field) for field in STATUS_FIELDS]
    if all(len(values) == num_joints for values in fields) and np.isfinite(fields).all():
        return None  # the usual case, in one array operation (this runs inside every tick)
    for field in STATUS_FIELDS:
        values = np.asarray(getattr(status, field), dtype=float)
        if values.shape != (num_joints,):
            return f"{field} has {values.size} values, the arm has {num_joints} joints"
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            return f"{field}[{bad[0]}] is {float(values[bad[0]])!r}"
    return None


def start_problem(q: np.ndarray, q0: np.ndarray, tolerance: float, joint_names) -> str | None:
    """The first status farther than ``tolerance`` from the scenario's start pose q0 on
    some joint (the worst one named)."""
    distance = np.abs(np.asarray(q) - np.asarray(q0))
    worst = int(np.argmax(distance))
    if distance[worst] <= tolerance:
        return None
    return (
        f"{joint_names[worst]} is at {q[worst]:.4f} rad, {distance[worst]:.4f} rad from the scenario's start "
        f"{q0[worst]:.4f} rad (driver.start_tolerance {tolerance:g} rad): move the arm to the start pose"
    )


def jump_problem(
    q: np.ndarray, q_previous: np.ndarray, max_step: float, periods: int, joint_names
) -> str | None:
    """A joint that moved more than ``max_step`` per period over the ``periods`` since
    the previous status: a jump no real arm makes (the worst joint named)."""
    step = np.abs(np.subtract(q, q_previous))
    if step.max() <= max_step * periods:
        return None
    worst = int(np.argmax(step))
    return (
        f"{joint_names[worst]} moved {step[worst]:.4g} rad in {periods} period(s) "
        f"(driver.max_joint_step {max_step:g} rad per period)"
    )


def clock_steps(utime: int, previous_utime: int, period: float) -> int | None:
    """Control periods between two statuses from their ``utime`` [µs], at least one; None
    when the clock did not advance."""
    if utime <= previous_utime:
        return None
    return max(1, round((utime - previous_utime) * 1e-6 / period))
