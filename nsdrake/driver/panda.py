"""What the controller must know about a Franka Panda behind its LCM driver.

The published limits (Franka Emika's FCI documentation, "Robot and interface
specifications": joint torque limits 87 N m for joints 1–4 and 12 N m for joints
5–7, torque-rate limit 1000 N m/s for every joint) are applied by the controller's
own actuator limits (:mod:`nsdrake.control.actuator_limits`) before anything is sent:
the robot stops with a reflex when a command breaks them. They bound the torque the
joint produces, τ of the law with g included (the robot adds g to the command).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from nsdrake.control.config import ActuatorLimitsConfig

NUM_JOINTS = 7  # pydrake.manipulation.kPandaArmNumJoints
TORQUE_LIMITS = np.array([87.0, 87.0, 87.0, 87.0, 12.0, 12.0, 12.0])  # [N m], joints 1–7
TORQUE_RATE_LIMIT = 1000.0  # [N m/s], every joint


class PandaLimitError(ValueError):
    """Limits or a model that do not fit the Panda; the message is one line."""


def panda_actuator_limits(limits: ActuatorLimitsConfig, joint_names: tuple[str, ...]) -> ActuatorLimitsConfig:
    """The scenario's actuator limits with the Panda's published ones wherever the scenario
    gives none, joint k of the model being the Panda's joint k + 1. A scenario limit above
    the published one is refused (never clamped silently): PandaLimitError naming it."""
    if len(joint_names) != NUM_JOINTS:
        raise PandaLimitError(
            f"the Panda driver speaks {NUM_JOINTS} joints; the scenario's arm has {len(joint_names)}"
        )
    torque, rate = dict(limits.torque), dict(limits.torque_rate)
    for k, name in enumerate(joint_names):
        for kind, table, published, unit in (
            ("torque", torque, TORQUE_LIMITS[k], "N m"),
            ("torque_rate", rate, TORQUE_RATE_LIMIT, "N m/s"),
        ):
            if name not in table:
                table[name] = float(published)
            elif table[name] > published:
                raise PandaLimitError(
                    f"actuator_limits.{kind}.{name}: {table[name]:g} {unit} is above the Panda's "
                    f"published limit {published:g} {unit} for joint {k + 1}"
                )
    return dataclasses.replace(limits, torque=torque, torque_rate=rate)


# Franka's published joint limits (FCI documentation, "Limits for Panda"), joints 1–7.
POSITION_LOWER = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])  # [rad]
POSITION_UPPER = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])  # [rad]
VELOCITY_LIMIT = np.array([2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100])  # [rad/s]
# How far a status may report a joint beyond them before the controller stops: the robot
# itself stops with a reflex at the limits, so a reading beyond them by more than its
# sensing noise (≈ 1e-4 rad, 1e-2 rad/s) is a robot out of its envelope or a broken
# stream: 0.01 rad of position, 5% of the velocity limit.
POSITION_MARGIN = 0.01  # [rad]
VELOCITY_MARGIN = 0.05  # [-] of VELOCITY_LIMIT


_LOWER, _UPPER = POSITION_LOWER - POSITION_MARGIN, POSITION_UPPER + POSITION_MARGIN
# The same limits as a box around a centre, rows q and q̇: |[q; q̇] − centre| ≤ half-width
ENVELOPE_CENTRE = np.array([(_LOWER + _UPPER) / 2, np.zeros(7)])
ENVELOPE_HALF_WIDTH = np.array([(_UPPER - _LOWER) / 2, VELOCITY_LIMIT * (1.0 + VELOCITY_MARGIN)])
_FAST = VELOCITY_LIMIT * (1.0 + VELOCITY_MARGIN)


def limit_problem(q: np.ndarray, v: np.ndarray, joint_names) -> str | None:
    """A joint position or velocity beyond the Panda's published limits by more than the
    margins above (the worst joint named), else None."""
    if (
        (q >= _LOWER).all() and (q <= _UPPER).all() and (v <= _FAST).all() and (v >= -_FAST).all()
    ):  # the usual case, in four array comparisons (this runs inside every tick)
        return None
    below = POSITION_LOWER - POSITION_MARGIN - q
    above = q - POSITION_UPPER - POSITION_MARGIN
    fast = np.abs(v) - VELOCITY_LIMIT * (1.0 + VELOCITY_MARGIN)
    for excess, kind in ((below, "below"), (above, "above")):
        k = int(np.argmax(excess))
        if excess[k] > 0.0:
            limit = POSITION_LOWER[k] if kind == "below" else POSITION_UPPER[k]
            return (
                f"{joint_names[k]} is at {q[k]:.4f} rad, {kind} the Panda's limit {limit:g} rad "
                f"by more than {POSITION_MARGIN:g} rad"
            )
    k = int(np.argmax(fast))
    return (
        f"{joint_names[k]} moves at {v[k]:.4g} rad/s, beyond the Panda's limit {VELOCITY_LIMIT[k]:g} rad/s "
        f"by more than {VELOCITY_MARGIN:.0%}"
    )


# A status's position against Franka's velocity limits and against its own reported velocity
# (nsdrake.driver.faults.jump_problem, velocity_mismatch_problem). Both allow the sensing noise
# of the two readings compared (POSITION_NOISE each); the second also the velocity's noise and
# what a joint accelerating at ACCELERATION_BOUND moves apart from the trapezoid of the two
# reported velocities (at most a Δt²/4). ACCELERATION_BOUND is five times Franka's largest
# published joint acceleration (20 rad/s², joints 6–7): a contact's impact accelerates joints
# faster than a planned motion may. At 1 kHz and one period the second rule allows 2.4e-4 rad:
# a position that creeps at 0.3 rad/s while its velocity reads zero is refused.
POSITION_NOISE = 1e-4  # [rad] per reading
VELOCITY_NOISE = 1e-2  # [rad/s] per reading
ACCELERATION_BOUND = 100.0  # [rad/s²]


def joint_step_allowance(elapsed: float) -> np.ndarray:
    """The most each joint may move in ``elapsed`` [s] [rad]: its velocity limit with
    VELOCITY_MARGIN, plus the noise of two readings."""
    return VELOCITY_LIMIT * (1.0 + VELOCITY_MARGIN) * elapsed + 2.0 * POSITION_NOISE


def slowest_joint_speed() -> float:
    """The smallest of Franka's published joint velocity limits [rad/s]."""
    return float(VELOCITY_LIMIT.min())


def velocity_mismatch_allowance(elapsed: float) -> float:
    """The most a joint's position change over ``elapsed`` [s] may differ from the
    trapezoid of its two reported velocities [rad] (the constants above)."""
    return 2.0 * POSITION_NOISE + VELOCITY_NOISE * elapsed + ACCELERATION_BOUND * elapsed**2 / 4.0


START_TOLERANCE_PERIODS = 2  # driver.start_tolerance's bound, in periods at the slowest joint's limit


def panda_driver_problems(driver, period: float):
    """Yields (field, problem) for the scenario's ``driver`` settings (a
    :class:`nsdrake.experiment.driver_config.DriverConfig`) beyond what the Panda allows at
    the control period [s]: ``start_tolerance`` above what its slowest joints move in
    START_TOLERANCE_PERIODS periods at their velocity limit (the field's comment argues
    the bound), ``max_joint_step`` above one period's allowance of the slowest joint."""
    tolerance = START_TOLERANCE_PERIODS * slowest_joint_speed() * period
    if driver.start_tolerance > tolerance:
        yield (
            "start_tolerance",
            f"must be at most {tolerance:.4g} rad (what the Panda's slowest joints move in "
            f"{START_TOLERANCE_PERIODS} control periods at their velocity limit), "
            f"got {driver.start_tolerance!r}",
        )
    step = float(joint_step_allowance(period).min())
    if driver.max_joint_step > step:
        yield (
            "max_joint_step",
            f"must be at most {step:.4g} rad (a period at the slowest joint's velocity limit, with the "
            f"margins of nsdrake/driver/panda.py), got {driver.max_joint_step!r}",
        )
