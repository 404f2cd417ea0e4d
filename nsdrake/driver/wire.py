"""Drake's Panda LCM messages read and written in place: each message's bytes copied into
one preallocated buffer, its fields read and written through numpy views of that buffer,
so that a tick allocates no message object (``lcmt_panda_status.decode`` builds eight
Python lists of floats, ≈ 7 µs).

The layouts are LCM's encoding of Drake's types (``drake/lcmtypes/lcmt_panda_*.lcm``):
an 8-byte type fingerprint, then the fields in order, big-endian. For 7 joints:

- ``lcmt_panda_status`` (486 bytes): utime int64 @8, num_joints int32 @16, eight double[7]
  arrays @20 (joint_position, _desired, joint_velocity, _desired,
  joint_acceleration_desired, joint_torque, joint_torque_desired,
  joint_torque_external), control_command_success_rate double @468, robot_mode int8
  @476, robot_utime int64 @477, control_mode int8 @485;
- ``lcmt_panda_command`` (85 bytes in torque mode): utime int64 @8, num_joint_position
  int32 = 0 @16, num_joint_velocity int32 = 0 @20, num_joint_torque int32 = 7 @24,
  joint_torque double[7] @28, control_mode_expected int8 @84;
- ``lcmt_force_torque`` (64 bytes): timestamp int64 @8 [ms], fx fy fz tx ty tz @16.

The driver tests decode the commands this module encodes with Drake's own ``decode``
(tests/driver/bad_driver.py, tests/driver/fake_bus.py); no test compares every field yet.
"""

from __future__ import annotations

import struct

import numpy as np
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status

from nsdrake.driver.panda import NUM_JOINTS

_N = NUM_JOINTS
STATUS_SIZE = 8 + 12 + 8 * 8 * _N + 18
COMMAND_SIZE = 8 + 8 + 12 + 8 * _N + 1
FORCE_TORQUE_SIZE = 8 + 8 + 48
STATUS_ARRAYS = (
    "joint_position", "joint_position_desired", "joint_velocity", "joint_velocity_desired",
    "joint_acceleration_desired", "joint_torque", "joint_torque_desired", "joint_torque_external",
)  # fmt: skip
_TAIL = 20 + 8 * 8 * _N  # control_command_success_rate's offset


def _fingerprint(message_type) -> bytes:
    return message_type._get_packed_fingerprint()


class StatusBuffer:
    """The latest ``lcmt_panda_status`` of 7 joints, decoded in place: :meth:`load` copies
    the bytes in (or says why they are not such a status); the fields are views."""

    def __init__(self):
        self.buffer = bytearray(STATUS_SIZE)
        self._fingerprint = _fingerprint(lcmt_panda_status)
        arrays = np.ndarray((8, _N), ">f8", buffer=self.buffer, offset=20)
        self.q, self.v, self.tau_ext = arrays[0], arrays[2], arrays[7]
        self.tau_desired = arrays[6]  # joint_torque_desired: what the robot's torque interface applies

    def problem(self, data: bytes) -> str | None:
        """Why ``data`` is not an lcmt_panda_status of 7 joints (None: it is one)."""
        if len(data) < 20 or data[:8] != self._fingerprint:
            return f"{len(data)} bytes that are not an lcmt_panda_status (its LCM type fingerprint differs)"
        (joints,) = struct.unpack_from(">i", data, 16)
        if joints != _N:
            return f"it has {joints} joints, the arm has {_N}"
        if len(data) != STATUS_SIZE:
            return f"{len(data)} bytes, an lcmt_panda_status of {_N} joints has {STATUS_SIZE}"
        return None

    def load(self, data: bytes) -> None:
        """Copies ``data`` (checked by :meth:`problem`) in."""
        self.buffer[:] = data

    @staticmethod
    def utime(data: bytes) -> int:
        return struct.unpack_from(">q", data, 8)[0]

    @staticmethod
    def robot_utime(data: bytes) -> int:
        return struct.unpack_from(">q", data, _TAIL + 9)[0]

    @property
    def success_rate(self) -> float:
        return struct.unpack_from(">d", self.buffer, _TAIL)[0]

    @property
    def robot_mode(self) -> int:
        return struct.unpack_from(">b", self.buffer, _TAIL + 8)[0]


def stamp_status(data: bytes, utime: int, robot_utime: int, robot_mode: int, success_rate: float) -> bytes:
    """``data``, an ``lcmt_panda_status`` of 7 joints, with its utime, robot_utime,
    robot_mode and control_command_success_rate replaced, written in place in a copy (what
    decoding it, setting the four fields and encoding it again gives, without the ``lcm``
    package's Python: tests/driver/test_compiled_wire.py); other bytes (another joint count,
    not a status) go through that decode and encode."""
    if len(data) != STATUS_SIZE or data[:8] != _STATUS_FINGERPRINT:
        status = lcmt_panda_status.decode(data)
        status.utime, status.robot_utime, status.robot_mode = utime, robot_utime, robot_mode
        status.control_command_success_rate = success_rate
        return status.encode()
    stamped = bytearray(data)
    struct.pack_into(">q", stamped, 8, utime)
    struct.pack_into(">dbq", stamped, _TAIL, success_rate, robot_mode, robot_utime)
    return bytes(stamped)


_STATUS_FINGERPRINT = _fingerprint(lcmt_panda_status)
_COMMAND_FINGERPRINT = _fingerprint(lcmt_panda_command)
_TORQUE_COUNTS = struct.pack(">iii", 0, 0, _N)  # a command's joint counts in torque mode
FORCE_TORQUE_FIELDS = ("fx", "fy", "fz", "tx", "ty", "tz")  # lcmt_force_torque's values, in order


class ForceTorqueBuffer:
    """The latest ``lcmt_force_torque``, decoded in place; :attr:`wrench` is [M; f] (6)
    [N m, N] (the message's tx ty tz, fx fy fz), a view."""

    def __init__(self):
        self.buffer = bytearray(FORCE_TORQUE_SIZE)
        self._fingerprint = _fingerprint(lcmt_force_torque)
        values = np.ndarray((6,), ">f8", buffer=self.buffer, offset=16)
        self.wrench = values[[3, 4, 5, 0, 1, 2]].astype(np.float64)  # native order; refreshed by load()
        self._values = values

    def problem(self, data: bytes) -> str | None:
        """Why ``data`` is not an lcmt_force_torque with finite values (None: it is one)."""
        if len(data) != FORCE_TORQUE_SIZE or data[:8] != self._fingerprint:
            return f"{len(data)} bytes that are not an lcmt_force_torque"
        values = np.frombuffer(data, ">f8", 6, offset=16)
        if not np.isfinite(values).all():
            k = int(np.flatnonzero(~np.isfinite(values))[0])
            return f"{FORCE_TORQUE_FIELDS[k]} is {float(values[k])!r}"
        return None

    def load(self, data: bytes) -> None:
        self.buffer[:] = data
        self.wrench[:3], self.wrench[3:] = self._values[3:], self._values[:3]


class StatusWriter:
    """An ``lcmt_panda_status`` of 7 joints encoded in place (the simulated driver's, as
    Drake's ``PandaStatusSender`` fills it: the desired position, velocity and acceleration,
    the success rate, the modes and robot_utime zero); :meth:`set` writes the rest."""

    def __init__(self):
        self.buffer = bytearray(STATUS_SIZE)
        self.buffer[:8] = _STATUS_FINGERPRINT
        struct.pack_into(">i", self.buffer, 16, _N)
        self._arrays = np.ndarray((8, _N), ">f8", buffer=self.buffer, offset=20)

    def set(self, utime: int, q, v, torque, torque_desired, torque_external) -> bytes:
        """The status's bytes: ``utime`` [µs], joint_position, joint_velocity, joint_torque,
        joint_torque_desired, joint_torque_external (7 each)."""
        struct.pack_into(">q", self.buffer, 8, utime)
        arrays = self._arrays
        arrays[0], arrays[2], arrays[5], arrays[6], arrays[7] = q, v, torque, torque_desired, torque_external
        return bytes(self.buffer)


class ForceTorqueWriter:
    """An ``lcmt_force_torque`` encoded in place (:func:`nsdrake.driver.wrench.force_torque_message`'s)."""

    def __init__(self):
        self.buffer = bytearray(FORCE_TORQUE_SIZE)
        self.buffer[:8] = _fingerprint(lcmt_force_torque)
        self._values = np.ndarray((6,), ">f8", buffer=self.buffer, offset=16)

    def set(self, time: float, wrench: np.ndarray) -> bytes:
        """The message's bytes: W = [M; f] (6) [N m, N] at ``time`` [s] (its timestamp in ms)."""
        struct.pack_into(">q", self.buffer, 8, round(time * 1e3))
        self._values[:3], self._values[3:] = wrench[3:], wrench[:3]
        return bytes(self.buffer)


def command_torque(data: bytes) -> np.ndarray | None:
    """The 7 torques of ``data`` when it is an ``lcmt_panda_command`` in torque mode of 7
    joints (:class:`CommandBuffer`'s layout), else None."""
    if len(data) != COMMAND_SIZE or data[:8] != _COMMAND_FINGERPRINT or data[16:28] != _TORQUE_COUNTS:
        return None
    if data[-1] != lcmt_panda_status.CONTROL_MODE_TORQUE:
        return None
    return np.frombuffer(data, ">f8", _N, offset=28).astype(np.float64)


class CommandBuffer:
    """One ``lcmt_panda_command`` in torque mode, encoded in place: :meth:`set` writes the
    utime and the torques into the preallocated bytes (:attr:`buffer`)."""

    def __init__(self):
        self.buffer = bytearray(COMMAND_SIZE)
        self.buffer[:8] = _fingerprint(lcmt_panda_command)
        struct.pack_into(">iii", self.buffer, 16, 0, 0, _N)
        struct.pack_into(">b", self.buffer, COMMAND_SIZE - 1, lcmt_panda_status.CONTROL_MODE_TORQUE)
        self.torque = np.ndarray((_N,), ">f8", buffer=self.buffer, offset=28)

    def set(self, utime: int, torque: np.ndarray) -> bytearray:
        struct.pack_into(">q", self.buffer, 8, utime)
        self.torque[:] = torque
        return self.buffer
