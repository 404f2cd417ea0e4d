"""Each controller tick's compute time, from the status in to the command out, and the
garbage collector kept out of the loop."""

from __future__ import annotations

import contextlib
import gc
import json
import time
from pathlib import Path

import numpy as np

# Glitches (issue 35): statuses answered two periods or more after the previous one answered,
# within the silence bound, by their distance in periods: (label, first, last).
GAP_BINS = (("2", 2, 2), ("3-10", 3, 10), ("11-50", 11, 50), ("over 50", 51, None))


def gap_bin(periods: int) -> int:
    """The index in :data:`GAP_BINS` of a gap of ``periods`` (>= 2) periods."""
    return 0 if periods <= 2 else 1 if periods <= 10 else 2 if periods <= 50 else 3


def gap_summary(counts, longest: int) -> dict:
    """timing.json's ``gaps`` (how many of each bin) and ``longest_gap_periods``."""
    return {
        "gaps": {label: int(n) for (label, _, _), n in zip(GAP_BINS, counts, strict=True)},
        "longest_gap_periods": int(longest),
    }


class TickTimes:
    """Compute times of the ticks, preallocated so that recording allocates nothing: the
    wall-clock time of each and the CPU time the loop's thread spent in it (the two differ
    by the time the thread waited: preempted by other processes, or paged)."""

    def __init__(self, capacity: int):
        self._times = np.zeros((2, max(1, capacity)))
        self.count = 0

    def record(self, seconds: float, cpu_seconds: float = np.nan) -> None:
        if self.count == self._times.shape[1]:  # longer than planned: grow (rare)
            self._times = np.concatenate([self._times, np.zeros_like(self._times)], axis=1)
        self._times[0, self.count] = seconds
        self._times[1, self.count] = cpu_seconds
        self.count += 1

    @property
    def seconds(self) -> np.ndarray:
        return self._times[0, : self.count]

    @property
    def cpu_seconds(self) -> np.ndarray:
        return self._times[1, : self.count]


def timing_summary(times: np.ndarray, period: float, cpu_times: np.ndarray | None = None, **extra) -> dict:
    """p50, p99, p99.9 and max of the tick times [µs], the ticks, and the ticks longer than
    the control period; with ``cpu_times``, the same percentiles of the ticks' CPU time
    (``cpu_p50_us`` …)."""
    us = np.asarray(times) * 1e6
    summary = {"ticks": int(us.size), "period_us": period * 1e6}
    if us.size:
        summary.update(_percentiles(us, ""), over_period=int(np.count_nonzero(us > period * 1e6)))
        if cpu_times is not None:
            summary.update(_percentiles(np.asarray(cpu_times) * 1e6, "cpu_"))
    summary.update(extra)
    return summary


def _percentiles(us: np.ndarray, prefix: str) -> dict:
    p50, p99, p999 = np.percentile(us, [50.0, 99.0, 99.9])
    names = ("p50_us", "p99_us", "p999_us", "max_us")
    return {prefix + name: float(v) for name, v in zip(names, (p50, p99, p999, us.max()), strict=True)}


def timing_line(summary: dict) -> str:
    """One line for the terminal."""
    if not summary["ticks"]:
        return "timing: no tick ran"
    return (
        f"timing: {summary['ticks']} ticks, status in to command out p50 {summary['p50_us']:.0f} µs, "
        f"p99 {summary['p99_us']:.0f} µs, p99.9 {summary['p999_us']:.0f} µs, max {summary['max_us']:.0f} µs; "
        f"{summary['over_period']} over the {summary['period_us']:.0f} µs period"
        + (f" (its CPU time: p99.9 {summary['cpu_p999_us']:.0f} µs)" if "cpu_p999_us" in summary else "")
        + (f"; {summary['statuses_skipped']} statuses skipped" if summary.get("statuses_skipped") else "")
        + _gaps_note(summary.get("gaps"), summary.get("longest_gap_periods"))
        + (
            f"; longest silence {summary['longest_silence_us'] / 1e3:.1f} ms"
            if summary.get("longest_silence_us")
            else ""
        )
        + _success_rate_note(summary.get("control_command_success_rate_min"))
    )


def _gaps_note(gaps: dict | None, longest: int | None) -> str:
    """The glitches: how many gaps of each length, the longest (nothing without any)."""
    if not gaps or not any(gaps.values()):
        return ""
    counts = ", ".join(f"{n} of {label}" for label, n in gaps.items() if n)
    return f"; late statuses: {counts} periods, the longest {longest} periods"


def _success_rate_note(rate: float | None) -> str:
    """The robot's lowest control_command_success_rate, when it fell below 0.95."""
    if rate is None or rate >= 0.95:
        return ""
    return f"; the robot's control_command_success_rate fell to {rate:.2f}"


def write_timing(path: Path, summary: dict) -> None:
    Path(path).write_text(json.dumps(summary, indent=2) + "\n")


class GcPauses:
    """Records every collection the garbage collector runs while active (gc.callbacks):
    how many, and the longest pause [s]."""

    def __init__(self):
        self.count = 0
        self.longest = 0.0
        self._start = None

    def __call__(self, phase, info):
        if phase == "start":
            self._start = time.perf_counter()
        elif self._start is not None:
            self.count += 1
            self.longest = max(self.longest, time.perf_counter() - self._start)
            self._start = None

    @contextlib.contextmanager
    def watching(self):
        gc.callbacks.append(self)
        try:
            yield self
        finally:
            gc.callbacks.remove(self)


@contextlib.contextmanager
def collector_paused(paused: bool = True):
    """Python's garbage collector off for the block (``paused``): everything allocated so
    far frozen out of later collections (gc.freeze) and automatic collections disabled,
    so that no collection pauses the real-time loop; restored afterwards."""
    if not paused:
        yield
        return
    was_enabled = gc.isenabled()
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        gc.unfreeze()
        if was_enabled:
            gc.enable()
