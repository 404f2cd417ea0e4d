"""What the controller side refuses on the wire: each check a pure function that returns
the problem in words (None: fine), so that the loop can stop with one line."""

from __future__ import annotations

import numpy as np
from numba.extending import register_jitable


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
    q: np.ndarray, q_previous: np.ndarray, allowance: np.ndarray, periods: int, joint_names, why: str
) -> str | None:
    """A joint that moved more than its ``allowance`` [rad] (one per joint, for the
    ``periods`` since the previous status; ``why`` says where it comes from) since the
    previous status: a jump no Panda makes (the worst joint, by its excess, named)."""
    step = np.abs(np.subtract(q, q_previous))
    excess = step - allowance
    worst = int(np.argmax(excess))
    if excess[worst] <= 0.0:
        return None
    return (
        f"{joint_names[worst]} moved {step[worst]:.4g} rad in {periods} period(s), more than the "
        f"{allowance[worst]:.4g} rad {why}"
    )


def velocity_mismatch_problem(
    q: np.ndarray, q_previous: np.ndarray, v: np.ndarray, v_previous: np.ndarray, elapsed: float,
    allowance: np.ndarray, joint_names,
) -> str | None:  # fmt: skip
    """A joint whose position change over ``elapsed`` [s] differs from the trapezoid of its
    two reported velocities, (q̇_prev + q̇) Δt / 2, by more than its ``allowance`` [rad] (one
    per joint, or one for all): a position and a velocity that cannot both be the robot's
    (the worst joint, by its excess, named)."""
    moved = np.subtract(q, q_previous)
    expected = 0.5 * elapsed * np.add(v, v_previous)
    mismatch = np.abs(moved - expected)
    excess = mismatch - allowance
    worst = int(np.argmax(excess))
    if excess[worst] <= 0.0:
        return None
    allowed = float(np.broadcast_to(allowance, mismatch.shape)[worst])
    return (
        f"{joint_names[worst]} moved {moved[worst]:.4g} rad in {elapsed * 1e3:g} ms while its reported "
        f"velocity ({v_previous[worst]:.4g} then {v[worst]:.4g} rad/s) says {expected[worst]:.4g} rad: "
        f"they disagree by more than {allowed:.3g} rad (nsdrake/driver/panda.py)"
    )


def clock_problem(
    clock: int, previous: int, anchor: int, period_us: int, bound_periods: float, name: str
) -> str | None:
    """A status's clock (``name``: robot_utime or utime) [µs] against the previous status's
    and the first's (``anchor``): None when it lies in a later control period
    (:func:`elapsed_periods`) at most ``bound_periods`` periods on (a gap within the bound
    is periods the controller skips, never replays); else why not: it repeats or goes
    back (two publishers on the channel interleave their clocks), it falls in a period
    already answered (a stream faster than the controller's period, 2 kHz), or it jumps
    forward beyond the bound (a stream at 250 Hz, statuses lost, a wall clock stepped by
    NTP). Jitter of less than half a period around the anchor (a PC's utime; the loop keeps
    the anchor on the stream's phase, :func:`anchor_step`) is taken."""
    verdict = clock_verdict(clock, previous, anchor, period_us, bound_periods)
    gap = clock - previous
    if verdict == 0:
        return None
    if verdict == 1:
        return f"its {name} {clock} µs repeats the previous status's (a second publisher on the channel?)"
    if verdict == 2:
        return (
            f"its {name} went back {-gap} µs, from {previous} to {clock} µs "
            "(a second publisher on the channel?)"
        )
    if verdict == 3:
        return (
            f"its {name} advanced {gap} µs from the previous status's, within the same control "
            f"period: the stream is faster than the controller's period of {period_us} µs"
        )
    return (
        f"its {name} jumped {gap * 1e-3:.3f} ms ({gap / period_us:.1f} periods) from the previous "
        f"status's (the silence bound: {bound_periods:g} periods, driver.expire_sec)"
    )


@register_jitable
def clock_verdict(clock: int, previous: int, anchor: int, period_us: int, bound_periods: float) -> int:
    """:func:`clock_problem`'s rules as a code (0: taken; 1 repeats, 2 goes back, 3 the same
    period, 4 beyond the bound), in Python and in the compiled tick (nsdrake/driver/tick.py)."""
    gap = clock - previous
    if gap == 0:
        return 1
    if gap < 0:
        return 2
    if elapsed_periods(clock, anchor, period_us) <= elapsed_periods(previous, anchor, period_us):
        return 3
    if gap > bound_periods * period_us:
        return 4
    return 0


ANCHOR_GAIN = 16  # the anchor follows the stream's phase: at most 1/16 of a status's offset


@register_jitable
def anchor_step(clock: int, anchor: int, period_us: int, accepted: int) -> int:
    """How far [µs] the anchor moves toward the phase of ``clock``, the ``accepted``-th
    status taken after the first: its offset from the nearest period on the anchor, over
    ``accepted + 1`` (the anchor is the mean phase of the statuses so far) and at most
    over :data:`ANCHOR_GAIN` (then an average that follows a slow drift of the clock),
    rounded toward zero, so that the status keeps its period. On the robot's own clock
    (``robot_utime``, whole periods) the offset is zero; on a PC's ``utime`` the anchor
    stops being the first status's jitter, and jitter of less than half a period around
    the stream's phase is taken (against the first status alone, an offset of 300 µs on
    it and −250 µs on a later one would put that one in the period already answered)."""
    offset = clock - anchor - elapsed_periods(clock, anchor, period_us) * period_us
    return int(offset / min(accepted + 1, ANCHOR_GAIN))


@register_jitable
def elapsed_periods(clock: int, anchor: int, period_us: int) -> int:
    """Control periods from the first status's clock ``anchor`` to ``clock`` [µs], to the
    nearest: the controller's time is this many periods, re-anchored at every status on
    the robot's clock (never a sum of rounded gaps, which drifts with the clock's jitter)."""
    return (2 * (clock - anchor) + period_us) // (2 * period_us)


SLOW_STREAM = 10  # statuses in a row each two periods or more after the previous: a slower stream


def slow_stream_problem(in_a_row: int, gap: int, period_us: int, name: str) -> str | None:
    """A stream slower than the controller's period (250 Hz against 1 kHz), told from lost
    statuses by persistence: ``in_a_row`` statuses in a row, the last ``gap`` [µs] after
    the previous, each at least two periods after the one before (a lost status now and
    then is a skipped period; :data:`SLOW_STREAM` in a row is the stream's period)."""
    if in_a_row < SLOW_STREAM:
        return None
    return (
        f"{in_a_row} statuses in a row came two periods or more apart (the last {gap} µs after the "
        f"previous, by its {name}): the stream's period is not the controller's {period_us} µs"
    )
