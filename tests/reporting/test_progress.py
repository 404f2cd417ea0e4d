"""Progress of long work (nsdrake/reporting/progress.py): a bar on a terminal, one line every
LOG_INTERVAL seconds of wall time elsewhere, so that a CI log shows a run is alive."""

from __future__ import annotations

import io
import re
import sys
import threading

from nsdrake.cli import main
from nsdrake.reporting.progress import LOG_INTERVAL, Progress


class Terminal(io.StringIO):
    def isatty(self):
        return True


class Clock:
    def __init__(self):
        self.now = 100.0

    def __call__(self):
        return self.now


def test_a_log_gets_one_line_per_interval_with_simulated_time_and_real_time_factor():
    """Catches a line per call (a wall of text in a CI log), no line at all, a line after
    the work is done, and a simulated time or real-time factor computed from the wrong
    quantity: 20 calls over 35 s of a fake clock give lines at 10, 20 and 30 s."""
    log, clock = io.StringIO(), Clock()
    progress = Progress("panda_wipe", 1.0, simulated=56.0, stream=log, clock=clock)
    for k in range(1, 21):
        clock.now = 100.0 + 35.0 * k / 20
        progress(k / 20)
    lines = log.getvalue().splitlines()
    assert len(lines) == 3, lines
    # the first line at k = 6 (10.5 s): 30% of 56 s simulated, 16.8 s, at 1.6x real time
    assert lines[0] == "panda_wipe: 30%, 16.8 s simulated in 10 s (1.6x real time)"
    assert all(line.startswith("panda_wipe: ") for line in lines)


def test_the_time_spent_compiling_kernels_is_not_simulation_time():
    """A first run compiles nsdrake's kernels inside its first steps (issue 36: the first line
    said "0.05 s simulated in 129 s (0.00039x real time)"). Catches the compile counted as
    simulation time, a compile that happened before the progress started subtracted again,
    and a line that hides the compile: 30 s compiled before, then 40 s of compile and 10 s
    of simulation make 20% of 10 s simulated in 10 s."""
    log, clock, compiled = io.StringIO(), Clock(), [30.0]
    progress = Progress("fig3", 1.0, simulated=10.0, stream=log, clock=clock, compiling=lambda: compiled[0])
    clock.now += 20.0
    compiled[0] += 20.0  # compiling, nothing simulated yet
    progress(0.0)
    clock.now += 30.0
    compiled[0] += 20.0
    progress(0.2)
    assert log.getvalue().splitlines() == [
        "fig3: 0%, compiling nsdrake's kernels (20 s)",
        "fig3: 20%, 2 s simulated in 10 s (0.2x real time), after 40 s compiling nsdrake's kernels",
    ]


def test_after_a_long_gap_the_next_line_is_one_interval_away():
    """A run that reports nothing for minutes (a slow step, a machine under load): one line
    when it reports again, then the next only one interval later, by the heartbeat as by the
    reports. Catches the next line scheduled from the previous schedule instead of from now,
    which after a gap of k intervals gives the log a burst of k lines, one per report."""
    log, clock = io.StringIO(), Clock()
    progress = Progress("panda_wipe", 1.0, simulated=56.0, stream=log, clock=clock)
    clock.now += LOG_INTERVAL
    progress(0.1)
    clock.now += 9.5 * LOG_INTERVAL  # the gap
    progress(0.2)
    assert len(log.getvalue().splitlines()) == 2
    for k in range(1, 20):  # reports and beats every 0.05 interval, up to 0.95 of it
        clock.now += 0.05 * LOG_INTERVAL
        progress(0.2 + 0.01 * k) if k % 2 else progress.beat()
    assert len(log.getvalue().splitlines()) == 2
    clock.now += 0.05 * LOG_INTERVAL
    progress.beat()
    assert len(log.getvalue().splitlines()) == 3


def test_a_terminal_gets_a_bar_and_no_log_line():
    tty, clock = Terminal(), Clock()
    progress = Progress("fig3", 1.0, stream=tty, clock=clock)
    for k in range(5):
        clock.now += LOG_INTERVAL
        progress(k / 4)
    text = tty.getvalue()
    assert text.count("\r") == 5 and "100%" in text and text.endswith("\n")
    assert "simulated" not in text


def test_counted_work_says_what_it_counts_and_what_failed():
    log, clock = io.StringIO(), Clock()
    progress = Progress("gains", 40, unit="runs", stream=log, clock=clock)
    clock.now += LOG_INTERVAL
    progress(12, failed=2)
    assert log.getvalue() == "gains: 12/40 runs (2 failed), 10 s\n"


def test_nsdrake_run_in_a_pipe_prints_no_bar(tmp_path, capsys, monkeypatch):
    """The command itself, stderr not a terminal: no carriage return, and a progress line
    only as a whole line of the log's format (a run far shorter than LOG_INTERVAL prints
    none, unless it is the first after an install and compiles the kernels first)."""
    monkeypatch.setattr(sys.stderr, "isatty", lambda: False, raising=False)
    assert main(["run", "fig3", "--duration", "0.1", "--no-replay", "--out", str(tmp_path / "r")]) in (0, 1)
    err = capsys.readouterr().err
    assert "\r" not in err
    line = r"fig3: +\d+%, [\d.e+-]+ s simulated in \d+ s \([\d.e+-]+x real time\)"
    line += r"(, after \d+ s compiling nsdrake's kernels)?"
    assert all(re.fullmatch(line, x) for x in err.splitlines() if "simulated in" in x), err


def test_the_heartbeat_repeats_the_line_while_nothing_reports():
    """A compare variant or a sweep run reports only when it ends, which can take minutes:
    the heartbeat prints the line for the last report when it is due, once per interval.
    Catches silence between reports, a heartbeat line before the interval, and one after
    the work is done."""
    log, clock = io.StringIO(), Clock()
    progress = Progress("realism", 9, unit="variants", stream=log, clock=clock)
    progress(3)
    clock.now += LOG_INTERVAL - 1.0
    progress.beat()
    assert log.getvalue() == ""
    clock.now += 1.0
    progress.beat()
    progress.beat()
    clock.now += LOG_INTERVAL
    progress.beat()
    assert log.getvalue().splitlines() == ["realism: 3/9 variants, 10 s", "realism: 3/9 variants, 20 s"]
    progress(9)
    clock.now += LOG_INTERVAL
    progress.beat()
    assert log.getvalue().count("\n") == 2


def test_the_heartbeat_thread_prints_without_reports():
    """``with progress:`` runs the heartbeat in a thread. (Waits for its line with a
    deadline far above the interval; no duration is asserted.)"""
    printed = threading.Event()

    class Log(io.StringIO):
        def write(self, text):
            printed.set()
            return super().write(text)

    log = Log()
    with Progress("lyapunov", 3, unit="variants", stream=log, interval=0.01) as progress:
        progress(1)
        assert printed.wait(timeout=30.0)
    assert log.getvalue().startswith("lyapunov: 1/3 variants, ")
    assert progress._thread is None  # stopped with the work
