"""Benchmark: what this machine itself allows a 1 kHz loop, apart from nsdrake's code.

    python bench/bench_machine_floor.py [--duration 20] [--runs 3] [--calls 6000]

Issue 27's free-running acceptance asks two processes to exchange a status and a command
every millisecond for 20 s with no silence longer than the drive's bound
(``driver.expire_sec``: 50 ms by default; 3 ms before issue 35). That needs every thread
involved to be woken up on time. Two measurements of the floor:

- ``wakeup``: ``cyclictest`` (rt-tests, the Linux real-time community's latency test, not
  nsdrake's code): two C threads, one per core, each woken by an absolute 1 ms timer for
  ``--duration`` seconds, at SCHED_FIFO priority 90 with memory locked and
  ``/dev/cpu_dma_latency`` held at 0 (as root; without root at normal priority). Per run
  and thread: the largest wake-up latency and how many wake-ups came later than the
  drive's silence bound. If a C thread at real-time priority is woken later than the
  bound, no Python driver or controller on this machine can keep it.
- ``step``: panda_wipe's controller as a plain ``ControllerStep`` at fresh states, CPU time
  per call (``time.thread_time``), ``hot`` (calls back to back) and ``paced`` (one call
  per millisecond, the thread asleep in between, as the drive's loop is): the same code
  and inputs, so the ratio is what sleeping between ticks costs on this machine (caches
  and idle states), the part of the drive's tick CPU figures that is not the loop's code.

Prints one line per part, writes ``table.md`` under ``--out`` (default
``bench/out/machine_floor``; docs/results/machine_floor/ keeps the one the docs show) and
ends with one JSON line. Measure on a quiet machine (the
1-minute load is recorded).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from nsdrake.experiment.driver_config import DriverConfig

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_controller import scenario_step  # noqa: E402 (the bench folder's own helper)

OUT = Path(__file__).resolve().parent / "out" / "machine_floor"


def silence_bound_us() -> float:
    """The drive's default silence bound [µs], the driver's command expiry."""
    return DriverConfig().expire_sec * 1e6


def histogram(path: Path) -> np.ndarray:
    """cyclictest's --histfile: rows of (latency µs, count per thread…)."""
    rows = [line.split() for line in path.read_text().splitlines() if line[:1].isdigit()]
    return np.array([[int(x) for x in row] for row in rows], dtype=np.int64)


def summary_line(path: Path, name: str) -> list[int]:
    """A per-thread figure of cyclictest's --histfile (``# Max Latencies: 00012 00034``)."""
    line = next(line for line in path.read_text().splitlines() if line.startswith(name))
    return [int(x) for x in line.split(":")[1].split()]


def wakeup(duration: float, runs: int, bound_us: float) -> dict:
    if shutil.which("cyclictest") is None:
        return {"failure": "cyclictest not installed (Debian/Ubuntu: apt install rt-tests)"}
    root = os.geteuid() == 0
    options = ["-m", "-p", "90"] if root else []
    result = {"threads": 2, "interval_us": 1000, "duration_s": duration, "realtime_priority": root}
    result["runs"] = []
    buckets = int(bound_us * 10)
    with tempfile.TemporaryDirectory() as folder:
        for run in range(runs):
            hist = Path(folder) / f"run{run}.txt"
            load = os.getloadavg()[0]
            subprocess.run(
                ["cyclictest", *options, "-i", "1000", "-D", f"{duration:g}", "-t", "2", "-a", "-q",
                 f"--histogram={buckets}", f"--histfile={hist}"],
                check=True, capture_output=True, timeout=duration + 60,
            )  # fmt: skip
            table = histogram(hist)
            maxima = summary_line(hist, "# Max Latencies")
            overflows = summary_line(hist, "# Histogram Overflows")
            late = [int(table[table[:, 0] > bound_us, 1 + k].sum()) + overflows[k] for k in range(2)]
            result["runs"].append({"max_us": maxima, "later_than_bound": late, "load_average_1min": load})
            print(f"wakeup run {run + 1}: largest wake-up latency {maxima} µs per thread; "
                  f"{late} wake-ups later than {bound_us:g} µs (load {load:.2f})")  # fmt: skip
    result["runs_with_a_wakeup_later_than_bound"] = sum(any(r["later_than_bound"]) for r in result["runs"])
    return result


def step_cpu(calls: int, paced: bool) -> tuple[float, float]:
    """CPU time per ControllerStep.step [µs], median and 99.9th percentile."""
    step, q0, period = scenario_step("panda_wipe")
    n, m_t, rotational = step.model.n, step.plan.m_t, step.plan.m_r > 0
    rng = np.random.default_rng(0)
    states = np.hstack([q0 + 0.05 * rng.standard_normal((512, n)), 0.2 * rng.standard_normal((512, n))])
    x_d = np.zeros(m_t)
    extra = (np.array([0.0, 1.0, 0.0, 0.0]), np.zeros(3), np.zeros(3)) if rotational else ()
    wrench = np.zeros(6)
    cpu = np.empty(calls)
    due = time.perf_counter()
    for k in range(calls + 200):  # the first 200 calls warm up
        if paced:
            due += period
            if due > time.perf_counter():
                time.sleep(due - time.perf_counter())
        s = states[k % 512]
        c0 = time.thread_time_ns()
        step.step(k * period, s[:n], s[n:], wrench, x_d, x_d, x_d, 5.0, *extra)
        if k >= 200:
            cpu[k - 200] = (time.thread_time_ns() - c0) / 1e3
    return float(np.median(cpu)), float(np.percentile(cpu, 99.9))


def step(calls: int, runs: int) -> dict:
    figures = {"hot": [], "paced": []}
    for _ in range(runs):  # interleaved, so both see the same machine
        for mode in figures:
            figures[mode].append(step_cpu(calls, mode == "paced"))
    result = {"calls": calls, "runs": runs, "load_average_1min": os.getloadavg()[0]}
    for mode, values in figures.items():
        result[f"{mode}_cpu_p50_us"] = round(float(np.median([v[0] for v in values])), 1)
        result[f"{mode}_cpu_p999_us"] = round(float(np.median([v[1] for v in values])), 1)
    result["paced_over_hot_p50"] = round(result["paced_cpu_p50_us"] / result["hot_cpu_p50_us"], 2)
    result["paced_over_hot_p999"] = round(result["paced_cpu_p999_us"] / result["hot_cpu_p999_us"], 2)
    print(f"step: panda_wipe's ControllerStep CPU per call, hot p50 {result['hot_cpu_p50_us']} µs "
          f"p99.9 {result['hot_cpu_p999_us']} µs; paced at 1 kHz p50 {result['paced_cpu_p50_us']} µs "
          f"p99.9 {result['paced_cpu_p999_us']} µs (medians of {runs} runs)")  # fmt: skip
    return result


def table(results: dict) -> str:
    """The measured table (docs/results/machine_floor/table.md)."""
    bound = results["silence_bound_us"]
    lines = [
        "# machine_floor",
        "",
        "What this machine allows a 1 kHz loop, apart from nsdrake's code: cyclictest's wake-up "
        "latency (rt-tests) against the drive's silence bound, and the same ControllerStep calls "
        "back to back and paced at 1 kHz.",
        "",
        "| measured | load (1 min) | figure |",
        "|---|---|---|",
    ]
    wake = results["wakeup"]
    if "failure" in wake:
        lines.append(f"| cyclictest | – | not run: {wake['failure']} |")
    else:
        how = "SCHED_FIFO 90, memory locked" if wake["realtime_priority"] else "normal priority"
        for k, run in enumerate(wake["runs"], 1):
            lines.append(
                f"| cyclictest run {k}: 2 C threads, 1 ms timer, {wake['duration_s']:g} s, {how} "
                f"| {run['load_average_1min']:.2f} | largest wake-up latency "
                f"{' and '.join(f'{m / 1e3:.2f} ms' for m in run['max_us'])}; "
                f"{sum(run['later_than_bound'])} wake-ups later than {bound / 1e3:g} ms |"
            )
    step = results["step"]
    for mode, words in (("hot", "back to back"), ("paced", "one per ms, asleep between")):
        lines.append(
            f"| panda_wipe's ControllerStep, CPU per call, {words} (median of {step['runs']} runs) "
            f"| {step['load_average_1min']:.2f} | p50 {step[f'{mode}_cpu_p50_us']:.1f} µs, "
            f"p99.9 {step[f'{mode}_cpu_p999_us']:.1f} µs |"
        )
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--duration", type=float, default=20.0, help="seconds per cyclictest run")
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--calls", type=int, default=6000, help="ControllerStep calls per run")
    parser.add_argument("--out", type=Path, default=OUT, help="where table.md is written")
    args = parser.parse_args()
    bound = silence_bound_us()
    results = {"bench": "machine_floor", "silence_bound_us": bound}
    results["wakeup"] = wakeup(args.duration, args.runs, bound)
    results["step"] = step(args.calls, args.runs)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "table.md").write_text(table(results))
    print(table(results), end="")
    print(json.dumps(results))


if __name__ == "__main__":
    main()
