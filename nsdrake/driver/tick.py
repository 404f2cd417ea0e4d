"""The drive's tick in compiled code: the bytes of the statuses in, the bytes of the command out.

:class:`nsdrake.driver.loop.ControllerLoop` answers each status with compiled calls around
the controller side's (the reference, then :class:`nsdrake.control.step.ControllerStep`,
whose stages are compiled already; the reference is still Python):

- :func:`take_statuses`: every status received since the last tick, in order, decoded from
  its LCM bytes (:func:`decode_status`) and held to the loop's rules (its clock, then the
  newest one's q, q̇, τ_ext and its motion since the status answered before:
  nsdrake/driver/loop.py's docstring), the loop's state updated only when all of them pass;
- :func:`decode_force_torque`: the sensor's newest ``lcmt_force_torque``, when one came;
- :func:`finish_tick`: what the robot's torque interface is asked for
  (:func:`robot_torques`), the last gate (:func:`nsdrake.driver.panda.command_problem`'s
  bounds) and the command's bytes (:func:`encode_command`).

Each returns 0 when everything passed, else a nonzero code and nothing changed: the loop
then runs the same tick through its Python path, which says what is wrong in words (and is
the reference the compiled path is tested against: tests/driver/test_compiled_tick.py). So
the rules keep one statement of their words, and their formulas one home: the clock's in
:mod:`nsdrake.driver.faults` (``register_jitable``: the same source in Python and compiled
here), the bounds' values from nsdrake/driver/panda.py, given as arrays
(:func:`motion_table`, :func:`limit_table`), never copied into this file.

The LCM layouts are those of nsdrake/driver/wire.py (Drake's ``lcmt_panda_status``,
``lcmt_panda_command``, big-endian); the ``lcm`` package's generated ``decode``/``encode``
are the reference (tests/driver/test_compiled_wire.py feeds both random and hostile bytes).
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numba.extending import register_jitable

from nsdrake.driver.faults import SLOW_STREAM, anchor_step, clock_verdict, elapsed_periods

# The compiled path leaves to the Python path (the loop's words) ...
CLOCK_RANGE = 1 << 60  # ... a clock beyond ±2⁶⁰ µs (36 000 years: the integer arithmetic of the
# clock rules stays far from int64's overflow; Python's integers have none)

# ints: the loop's integer state (ControllerLoop's attributes of these names are views)
I_ROBOT_CLOCK, I_LAST_CLOCK, I_ANCHOR, I_ACCEPTED, I_LONG_GAPS, I_PERIODS = 0, 1, 2, 3, 4, 5
I_COMMANDS, I_LONGEST_GAP, I_UTIME, I_PERIOD_US = 6, 7, 8, 9
I_GAPS = 10  # four glitch counts (nsdrake.driver.timing.GAP_BINS)
INTS = I_GAPS + 4
# floats: rows q, q̇, τ_ext of the status answered, q and q̇ of the one before, then scalars
F_MEASURED, F_LAST = 0, 21
F_SUCCESS_MIN, F_PERIOD, F_BOUND = 35, 36, 37
FLOATS = 38
SCRATCH = 136  # the tick's scratch: a status's 57 doubles, its 4 integers, 64 doubles' bits

STATUS_NOT, STATUS_JOINTS, STATUS_SIZE_WRONG = 1, 2, 3  # decode_status's verdicts (0: a status)


@register_jitable  # compiled inside each kernel that reads the bytes: no dispatcher of its own
def _u64(data, at):
    value = np.uint64(0)
    for k in range(8):
        value = (value << np.uint64(8)) | np.uint64(data[at + k])
    return value


@register_jitable  # compiled inside each kernel that reads the bytes: no dispatcher of its own
def _i64(data, at):
    return np.int64(_u64(data, at))  # two's complement: the bits as they are


@register_jitable  # compiled inside each kernel that reads the bytes: no dispatcher of its own
def _doubles(data, at, count, bits, out):
    """``count`` big-endian doubles from ``data[at:]`` into ``out`` (``bits``: a float64
    scratch array of at least ``count``, read through its uint64 view)."""
    words = bits.view(np.uint64)
    for k in range(count):
        words[k] = _u64(data, at + 8 * k)
    for k in range(count):
        out[k] = bits[k]


@njit(cache=True)
def decode_status(data, length, fingerprint, bits, fields, ints) -> int:
    """``data[:length]`` as an ``lcmt_panda_status`` of 7 joints (nsdrake/driver/wire.py's
    layout): 0 and its fields, or why not (:data:`STATUS_NOT`: too short or another type's
    fingerprint; :data:`STATUS_JOINTS`: not 7 joints; :data:`STATUS_SIZE_WRONG`: not
    exactly the 486 bytes of one), the order of
    :meth:`nsdrake.driver.wire.StatusBuffer.problem`. ``fields`` (57): the eight double[7]
    arrays, then control_command_success_rate; ``ints`` (4): utime, robot_utime,
    robot_mode, control_mode."""
    if length < 20:
        return STATUS_NOT
    for k in range(8):
        if data[k] != fingerprint[k]:
            return STATUS_NOT
    joints = np.int64(0)
    for k in range(16, 20):
        joints = (joints << 8) | np.int64(data[k])
    if joints != 7:  # int32 7: every other value, negative ones included, is not 7
        return STATUS_JOINTS
    if length != 486:
        return STATUS_SIZE_WRONG
    _doubles(data, 20, 57, bits, fields)
    ints[0] = _i64(data, 8)
    ints[1] = _i64(data, 477)
    ints[2] = np.int8(data[476])
    ints[3] = np.int8(data[485])
    return 0


@njit(cache=True)
def decode_force_torque(data, fingerprint, bits, wrench) -> int:
    """``data`` as an ``lcmt_force_torque`` with finite values (nsdrake/driver/wire.py's
    layout, :meth:`nsdrake.driver.wire.ForceTorqueBuffer.problem`'s verdict): 0 and
    ``wrench`` [M; f] (6) its tx ty tz, fx fy fz; else 1 and ``wrench`` as it was."""
    if data.shape[0] != 64:
        return 1
    for k in range(8):
        if data[k] != fingerprint[k]:
            return 1
    _doubles(data, 16, 6, bits, bits[8:14])
    for k in range(6):
        if not np.isfinite(bits[8 + k]):
            return 1
    for k in range(3):
        wrench[k], wrench[3 + k] = bits[11 + k], bits[8 + k]
    return 0


@njit(cache=True)
def encode_command(buffer, utime, torque, bits) -> None:
    """``utime`` and the 7 ``torque`` [N m] into an ``lcmt_panda_command``'s bytes
    (nsdrake/driver/wire.py's :class:`CommandBuffer` wrote the rest once)."""
    word = np.uint64(utime)
    for k in range(8):
        buffer[15 - k] = np.uint8(word & np.uint64(255))
        word >>= np.uint64(8)
    words = bits.view(np.uint64)
    for j in range(7):
        bits[j] = torque[j]
        word = words[j]
        for k in range(8):
            buffer[28 + 8 * j + 7 - k] = np.uint8(word & np.uint64(255))
            word >>= np.uint64(8)


@njit(cache=True)
def _reading_problem(q, v, tau_ext, header, limits) -> int:
    """The newest status's q, q̇, τ_ext finite (5), within the Panda's limits
    (panda.limit_problem's comparisons: 6), its robot in kMove when it reports its own
    state (7); 0: fine."""
    for j in range(7):
        if not (np.isfinite(q[j]) and np.isfinite(v[j]) and np.isfinite(tau_ext[j])):
            return 5
        if not (q[j] >= limits[0, j] and q[j] <= limits[1, j]):
            return 6
        if not (v[j] <= limits[2, j] and v[j] >= -limits[2, j]):
            return 6
    if header[1] != 0 and header[2] != 2:  # robot_utime, robot_mode: loop.ROBOT_MODE_MOVE
        return 7
    return 0


@njit(cache=True)
def _motion_problem(q, v, q_last, v_last, allowances, elapsed) -> int:
    """A joint that moved more than ``allowances[0]`` since the status answered before
    (10), or whose move disagrees with its reported velocities by more than
    ``allowances[1]`` over ``elapsed`` [s] (11): faults.jump_problem's and
    velocity_mismatch_problem's verdicts; 0: fine."""
    for j in range(7):
        if np.abs(q[j] - q_last[j]) - allowances[0, j] > 0.0:
            return 10
    for j in range(7):
        moved = q[j] - q_last[j]
        expected = 0.5 * elapsed * (v[j] + v_last[j])
        if np.abs(moved - expected) - allowances[1, j] > 0.0:
            return 11
    return 0


@njit(cache=True)
def take_statuses(raw, lengths, count, fingerprint, ints, floats, limits, motion, scratch) -> int:
    """Every status of ``raw[:count]`` (``lengths``: their sizes) by the loop's rules
    (module docstring); 0 and the state (``ints``, ``floats``) updated, else nonzero and
    the state as it was. ``limits`` (:func:`limit_table`), ``motion`` (:func:`motion_table`),
    ``scratch``: float64 (:data:`SCRATCH`)."""
    period_us = ints[I_PERIOD_US]
    robot_clock = ints[I_ROBOT_CLOCK] != 0
    last, anchor = ints[I_LAST_CLOCK], ints[I_ANCHOR]
    accepted, long_gaps = ints[I_ACCEPTED], ints[I_LONG_GAPS]
    bound = floats[F_BOUND]
    fields, header, bits = scratch[:57], scratch[64:68].view(np.int64), scratch[72:SCRATCH]
    if count < 1 or abs(last) > CLOCK_RANGE or abs(anchor) > CLOCK_RANGE:
        return 1
    for k in range(count):
        if decode_status(raw[k], lengths[k], fingerprint, bits, fields, header):
            return 2
        clock = header[1] if robot_clock else header[0]
        if abs(clock) > CLOCK_RANGE or clock_verdict(clock, last, anchor, period_us, bound):
            return 3
        gap = elapsed_periods(clock, anchor, period_us) - elapsed_periods(last, anchor, period_us)
        long_gaps = long_gaps + 1 if gap >= 2 else 0
        if long_gaps >= SLOW_STREAM:
            return 4
        last = clock
        anchor += anchor_step(clock, anchor, period_us, accepted)
        accepted += 1
    periods = elapsed_periods(last, anchor, period_us)
    q, v, tau_ext = fields[0:7], fields[14:21], fields[49:56]
    robot_utime = header[1]
    code = _reading_problem(q, v, tau_ext, header, limits)
    if code:
        return code
    step = periods - ints[I_PERIODS]
    if step >= 2 and step > bound:
        return 8
    if step < 1 or step >= motion.shape[0]:
        return 9  # beyond the precomputed allowances (the Python path decides)
    q_last, v_last = floats[F_MEASURED : F_MEASURED + 7], floats[F_MEASURED + 7 : F_MEASURED + 14]
    code = _motion_problem(q, v, q_last, v_last, motion[step], step * floats[F_PERIOD])
    if code:
        return code
    # every rule passed: the state moves on
    if robot_utime != 0 and ints[I_COMMANDS] >= 100:  # loop.SUCCESS_RATE_WINDOW
        rate, low = fields[56], floats[F_SUCCESS_MIN]
        floats[F_SUCCESS_MIN] = rate if not rate >= low else low
    if step >= 2:
        ints[I_GAPS + (0 if step <= 2 else 1 if step <= 10 else 2 if step <= 50 else 3)] += 1
        ints[I_LONGEST_GAP] = max(ints[I_LONGEST_GAP], step)
    for j in range(7):
        floats[F_LAST + j], floats[F_LAST + 7 + j] = q_last[j], v_last[j]
        floats[F_MEASURED + j], floats[F_MEASURED + 7 + j] = q[j], v[j]
        floats[F_MEASURED + 14 + j] = tau_ext[j]
    ints[I_LAST_CLOCK], ints[I_ANCHOR] = last, anchor
    ints[I_ACCEPTED], ints[I_LONG_GAPS] = accepted, long_gaps
    ints[I_PERIODS] = periods
    ints[I_UTIME] = header[0]
    return 0


@njit(cache=True)
def robot_torques(tau, gravity, adds_gravity, at_robot, command) -> None:
    """What the robot's torque interface is asked for, τ − g(q) (``at_robot``), and the
    command sent: that when the robot adds g, else τ (the driver subtracts its g:
    nsdrake/driver/controller_side.py's docstring)."""
    for j in range(at_robot.shape[0]):
        at_robot[j] = tau[j] - gravity[j]
        command[j] = at_robot[j] if adds_gravity else tau[j]


@njit(cache=True)
def finish_tick(tau, gravity, adds_gravity, at_robot, command, previous, bounds, ints, buffer, bits) -> int:
    """:func:`robot_torques` into ``at_robot`` and ``command``, the last gate on at_robot
    against ``previous``, the at_robot sent before (before the first command, the first
    status's joint_torque_desired: nsdrake/driver/loop.py) (``bounds`` rows: |τ| and its
    change per robot cycle, :func:`gate_bounds`), then the
    command's bytes into ``buffer``, stamped with the status's utime: 0, ``previous`` now
    this at_robot; or 1, ``buffer`` and ``previous`` unchanged."""
    robot_torques(tau, gravity, adds_gravity, at_robot, command)
    for j in range(7):
        if not (np.abs(at_robot[j]) <= bounds[0, j]):
            return 1
        if not (np.abs(at_robot[j] - previous[j]) <= bounds[1, j]):
            return 1
    encode_command(buffer, ints[I_UTIME], command, bits)
    previous[:] = at_robot
    return 0


def limit_table() -> np.ndarray:
    """(3, 7): the status limits of :func:`nsdrake.driver.panda.limit_problem`, rows lower,
    upper, |q̇|, with their margins."""
    from nsdrake.driver import panda

    return np.array([panda._LOWER, panda._UPPER, panda._FAST])


def gate_bounds() -> np.ndarray:
    """(2, 7): :func:`nsdrake.driver.panda.command_problem`'s bounds on |τ| and on its change."""
    from nsdrake.driver import panda

    return np.array([panda._COMMAND_BOUND, np.full(7, panda._RATE_BOUND)])


def motion_table(allowances, periods: int) -> np.ndarray:
    """(periods + 1, 2, 7): row k the allowances of a status k periods after the one answered
    before, on the jump and on the velocity mismatch, from ``allowances(k)`` (the loop's
    own, nsdrake/driver/loop.py); row 0 unused."""
    table = np.zeros((periods + 1, 2, 7))
    for k in range(1, periods + 1):
        table[k] = allowances(k)
    return table
