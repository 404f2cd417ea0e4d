"""Progress of long work: a bar on a terminal, a short line now and then in a log.

On a terminal, :class:`Progress` redraws one bar in place (``\\r``). Anywhere else (a
pipe, a CI log, a batch job's output file) a bar would be an unreadable run of carriage
returns, and nothing at all looks like a hang: there it prints one short line at a low
rate, every ``interval`` seconds of wall time (:data:`LOG_INTERVAL`), so a log shows the
work is alive and how fast it goes:

    nsdrake: panda_wipe: 21.3 of 56 s simulated (38%), 0.42x real time, 51 s

A heartbeat thread prints the line while nothing reports (a compare variant or a sweep
run can take minutes); the same line is printed at most once per interval. The clock is
a parameter, so tests drive it by hand (:meth:`Progress.beat`).
"""

from __future__ import annotations

import os
import sys
import threading
import time

LOG_INTERVAL = 10.0  # [s] of wall time between two progress lines in a log
INTERVAL_VARIABLE = "NSDRAKE_PROGRESS_INTERVAL"  # overrides LOG_INTERVAL (e.g. 60 in a quiet log)


def log_interval() -> float:
    """:data:`LOG_INTERVAL`, or the seconds in the environment variable
    :data:`INTERVAL_VARIABLE` (a positive number; anything else keeps the default)."""
    try:
        value = float(os.environ.get(INTERVAL_VARIABLE, ""))
    except ValueError:
        return LOG_INTERVAL
    return value if value > 0 else LOG_INTERVAL


class Progress:
    """Progress of one command's work: ``update(done)`` with ``done`` out of ``total``.

    Args:
        label: what is running (a scenario, a family, a sweep), first on every line.
        total: the amount of work, in ``unit`` (1.0: a fraction).
        unit: the words after the counts in a log line ("variants done", "runs done");
            None for a simulation, whose line gives the simulated time and the real-time
            factor instead (``simulated`` seconds in all).
        simulated: the simulated seconds ``total`` stands for (a run and its comparison
            run: twice the scenario's duration).
        stream: where to write (stderr).
        interval: seconds of wall time between two log lines (:func:`log_interval`).
        clock: wall-clock seconds (``time.monotonic``); tests pass their own.
        bar_label, bar_counts: the bar's label (``label``) and whether it ends in
            ``done/total`` (else the percentage and the elapsed seconds).
    """

    def __init__(
        self, label: str, *, total: float = 1.0, unit: str | None = None, simulated: float | None = None,
        stream=None, interval: float | None = None, clock=time.monotonic, width: int = 30,
        bar_label: str | None = None, bar_counts: bool = False,
    ):  # fmt: skip
        self.label, self.total, self.unit, self.simulated = label, total, unit, simulated
        self.bar_label = label if bar_label is None else bar_label
        self.bar_counts = bar_counts
        self.stream = stream if stream is not None else sys.stderr
        self.terminal = self.stream.isatty()
        self.interval = log_interval() if interval is None else interval
        self.clock, self.width = clock, width
        self.start = self.last_line = clock()
        self.done, self.failed = 0.0, 0
        self.partial = False  # a bar is drawn and its line not ended
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = None

    # ---- reports

    def update(self, done: float, failed: int = 0) -> None:
        """``done`` of ``total`` finished (``failed`` of them failed)."""
        with self._lock:
            self.done, self.failed = done, failed
            if self.terminal:
                self._draw_bar()
            else:
                self._line_if_due()

    def __call__(self, fraction: float) -> None:
        """The fraction done (a run's and compare's callback)."""
        self.update(round(fraction * self.total, 9))

    def beat(self) -> None:
        """The heartbeat: the log line, if one is due (nothing on a terminal)."""
        if not self.terminal:
            with self._lock:
                self._line_if_due()

    # ---- what it writes

    def line(self) -> str:
        """The log line for the work done so far."""
        elapsed = self.clock() - self.start
        share = self.done / self.total if self.total else 1.0
        if self.unit is None and self.simulated:
            simulated = share * self.simulated
            rate = simulated / elapsed if elapsed > 0 else 0.0
            return (
                f"nsdrake: {self.label}: {simulated:.3g} of {self.simulated:g} s simulated "
                f"({share:.0%}), {rate:.2g}x real time, {elapsed:.0f} s"
            )
        failed = f" ({self.failed} failed)" if self.failed else ""
        unit = f" {self.unit}" if self.unit else ""
        return f"nsdrake: {self.label}: {self.done:g} of {self.total:g}{unit}{failed}, {elapsed:.0f} s"

    def _line_if_due(self) -> None:
        now = self.clock()
        if now - self.last_line >= self.interval and self.done < self.total:
            self.last_line = now
            self.stream.write(self.line() + "\n")
            self.stream.flush()

    def _draw_bar(self) -> None:
        k = int(round(self.width * min(self.done / self.total, 1.0))) if self.total else self.width
        if self.bar_counts:
            counts = f"{self.done:g}/{self.total:g}" + (f" ({self.failed} failed)" if self.failed else "")
        else:
            counts = f"{self.done / self.total:4.0%} {self.clock() - self.start:5.1f} s"
        label = f"{self.bar_label} " if self.bar_label else ""
        self.stream.write(f"\r{label}[{'#' * k}{'.' * (self.width - k)}] {counts}")
        self.partial = self.done < self.total
        if not self.partial:
            self.stream.write("\n")
        self.stream.flush()

    # ---- the heartbeat

    def __enter__(self) -> Progress:
        """Starts the heartbeat (in a log only)."""
        if not self.terminal and self._thread is None:
            self._thread = threading.Thread(target=self._heartbeat, name="nsdrake-progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _heartbeat(self) -> None:
        while not self._stop.wait(min(max(self.interval, 0.1), 1.0)):
            self.beat()

    def close(self) -> None:
        """Stops the heartbeat and ends a bar left half-drawn (the work stopped), so that a
        message starts a line."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        with self._lock:
            if self.partial:
                self.stream.write("\n")
                self.stream.flush()
                self.partial = False
