"""Progress in a log (nsdrake.reporting.progress): a short line at a low rate, driven by a
fake clock, so that no test depends on how fast the machine is."""

from __future__ import annotations

import io
import threading

import pytest

from nsdrake.reporting.progress import INTERVAL_VARIABLE, LOG_INTERVAL, Progress, log_interval
from nsdrake.studies.sweep import SweepProgress


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_run_prints_one_line_per_interval_with_simulated_time_and_real_time_factor():
    """Catches a line per report (a flood: a run reports a hundred times), no line at all,
    a heartbeat that repeats a line within the interval, a wrong real-time factor, and
    lines after the work is done."""
    clock, log = Clock(), io.StringIO()
    progress = Progress("panda_wipe", simulated=56.0, stream=log, interval=10.0, clock=clock)
    for k in range(1, 10):  # 1 s of wall time per report
        clock.now += 1.0
        progress(k / 100)
    assert log.getvalue() == ""  # 9 s: nothing due yet
    clock.now += 1.0
    progress(0.10)  # 10 s: 5.6 s simulated
    assert log.getvalue() == "nsdrake: panda_wipe: 5.6 of 56 s simulated (10%), 0.56x real time, 10 s\n"
    clock.now += 5.0
    progress.beat()  # the heartbeat, 5 s later: not due
    assert log.getvalue().count("\n") == 1
    clock.now += 5.0
    progress.beat()  # 10 s after the last line, no new report: the same work, later
    assert log.getvalue().splitlines()[-1] == (
        "nsdrake: panda_wipe: 5.6 of 56 s simulated (10%), 0.28x real time, 20 s"
    )
    clock.now += 30.0
    progress(1.0)
    progress.beat()
    assert log.getvalue().count("\n") == 2  # done: the command's own lines follow


def test_compare_and_sweep_lines_count_what_is_done():
    clock, log = Clock(), io.StringIO()
    compare = Progress("realism", total=9, unit="variants done", stream=log, interval=10.0, clock=clock)
    clock.now += 12.0
    compare(3 / 9)
    sweep = SweepProgress(40, stream=log, label="sweep fig3_gains", interval=10.0, clock=clock)
    clock.now += 12.0
    sweep(12, failed=1)
    assert log.getvalue().splitlines() == [
        "nsdrake: realism: 3 of 9 variants done, 12 s",
        "nsdrake: sweep fig3_gains: 12 of 40 runs done (1 failed), 12 s",
    ]


def test_a_terminal_gets_the_bar_and_no_lines():
    """Catches log lines on a terminal (they would break the bar) and a bar whose line is
    not ended when the work stops half-way."""
    clock, tty = Clock(), Terminal()
    progress = Progress("fig3", simulated=10.0, stream=tty, interval=10.0, clock=clock)
    with progress:
        clock.now += 60.0
        progress(0.5)
        progress.beat()
    assert tty.getvalue() == "\rfig3 [###############...............]  50%  60.0 s\n"


def test_the_heartbeat_prints_while_nothing_reports():
    """A compare variant or a sweep run can take minutes without a report: the heartbeat
    thread prints the line anyway. (Waits for the thread, with a deadline far above its
    interval; no timing is asserted.)"""
    log, printed = io.StringIO(), threading.Event()

    class Log(io.StringIO):
        def write(self, text):
            log.write(text)
            printed.set()
            return len(text)

    with Progress("lyapunov", total=3, unit="variants done", stream=Log(), interval=0.01) as progress:
        progress(1 / 3)
        assert printed.wait(timeout=30.0)
    assert log.getvalue().startswith("nsdrake: lyapunov: 1 of 3 variants done, ")
    assert progress._thread is None  # stopped with the work


@pytest.mark.parametrize(("value", "expected"), [("30", 30.0), ("0", LOG_INTERVAL), ("soon", LOG_INTERVAL)])
def test_the_interval_can_be_set_in_the_environment(monkeypatch, value, expected):
    monkeypatch.setenv(INTERVAL_VARIABLE, value)
    assert log_interval() == expected
