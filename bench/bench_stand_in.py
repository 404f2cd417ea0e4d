"""Benchmark: what the simulated driver (the stand-in robot) costs the PC per period, before
and after issue 44 cut it, in the same run.

    python bench/bench_stand_in.py [--rounds 3] [--duration 3]

Both drivers are given the commands a lockstep panda_wipe drive sent over its first
``--duration`` seconds (the approach and, from 1.44 s, the contact), as ``nsdrake sim-driver``
gives them: each period the status and sensor message of t_k taken and stamped
(nsdrake/driver/wire.py's ``stamp_status``), the period's torque applied, the plant advanced.

- *before*: the Drake diagram of LCM systems of 6395e08 (tests/driver/lcm_simulated_driver.py:
  subscriber, PandaCommandReceiver, PandaStatusSender, publishers and loggers in the diagram,
  the messages taken off an in-process bus as nsdrake sim-driver forwarded them);
- *after*: nsdrake/driver/simulated_driver.py (the command a fixed input, the messages
  encoded in place from the ports, no logs: ``record=False``, as sim-driver runs it).

``--rounds`` alternating rounds; each round's CPU time per period (``time.process_time``
over the whole replay: the thread's work, not the machine's waits), their medians and the
ratio after / before. The two are the same robot to the bit (tests/driver/test_stand_in.py).
Prints one JSON line with the machine's 1-minute load before and after.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from pydrake.lcm import DrakeLcm

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "driver"))  # the driver before issue 44, kept for comparison

from lcm_simulated_driver import LcmSimulatedDriver  # noqa: E402

from nsdrake.driver.run import run_simulated  # noqa: E402
from nsdrake.driver.simulated_driver import SimulatedDriver  # noqa: E402
from nsdrake.driver.wire import stamp_status  # noqa: E402
from nsdrake.experiment.scenario import load_scenario  # noqa: E402


def before(scenario, commands: np.ndarray) -> float:
    """CPU [µs] per period of the LCM diagram, its messages forwarded off its own bus."""
    inner, outgoing = DrakeLcm("memq://"), []
    d = scenario.driver
    inner.Subscribe(d.status_channel, lambda data: outgoing.append(data))
    inner.Subscribe(d.force_torque_channel, lambda data: outgoing.append(data))
    driver = LcmSimulatedDriver(scenario, inner)
    driver.start()
    start = time.process_time()
    for k, torque in enumerate(commands):
        inner.HandleSubscriptions(0)
        status, _ = outgoing
        stamp_status(status, k, k, 2, 1.0)
        outgoing.clear()
        driver.apply_torque(torque, utime=k)
        driver.advance()
    return (time.process_time() - start) / len(commands) * 1e6


def after(scenario, commands: np.ndarray) -> float:
    """CPU [µs] per period of the lean driver (record=False, as sim-driver runs it)."""
    driver = SimulatedDriver(scenario, None, record=False)
    driver.start()
    start = time.process_time()
    for k, torque in enumerate(commands):
        status, _ = driver.messages()
        stamp_status(status, k, k, 2, 1.0)
        driver.apply_torque(torque)
        driver.advance()
    return (time.process_time() - start) / len(commands) * 1e6


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--duration", type=float, default=3.0, help="the recorded drive's length [s]")
    args = parser.parse_args()
    scenario = load_scenario("panda_wipe", duration=args.duration)
    run = run_simulated(scenario, realtime_rate=0.0)
    commands = run.loop.recorder.logs()["command"].data().T.copy()
    load = os.getloadavg()[0]
    rounds = [(before(scenario, commands), after(scenario, commands)) for _ in range(args.rounds)]
    old, new = (float(np.median(values)) for values in zip(*rounds, strict=True))
    for k, (b, a) in enumerate(rounds):
        print(f"round {k + 1}: before {b:.0f} µs, after {a:.0f} µs of CPU per period ({a / b:.2f})")
    print(f"median of {args.rounds}: before {old:.0f} µs, after {new:.0f} µs per period ({new / old:.2f})")
    result = {
        "bench": "stand_in", "periods": len(commands), "rounds": args.rounds,
        "before_cpu_per_period_us": old, "after_cpu_per_period_us": new, "after_over_before": new / old,
        "load_average_1min": [load, os.getloadavg()[0]],
    }  # fmt: skip
    print(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
