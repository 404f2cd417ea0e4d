"""A bus on a fake clock for the controller loop's timing rules: messages are scheduled
at given times; ``handle`` delivers what is due and advances the clock as a real wait
would. Deterministic, so that the rules can be tested at their boundaries."""

from __future__ import annotations

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status

from nsdrake.driver.bus import Bus

STEP = 1e-6  # [s] time a handle(0) takes: the fake clock always advances


class FakeBus(Bus):
    def __init__(self):
        self.now = 0.0
        self.pending: list[tuple[float, int, str, bytes]] = []
        self.handlers: dict[str, list] = {}
        self.sent: list[tuple[float, lcmt_panda_command]] = []
        self.tick_cost = 0.0  # [s] the fake clock advances this much at each publish (a tick's compute)
        self._order = 0

    def clock(self) -> float:
        return self.now

    def at(self, time: float, channel: str, data: bytes) -> None:
        self._order += 1
        self.pending.append((time, self._order, channel, data))
        self.pending.sort()

    def subscribe(self, channel: str, handler) -> None:
        self.handlers.setdefault(channel, []).append(handler)

    def handle(self, timeout_ms: int) -> int:
        due = [m for m in self.pending if m[0] <= self.now]
        if not due and self.pending and self.pending[0][0] <= self.now + timeout_ms * 1e-3:
            self.now = self.pending[0][0]
            due = [m for m in self.pending if m[0] <= self.now]
        elif not due:
            self.now += max(timeout_ms * 1e-3, STEP)
        for message in due:
            self.pending.remove(message)
            for handler in self.handlers.get(message[2], []):
                handler(message[3])
        return len(due)

    def publish(self, channel: str, data) -> None:
        self.now += self.tick_cost
        self.sent.append((self.now, lcmt_panda_command.decode(bytes(data))))


def status_bytes(
    q, *, utime: int, robot_utime: int = 0, v=None, num_joints: int = 7, tau_desired=None
) -> bytes:
    """A status at ``q`` (and ``v``); ``tau_desired``: its joint_torque_desired (zeros)."""
    status = lcmt_panda_status()
    status.utime, status.robot_utime, status.num_joints = utime, robot_utime, num_joints
    zeros = [0.0] * num_joints
    for field in (
        "joint_position_desired", "joint_velocity_desired", "joint_acceleration_desired",
        "joint_torque", "joint_torque_desired", "joint_torque_external",
    ):  # fmt: skip
        setattr(status, field, zeros)
    status.joint_position = list(np.asarray(q, dtype=float)[:num_joints])
    status.joint_velocity = zeros if v is None else list(v)
    if tau_desired is not None:
        status.joint_torque_desired = [float(x) for x in tau_desired]
    status.robot_mode, status.control_command_success_rate = 2, 1.0  # kMove, as a running Panda reports
    return status.encode()


def force_torque_bytes() -> bytes:
    return lcmt_force_torque().encode()
