"""A Panda driver that misbehaves on purpose, for the wire-fault tests over UDP
(tests/driver/test_udp.py): it publishes lcmt_panda_status (and lcmt_force_torque) at
1 kHz with robot_utime, a Panda at rest at --q, and once the controller has answered
``WARM`` statuses it injects ``--fault`` (``none``: never; SIGTERM ends it), keeps talking
for 0.4 s and prints one JSON line: the commands received in all, and those that answer
the faulty status or a later one (which must be none). Light on purpose (the lcm package
and Drake's message types only): it starts in a fraction of a second.

    python bad_driver.py --url URL --fault NAME --q q1,…,q7
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import time

import lcm
from drake import lcmt_force_torque, lcmt_panda_command, lcmt_panda_status

WARM = 100  # commands before the fault
ACCELERATION = 2.7  # [rad/s²] position_limit's joint 6 from rest to past its limit
UTIME0 = 1_700_000_000_000_000
FAULTS = (
    "undecodable", "nan", "position_limit", "velocity_limit", "two_publishers", "silence",
    "jump", "backward", "2khz", "250hz", "sensor_silence", "no_sensor", "creep", "none",
)  # fmt: skip


def status(q, v, utime, robot_utime) -> bytes:
    message = lcmt_panda_status()
    message.utime, message.robot_utime, message.num_joints = utime, robot_utime, 7
    zeros = [0.0] * 7
    for field in (
        "joint_position_desired", "joint_velocity_desired", "joint_acceleration_desired",
        "joint_torque", "joint_torque_desired", "joint_torque_external",
    ):  # fmt: skip
        setattr(message, field, zeros)
    message.joint_position, message.joint_velocity = list(q), list(v)
    message.robot_mode, message.control_command_success_rate = 2, 1.0
    return message.encode()


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--url", required=True)
    parser.add_argument("--fault", choices=FAULTS, required=True)
    parser.add_argument("--q", required=True)
    parser.add_argument("--seconds", type=float, default=20.0, help="give up after this long")
    parser.add_argument(
        "--after", type=float, default=0.4, help="[s] of talking after the fault (past any silence bound)"
    )
    args = parser.parse_args()
    stopped: list[int] = []  # SIGTERM ends the loop and the report is printed (fault "none": a
    signal.signal(signal.SIGTERM, lambda *_: stopped.append(1))  # robot at rest, told when to stop)
    bus = lcm.LCM(args.url)
    commands: list[int] = []

    def on_command(_channel, data):
        commands.append(lcmt_panda_command.decode(data).utime)

    subscription = bus.subscribe("PANDA_COMMAND", on_command)
    subscription.set_queue_capacity(1000)
    q, v = [float(x) for x in args.q.split(",")], [0.0] * 7
    fault = args.fault
    k, utime, robot_utime, offset = 0, UTIME0, 5_000_000, 0
    period, step = 1e-3, 1000
    began = faulty_utime = faulty_at = q_on = None
    now = time.monotonic()
    deadline, next_time = now + args.seconds, now
    while time.monotonic() < deadline and not stopped:
        k += 1
        if began is None and len(commands) >= WARM:
            began = time.monotonic()
            if fault == "2khz":
                period, step = 0.5e-3, 500
            elif fault == "250hz":
                period, step = 4e-3, 4000
            elif fault == "jump":
                offset = 3 * 3600 * 10**6  # an NTP step of the clock: every later status
            elif fault == "backward":
                offset = -5 * step
        on = began is not None
        utime, robot_utime = utime + step, robot_utime + step
        if on and fault == "position_limit":  # joint 6 accelerates from rest at 2.7 rad/s² until past
            # its position limit (about 0.93 s, 2.5 rad/s then: within its velocity limit): the
            # position is the integral of the reported velocity exactly, over any gap between
            # two statuses the controller answers (a velocity step, as it was, disagreed with
            # the position when the controller skipped a status: a consistency refusal instead)
            if q_on is None:
                q_on, n_on = q[5], 0
            n_on += 1
            t_on = n_on * period
            q[5], v[5] = q_on + 0.5 * ACCELERATION * t_on**2, ACCELERATION * t_on
        if on and fault == "creep":  # joint 7 creeps at 5 rad/s while its velocity reads 0 (issue 35)
            q[6] += 0.005
        data = status(
            q, v if not (on and fault == "velocity_limit") else [3.0] + v[1:], utime, robot_utime + offset
        )
        # every status from the fault on is faulty: one datagram can be lost on UDP (it was,
        # once in a loaded CI run), and a fault sent once would then not be a test of it
        if on and fault == "undecodable":
            data = b"not an lcmt_panda_status"
        if on and fault == "nan":
            data = status([math.nan] + q[1:], v, utime, robot_utime + offset)
        faulty = on and (fault != "position_limit" or q[5] > 3.7525 + 0.01)
        if faulty and faulty_utime is None:
            faulty_utime, faulty_at = utime, time.monotonic()
        if not (on and fault == "silence"):
            bus.publish("PANDA_STATUS", data)
        if on and fault == "two_publishers":  # a second driver: its own clock, its statuses between
            bus.publish("PANDA_STATUS", status(q, v, utime + 1, 1000 + k))
        if not (fault == "no_sensor" or (on and fault == "sensor_silence")):
            bus.publish("PANDA_FORCE_TORQUE", lcmt_force_torque().encode())
        if faulty_at is not None and time.monotonic() > faulty_at + args.after:
            break
        next_time += period
        _sleep_until(next_time, bus)
    after = [u for u in commands if faulty_utime is not None and u >= faulty_utime]
    print(
        json.dumps(
            {
                "fault": fault,
                "commands": len(commands),
                "after_fault": len(after),
                "injected": faulty_utime is not None,
            }
        )
    )


def _sleep_until(when: float, bus) -> None:
    while (remaining := when - time.monotonic()) > 0:
        try:
            bus.handle_timeout(max(0, int(remaining * 1e3)))
        except OSError:  # a signal (SIGTERM: stop and report) interrupted the wait: the loop decides
            return


if __name__ == "__main__":
    main()
