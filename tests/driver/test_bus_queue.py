"""The drive's bus keeps every message that arrives while the controller computes (issue
37): over real UDP multicast, inside a private network namespace (tests/driver/netns.py),
which ``memq://`` cannot show (it delivers every queued message whatever a subscription's
queue capacity)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

from netns import URL, require_namespace, run_in_namespace

ROOT = Path(__file__).resolve().parents[2]
MESSAGES = 50  # per channel: 50 ms of a 1 kHz stream; LCM's default queue holds 30

SCRIPT = f"""
import json, time
import lcm
from nsdrake.driver.bus import LcmBus

bus = LcmBus({URL!r})
got = {{"PANDA_STATUS": [], "PANDA_FORCE_TORQUE": []}}
for channel, messages in got.items():
    bus.subscribe(channel, messages.append)
robot = lcm.LCM({URL!r})
for k in range({MESSAGES}):  # a 1 kHz robot, while the controller does not read the bus
    for channel in got:
        robot.publish(channel, k.to_bytes(2, "little"))
    time.sleep(1e-3)
time.sleep(0.5)
first = bus.handle(0)
time.sleep(0.5)  # a receive thread slowed by a loaded machine: what it still had
bus.handle(0)
received = {{c: [int.from_bytes(m, "little") for m in ms] for c, ms in got.items()}}
print(json.dumps({{"first": first, **received}}))
"""


def test_every_message_that_arrives_during_a_tick_is_delivered(tmp_path):
    """50 statuses and 50 force-torque messages published over UDP at 1 kHz while the bus
    is not read (a 50 ms tick): the bus then delivers all of them, in order, on both channels.
    Catches a subscription left at LCM's default queue capacity (30: the rest dropped as
    they arrive, and the controller acts on a stale status), on any channel."""
    require_namespace()
    (tmp_path / "check.py").write_text(SCRIPT)
    result = run_in_namespace(f"PYTHONPATH={ROOT} {sys.executable} check.py", cwd=tmp_path, timeout=120)
    assert result.returncode == 0, result.stderr
    got = json.loads(result.stdout.strip().splitlines()[-1])
    for channel in ("PANDA_STATUS", "PANDA_FORCE_TORQUE"):
        assert got[channel] == list(range(MESSAGES)), (channel, len(got[channel]))
