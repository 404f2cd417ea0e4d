"""The loop's compiled tick (nsdrake/driver/tick.py) against its Python path, the reference
(``ControllerLoop.compiled = False``: every rule step by step, each refusal in words): on
random status streams with hostile statuses mixed in (clocks that repeat, go back, stay in
a period, jump past the silence bound; lost statuses, bursts, slow streams; joints that
jump, creep against their reported velocity, leave the Panda's limits; NaN; a robot out of
kMove; other joint counts; truncated bytes; success rates falling; a sensor's message not
finite or not one), both loops end the same
way (the same fault's words, or none) having sent the same command bytes and recorded the
same rows, with the same counts (periods, skipped, glitches, the lowest success rate).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from drake import lcmt_force_torque, lcmt_panda_status
from fake_bus import FakeBus, status_bytes

from nsdrake.driver.controller_side import build_controller_side
from nsdrake.driver.loop import ControllerLoop, DriveFaultError
from nsdrake.driver.wire import STATUS_ARRAYS
from nsdrake.experiment.scenario import load_scenario

UTIME0, ROBOT_UTIME0 = 1_700_000_000_000_000, 5_000_000  # [µs] a wall clock's, the robot's
STATUSES = 130  # a stream's length: past the success-rate window (100 commands)
# statuses the rules take (the compiled path must too) and those they refuse (it must leave
# to the Python path, which says why)
BENIGN = ("lost", "gap within the bound", "burst", "rate", "two periods")
FATAL = ("gap beyond the bound", "repeat", "back", "same period", "jump", "creep", "nan", "limit", "fast",
         "mode", "joints", "short", "longer", "clock switch", "slow stream", "sensor nan",
         "sensor bytes")  # fmt: skip


@pytest.fixture(scope="module")
def side():
    s = load_scenario("panda_wipe", duration=1.0)
    driver = dataclasses.replace(s.driver, first_status_timeout=0.3)
    return build_controller_side(dataclasses.replace(s, driver=driver))


def stream(rng, q0: np.ndarray, period_us: int, fatal: str | None):
    """[(arrival [s], status bytes, force-torque bytes)]: a Panda moving slowly from q0 (its velocities
    consistent), one in ten statuses after the first one of BENIGN, and ``fatal`` (one of
    FATAL, or None) at a random status after the success-rate window's first 100."""
    T = period_us * 1e-6
    v = rng.uniform(-0.05, 0.05, 7)
    events, k, arrival = [], 0, 0.0
    robot_clock, at = True, int(rng.integers(100, STATUSES - 12))
    for n in range(STATUSES):
        kind = BENIGN[rng.integers(len(BENIGN))] if n and rng.random() < 0.1 else None
        kind = fatal if n == at else kind
        step = {"lost": int(rng.integers(2, 12)), "gap within the bound": int(rng.integers(12, 49)),
                "gap beyond the bound": int(rng.integers(51, 70)), "two periods": 2}.get(kind, 1)  # fmt: skip
        if fatal == "slow stream" and at <= n < at + 10:
            step = 2
        k += step
        arrival += step * T + rng.uniform(0, 0.2 * T)
        if kind == "gap beyond the bound":  # on time on the wire, late on its own clock
            arrival -= (step - 1) * T
        q, vel = q0 + v * k * T, v.copy()
        tau_ext = rng.normal(0, 0.1, 7)
        clock = k * period_us
        if kind == "repeat":
            clock -= period_us
        elif kind == "back":
            clock -= 3 * period_us
        elif kind == "same period":
            clock -= 2 * period_us // 3  # a third of a period after the previous status
        elif kind == "jump":
            q[rng.integers(7)] += 0.01
        elif kind == "creep":
            q[rng.integers(7)] += 4e-4
        elif kind == "nan":
            [q, vel, tau_ext][rng.integers(3)][rng.integers(7)] = np.nan
        elif kind == "limit":
            q[3] = -0.0698 + 0.02
        elif kind == "fast":
            vel[rng.integers(7)] = 3.0
        elif kind == "clock switch":
            robot_clock = False
        message = lcmt_panda_status.decode(
            status_bytes(q, utime=UTIME0 + clock + int(rng.integers(-200, 200)), v=vel,
                         robot_utime=ROBOT_UTIME0 + clock if robot_clock else 0)
        )  # fmt: skip
        message.joint_torque_external = list(tau_ext)
        message.robot_mode = 4 if kind == "mode" else 2
        message.control_command_success_rate = rng.uniform(0.5, 1.0) if kind == "rate" else 1.0
        if kind == "joints":
            message.num_joints = 6
            for name in STATUS_ARRAYS:
                setattr(message, name, getattr(message, name)[:6])
        data = message.encode()
        if kind == "short":
            data = data[: int(rng.integers(0, len(data)))]
        elif kind == "longer":
            data += b"\0"
        sensor = lcmt_force_torque()
        sensor.fx, sensor.fy, sensor.fz, sensor.tx, sensor.ty, sensor.tz = rng.normal(0, 2, 6)
        if kind == "sensor nan":
            setattr(sensor, ("fx", "fy", "fz", "tx", "ty", "tz")[rng.integers(6)], np.inf)
        sensor = sensor.encode()
        if kind == "sensor bytes":
            sensor = sensor[:-1]
        if kind == "burst":  # this one and the one before arrive together
            arrival = events[-1][0]
        events.append((arrival, data, sensor))
    return events


def drive(side, events, compiled: bool) -> dict:
    """One loop over ``events`` on a fake bus; what it did."""
    bus = FakeBus()
    side.reset()
    loop = ControllerLoop(side, bus, clock=bus.clock, capacity=STATUSES + 2)
    loop.compiled = compiled
    loop.ready()
    for arrival, data, sensor in events:
        bus.at(arrival, "PANDA_STATUS", data)
        bus.at(arrival, "PANDA_FORCE_TORQUE", sensor)
    fault = None
    try:
        loop.start()
        while bus.pending:
            loop.tick()
    except DriveFaultError as e:
        fault = str(e)
    return {
        "fault": fault,
        "sent": [(c.utime, list(c.joint_torque)) for _, c in bus.sent],
        "rows": loop.recorder.rows[: loop.recorder.count].tobytes(),
        "compiled_ticks": loop.compiled_ticks,
        "counts": (
            loop.commands,
            loop.periods,
            loop.skipped,
            loop.longest_gap,
            list(loop.gap_counts),
            loop.clock_name,
            repr(loop.success_rate_min),
            loop.time,
        ),  # fmt: skip
    }


@pytest.mark.parametrize("fatal", [None, *FATAL])
def test_the_compiled_tick_ends_as_the_python_path_does(side, fatal):
    """Two streams with each fatal status (and two without): the same end, commands, rows
    and counts both ways; the compiled path answered every tick before the fatal status
    (catches a rule dropped or loosened in the compiled path, e.g. the velocity-mismatch
    check, which then answers a creeping joint the Python path refuses; a state moved on by
    a refused tick; a glitch counted in the wrong bin; a compiled path never taken)."""
    for seed in range(2):
        rng = np.random.default_rng(seed + 10 * (0 if fatal is None else 1 + FATAL.index(fatal)))
        q0, period_us = np.asarray(side.station.q0, dtype=float), round(side.scenario.control_period * 1e6)
        events = stream(rng, q0, period_us, fatal)
        ours, reference = drive(side, events, True), drive(side, events, False)
        assert ours["fault"] == reference["fault"], seed
        assert ours["counts"] == reference["counts"], seed
        assert ours["sent"] == reference["sent"], seed
        assert ours["rows"] == reference["rows"], seed
        assert (reference["fault"] is None) == (fatal is None), reference["fault"]
        # every tick but the start's took its statuses in compiled code (a sensor's fault comes after)
        taken = ours["counts"][0] - (0 if fatal in ("sensor nan", "sensor bytes") else 1)
        assert ours["compiled_ticks"] == taken and reference["compiled_ticks"] == 0
