"""Benchmark: the controller side's tick against the simulated driver, at 1 kHz real time.

    python bench/bench_drive.py [--duration 20] [--out DIR] [--gc off|on|both] [--profile]

Soaks panda_wipe's first ``--duration`` seconds (at least 20) through the controller side
and the simulated driver in one process over memq://, the driver paced at real time (one
status per millisecond when the loop keeps up), and records each controller tick from the
status's arrival to the command's publish (nsdrake/driver/loop.py). Writes ``timing.json``
into ``--out`` (default ``bench/out/drive-soak``; with ``--gc both`` also
``timing_gc_on.json``), prints each, and ends with one JSON line.

``--gc``: ``off`` is nsdrake's setting (the collector frozen and disabled during the loop);
``on`` leaves it running and counts its collections and their longest pause; ``both``
soaks twice, on first. The process's resident memory growth is reported for each, and the
machine's 1-minute load average before and after (wall-clock ticks on a loaded machine are
preempted: read the figures with it).

``--profile`` instead says where the tick's time goes: the median of each stage over 3000
unpaced ticks (take and check the status; advance the diagram, which runs the controller's
periodic updates and evaluates every output for the loggers; publish the command), and
the share of the tick spent in the controller's code and in the reference's systems under
cProfile on CPU time (a ratio: the profiler inflates Python more than Drake's C++).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import resource
import sys
import time
from pathlib import Path

import numpy as np

from nsdrake.driver.run import prepare
from nsdrake.driver.timing import collector_paused, timing_line, write_timing
from nsdrake.experiment.scenario import load_scenario

OUT = Path(__file__).resolve().parent / "out" / "drive-soak"


def rss_mb() -> float:
    """Resident set size now [MB] (Linux /proc)."""
    pages = int(Path("/proc/self/statm").read_text().split()[1])
    return pages * resource.getpagesize() / 1e6


def soak(duration: float, pause_gc: bool) -> dict:
    scenario = load_scenario("panda_wipe", duration=duration)
    drive = prepare(scenario, realtime_rate=1.0)
    before, load_before = rss_mb(), os.getloadavg()[0]
    run = drive.run(pause_gc=pause_gc)
    timing = dict(run.timing)
    timing.update(
        load_average_1min=[load_before, os.getloadavg()[0]],  # the machine's, before and after
        scenario="panda_wipe",
        duration_s=duration,
        realtime_rate=1.0,
        rss_growth_mb=rss_mb() - before,
        failure=run.failure,
    )
    return timing


def staged_tick(loop, stages: dict) -> None:
    """ControllerLoop.tick with each stage timed (the status is already queued): the
    status taken and checked, the diagram advanced (the controller's periodic updates, the
    hold's sample, the loggers, which evaluate every output), the command published."""
    t0 = time.perf_counter()
    loop.lcm.HandleSubscriptions(0)
    arrival, status = loop._newest_status()
    steps = loop._check(status)
    loop._absorb_messages()
    t1 = time.perf_counter()
    loop.periods += steps
    loop.simulator.AdvanceTo(loop.periods * loop.period)
    t2 = time.perf_counter()
    loop._last, loop._last_arrival = status, arrival
    loop._command(arrival)
    t3 = time.perf_counter()
    for name, seconds in (("take and check the status", t1 - t0), ("advance", t2 - t1), ("publish", t3 - t2)):
        stages[name].append(seconds)


def where_the_time_goes(ticks: int = 3000) -> dict:
    """Median per-tick time [µs] of each stage of the tick over ``ticks`` unpaced ticks, and
    the share of the controller's code and of the reference's systems (the same run under
    cProfile: their cumulative time over the profiled ticks', a ratio)."""
    scenario = load_scenario("panda_wipe", duration=ticks * 1e-3)
    drive = prepare(scenario, realtime_rate=0.0)
    stages = {"take and check the status": [], "advance": [], "publish": []}
    loop, driver = drive.loop, drive.driver
    with collector_paused():
        driver.start()
        loop.start()
        while loop.time < scenario.duration - 0.5 * loop.period:
            driver.step()
            staged_tick(loop, stages)
    medians = {name: float(np.median(values)) * 1e6 for name, values in stages.items()}
    profiler = cProfile.Profile(time.process_time)  # CPU time: a loaded machine preempts the wall clock
    drive = prepare(load_scenario("panda_wipe", duration=1.0), realtime_rate=0.0)
    profiler.enable()
    drive.run()
    profiler.disable()
    stats = pstats.Stats(profiler)
    total = sum(v[3] for k, v in stats.stats.items() if k[2] == "tick" and "loop.py" in k[0])
    shares = {
        "controller (nsdrake/control)": entered_from_outside(stats, "/nsdrake/control/") / total,
        "reference systems": entered_from_outside(stats, "/nsdrake/experiment/reference") / total,
    }
    return {"ticks": ticks, "stage_median_us": medians, "share_of_tick_under_cprofile": shares}


def entered_from_outside(stats: pstats.Stats, folder: str) -> float:
    """Cumulative time [s] of the calls into the code under ``folder`` from code outside it
    (Drake's calls into a system's callbacks, the loop's), each call counted once."""
    seconds = 0.0
    for (filename, _, _), (_, _, _, _, callers) in stats.stats.items():
        if folder in filename:
            seconds += sum(ct for caller, (_, _, _, ct) in callers.items() if folder not in caller[0])
    return seconds


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration", type=float, default=20.0, help="soak length [s], at least 20")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--gc", choices=("off", "on", "both"), default="both")
    parser.add_argument("--profile", action="store_true")
    args = parser.parse_args()
    if args.profile:
        print(json.dumps(where_the_time_goes()))
        return 0
    if args.duration < 20.0:
        parser.error("--duration must be at least 20 s (the soak the issue asks for)")
    args.out.mkdir(parents=True, exist_ok=True)
    results = {}
    for setting in ("on", "off") if args.gc == "both" else (args.gc,):
        timing = soak(args.duration, pause_gc=setting == "off")
        name = "timing.json" if setting == "off" else "timing_gc_on.json"
        write_timing(args.out / name, timing)
        print(
            f"gc {setting}: {timing_line(timing)}; gc collections {timing['gc_collections']}, longest "
            f"{timing['gc_longest_pause_us']:.0f} µs; rss +{timing['rss_growth_mb']:.1f} MB "
            f"-> {args.out / name}"
        )
        results[f"gc_{setting}"] = {
            key: timing[key]
            for key in (
                "ticks",
                "p50_us",
                "p99_us",
                "p999_us",
                "max_us",
                "over_period",
                "gc_collections",
                "gc_longest_pause_us",
                "rss_growth_mb",
                "statuses_skipped",
                "load_average_1min",
                "failure",
            )
        }
    print(json.dumps(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
