"""Tick timing: the summary's figures and the garbage collector kept out of the loop."""

from __future__ import annotations

import gc

import numpy as np

from nsdrake.driver.timing import GcPauses, TickTimes, collector_paused, timing_line, timing_summary


def test_summary_of_known_times():
    times = TickTimes(capacity=4)
    for us in range(1, 1001):  # 1 … 1000 µs, growing past the capacity; CPU time a tenth
        times.record(us * 1e-6, us * 1e-7)
    s = timing_summary(times.seconds, 5e-4, times.cpu_seconds)
    assert s["ticks"] == 1000
    np.testing.assert_allclose(
        [s["p50_us"], s["p99_us"], s["p999_us"], s["max_us"]], [500.5, 990.01, 999.001, 1000.0]
    )
    np.testing.assert_allclose(
        [s["cpu_p50_us"], s["cpu_p99_us"], s["cpu_p999_us"], s["cpu_max_us"]], [50.05, 99.001, 99.9001, 100.0]
    )
    assert s["over_period"] == 500  # 501 … 1000 µs over a 500 µs period
    assert "p99.9 999 µs" in timing_line(s) and "CPU time: p99.9 100 µs" in timing_line(s)


def test_the_collector_is_off_inside_and_restored_after():
    assert gc.isenabled()
    pauses = GcPauses()
    with collector_paused(), pauses.watching():
        assert not gc.isenabled()
        garbage = [[] for _ in range(100_000)]  # would trigger a generation-0 collection
        del garbage
    assert gc.isenabled()
    assert pauses.count == 0
    with pauses.watching():
        gc.collect()
    assert pauses.count == 1 and pauses.longest > 0.0
