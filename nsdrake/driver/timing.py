"""Each controller tick's compute time, from the status in to the command out, and the
garbage collector kept out of the loop."""

from __future__ import annotations

import contextlib
import gc
import json
import time
from pathlib import Path

import numpy as np


class TickTimes:
    """Compute times of the ticks, preallocated so that recording allocates nothing."""

    def __init__(self, capacity: int):
        self._times = np.zeros(max(1, capacity))
        self.count = 0

    def record(self, seconds: float) -> None:
        if self.count == self._times.size:  # longer than planned: grow (rare)
            self._times = np.concatenate([self._times, np.zeros(self._times.size)])
        self._times[self.count] = seconds
        self.count += 1

    @property
    def seconds(self) -> np.ndarray:
        return self._times[: self.count]


def timing_summary(times: np.ndarray, period: float, **extra) -> dict:
    """p50, p99, p99.9 and max of the tick times [µs], the ticks, and the ticks longer than
    the control period."""
    us = np.asarray(times) * 1e6
    summary = {"ticks": int(us.size), "period_us": period * 1e6}
    if us.size:
        p50, p99, p999 = np.percentile(us, [50.0, 99.0, 99.9])
        summary.update(
            p50_us=float(p50),
            p99_us=float(p99),
            p999_us=float(p999),
            max_us=float(us.max()),
            over_period=int(np.count_nonzero(us > period * 1e6)),
        )
    summary.update(extra)
    return summary


def timing_line(summary: dict) -> str:
    """One line for the terminal."""
    if not summary["ticks"]:
        return "timing: no tick ran"
    return (
        f"timing: {summary['ticks']} ticks, status in to command out p50 {summary['p50_us']:.0f} µs, "
        f"p99 {summary['p99_us']:.0f} µs, p99.9 {summary['p999_us']:.0f} µs, max {summary['max_us']:.0f} µs; "
        f"{summary['over_period']} over the {summary['period_us']:.0f} µs period"
    )


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
