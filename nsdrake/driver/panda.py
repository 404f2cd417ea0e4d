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
