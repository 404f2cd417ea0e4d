"""The compiled LCM decode and encode (nsdrake/driver/tick.py) against the ``lcm``
package's generated Python for Drake's types, the reference: on random messages and on
hostile bytes, the same verdict (a 7-joint ``lcmt_panda_status`` or not) and, where one,
the same values bit for bit; a command's bytes equal to ``lcmt_panda_command.encode()``.

The reference verdict: ``lcmt_panda_status.decode`` takes the bytes, the message has 7
joints, and encoding it again gives the same bytes (the ``lcm`` package ignores bytes after
a message; the drive refuses them, as nsdrake/driver/wire.py's ``StatusBuffer.problem``).
"""

from __future__ import annotations

import struct

import numpy as np
import pytest
from drake import lcmt_panda_command, lcmt_panda_status

from nsdrake.driver.tick import SCRATCH, decode_status, encode_command
from nsdrake.driver.wire import STATUS_ARRAYS, STATUS_SIZE, CommandBuffer, stamp_status

FINGERPRINT = np.frombuffer(lcmt_panda_status._get_packed_fingerprint(), np.uint8).copy()


def random_status(rng, joints: int = 7) -> lcmt_panda_status:
    """A status with every field random: doubles of any exponent and sign (NaN and ±∞ among
    them, from random bits), clocks over the whole int64 range, modes over int8's."""
    m = lcmt_panda_status()
    m.num_joints = joints
    for name in STATUS_ARRAYS:
        setattr(m, name, list(rng.integers(0, 2**64, joints, dtype=np.uint64).view(np.float64)))
    m.utime, m.robot_utime = (int(x) for x in rng.integers(-(2**63), 2**63 - 1, 2, dtype=np.int64))
    m.robot_mode, m.control_mode = (int(x) for x in rng.integers(-128, 128, 2))
    m.control_command_success_rate = float(rng.integers(0, 2**64, dtype=np.uint64).view(np.float64))
    return m


def reference(data: bytes):
    """The ``lcm`` package's verdict: the decoded message, or None."""
    try:
        message = lcmt_panda_status.decode(data)
    except (ValueError, struct.error):
        return None
    if message.num_joints != 7 or message.encode() != data:
        return None
    return message


def compiled(data: bytes):
    """decode_status's verdict: (fields (57), ints (4)) or None."""
    fields, ints, bits = np.zeros(57), np.zeros(4, np.int64), np.zeros(SCRATCH)
    buffer = np.zeros(max(len(data), STATUS_SIZE), np.uint8)  # the loop's rows are this wide
    buffer[: len(data)] = np.frombuffer(data, np.uint8)
    if decode_status(buffer, len(data), FINGERPRINT, bits, fields, ints):
        return None
    return fields, ints


def same_values(message: lcmt_panda_status, fields: np.ndarray, ints: np.ndarray) -> bool:
    """Every field equal bit for bit (NaN payloads included)."""
    expected = np.concatenate([getattr(message, name) for name in STATUS_ARRAYS])
    expected = np.append(expected, message.control_command_success_rate)
    return np.array_equal(fields.view(np.uint64), expected.view(np.uint64)) and list(ints) == [
        message.utime,
        message.robot_utime,
        message.robot_mode,
        message.control_mode,
    ]


def hostile(rng, data: bytes):
    """Bytes a broken or malicious publisher sends, from one valid status: every truncation
    near the layout's edges, a byte more, each fingerprint byte flipped, other joint counts
    (negative and huge too), random bytes of the right length, and random single-byte edits."""
    yield b""
    for size in (*range(0, 24), *range(STATUS_SIZE - 10, STATUS_SIZE)):
        yield data[:size]
    yield data + b"\0"
    yield data + data
    for k in range(8):
        yield data[:k] + bytes([data[k] ^ 1]) + data[k + 1 :]
    for joints in (0, 1, 6, 8, -7, -1, 2**31 - 1, -(2**31), 7 + 2**16):
        yield data[:16] + struct.pack(">i", joints) + data[20:]
    for _ in range(20):
        yield rng.bytes(STATUS_SIZE)
        yield data[:8] + rng.bytes(STATUS_SIZE - 8)
        k = int(rng.integers(0, STATUS_SIZE))
        yield data[:k] + bytes([int(rng.integers(0, 256))]) + data[k + 1 :]
    for joints in (6, 8):  # well-formed statuses of another arm
        yield random_status(rng, joints).encode()


@pytest.mark.parametrize("seed", range(4))
def test_random_statuses_decode_as_the_lcm_package_decodes_them(seed):
    """200 random statuses: both take each, with the same values bit for bit (catches a
    field read at the wrong offset, e.g. robot_utime at 476 instead of 477, a little-endian
    read, a sign lost on utime or robot_mode)."""
    rng = np.random.default_rng(seed)
    for _ in range(200):
        data = random_status(rng).encode()
        message, ours = reference(data), compiled(data)
        assert message is not None and ours is not None
        assert same_values(message, *ours)


@pytest.mark.parametrize("seed", range(4))
def test_hostile_bytes_get_the_lcm_package_s_verdict(seed):
    """Truncated, extended, mistyped, other joint counts and random bytes: the compiled
    decode takes exactly what the ``lcm`` package decodes as a 7-joint status of exactly
    its bytes, with the same values (catches a length or fingerprint check dropped: stale
    or out-of-range bytes read as a status)."""
    rng = np.random.default_rng(100 + seed)
    verdicts = []
    for data in hostile(rng, random_status(rng).encode()):
        message, ours = reference(data), compiled(data)
        assert (message is None) == (ours is None), (len(data), data[:24].hex())
        if message is not None:
            assert same_values(message, *ours)
        verdicts.append(message is not None)
    assert any(verdicts) and not all(verdicts)  # both verdicts met: the stream tests both


@pytest.mark.parametrize("seed", range(2))
def test_a_command_s_bytes_are_the_lcm_package_s(seed):
    """utime over the int64 range, torques of random bits: encode_command into the drive's
    CommandBuffer gives lcmt_panda_command.encode()'s bytes exactly (catches a byte order
    or an offset wrong, the utime's sign lost)."""
    rng = np.random.default_rng(200 + seed)
    buffer, bits = CommandBuffer(), np.zeros(SCRATCH)
    for _ in range(200):
        command = lcmt_panda_command()
        command.utime = int(rng.integers(-(2**63), 2**63 - 1, dtype=np.int64))
        command.num_joint_torque = 7
        command.joint_torque = list(rng.integers(0, 2**64, 7, dtype=np.uint64).view(np.float64))
        command.control_mode_expected = lcmt_panda_status.CONTROL_MODE_TORQUE
        encode_command(
            np.frombuffer(buffer.buffer, np.uint8), command.utime, np.array(command.joint_torque), bits
        )
        assert bytes(buffer.buffer) == command.encode()


@pytest.mark.parametrize("seed", range(2))
def test_a_stamped_status_is_the_lcm_package_s_decode_set_encode(seed):
    """The simulated driver's stamp (wire.stamp_status: utime, robot_utime, robot_mode and
    control_command_success_rate written into the bytes in place): the bytes
    lcmt_panda_status.decode, setting the four fields and encode() give, for random statuses
    and values over their types' ranges, 6-joint statuses too (catches an offset one off,
    the mode's byte taken for the clock's, a little-endian write)."""
    rng = np.random.default_rng(300 + seed)
    for joints in [7] * 100 + [6] * 5:
        data = random_status(rng, joints).encode()
        utime, robot_utime = (int(x) for x in rng.integers(-(2**63), 2**63 - 1, 2, dtype=np.int64))
        mode = int(rng.integers(-128, 128))
        rate = float(rng.integers(0, 2**64, dtype=np.uint64).view(np.float64))
        expected = lcmt_panda_status.decode(data)
        expected.utime, expected.robot_utime, expected.robot_mode = utime, robot_utime, mode
        expected.control_command_success_rate = rate
        assert stamp_status(data, utime, robot_utime, mode, rate) == expected.encode()
