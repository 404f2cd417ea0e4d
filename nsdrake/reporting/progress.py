"""How long work shows that it is alive: the progress of `nsdrake run`, `compare` and `sweep`.

On a terminal, a bar redrawn in place (``\\r``). Anywhere else (a pipe, a CI log) a bar
would be a wall of carriage returns, and silence looks hung: panda_wipe's run takes
minutes. There, one short line every :data:`LOG_INTERVAL` seconds of wall time says how
far the work is (and, for a simulation, how much time it has simulated and at what
real-time factor), and nothing more. Work that reports only when a piece of it ends (a
compare variant, a sweep run: minutes each for panda_wipe) keeps the lines coming from a
heartbeat thread while it runs (``with progress:``).

A first run after an install compiles nsdrake's kernels (tens of seconds) inside its
simulation's first steps: the log line leaves that time out of the simulation's and says
it apart (``…, 0.3 s simulated in 2 s (0.15x real time), after 45 s compiling nsdrake's
kernels``), so that the real-time factor is the simulation's.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable

LOG_INTERVAL = 10.0  # [s of wall time] between two progress lines when not on a terminal


def kernels_compile_seconds() -> float:
    """The wall time this process has spent compiling nsdrake's kernels [s]; 0 if it has
    not loaded them (:func:`nsdrake.control.kernels.compile_seconds`)."""
    kernels = sys.modules.get("nsdrake.control.kernels")
    return kernels.compile_seconds() if kernels is not None else 0.0


class Progress:
    """``progress(done, failed=0)``: ``done`` of ``total`` (runs, variants, or a fraction
    of 1). ``simulated``: the simulated seconds that ``total`` stands for (a run's
    simulations), for the log line's simulated time and real-time factor. ``clock`` and
    ``interval`` are the wall clock and the log lines' spacing, ``compiling`` the wall
    time spent compiling kernels so far (the module docstring; tests give their own)."""

    def __init__(
        self,
        label: str,
        total: float,
        *,
        unit: str = "",
        simulated: float | None = None,
        stream=None,
        width: int = 30,
        clock: Callable[[], float] = time.monotonic,
        interval: float = LOG_INTERVAL,
        compiling: Callable[[], float] = kernels_compile_seconds,
    ):
        self.stream = stream if stream is not None else sys.stderr
        self.on_terminal = bool(getattr(self.stream, "isatty", lambda: False)())
        self.label, self.total, self.unit, self.simulated = label, total, unit, simulated
        self.width, self.clock, self.interval = width, clock, interval
        self.start = clock()
        self.compiling, self.compiled_before = compiling, compiling()
        self.next_line = self.start + interval
        self.partial = False  # a bar is drawn and its line not ended
        self.done, self.failed = 0.0, 0  # the last report
        self._lock, self._stop, self._thread = threading.Lock(), threading.Event(), None

    def __call__(self, done: float, failed: int = 0) -> None:
        with self._lock:
            self.done, self.failed = done, failed
            if self.on_terminal:
                self._draw(done, failed)
            else:
                self._line_if_due()

    def beat(self) -> None:
        """The heartbeat: the log line for the last report, if one is due (the work goes on
        though nothing reported); nothing on a terminal."""
        if not self.on_terminal:
            with self._lock:
                self._line_if_due()

    def _line_if_due(self) -> None:
        now = self.clock()
        if now >= self.next_line and self.done < self.total:
            compiled = self.compiling() - self.compiled_before
            self.stream.write(self.log_line(self.done, self.failed, now - self.start, compiled) + "\n")
            self.stream.flush()
            self.next_line = now + self.interval

    def __enter__(self) -> Progress:
        """Starts the heartbeat thread (not on a terminal), which calls :meth:`beat` about
        once a second until the ``with`` block ends."""
        if not self.on_terminal and self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._heartbeat, name="nsdrake-progress", daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None

    def _heartbeat(self) -> None:
        while not self._stop.wait(min(max(self.interval, 0.1), 1.0)):
            self.beat()

    def end_line(self) -> None:
        """Ends a bar left half-drawn (the work stopped), so that a message starts a line."""
        if self.partial:
            self.stream.write("\n")
            self.partial = False

    def count(self, done: float) -> str:
        if self.unit:
            return f"{done:g}/{self.total:g} {self.unit}"
        return f"{done / self.total:4.0%}"

    def log_line(self, done: float, failed: int, elapsed: float, compiled: float = 0.0) -> str:
        """``fig3: 43%, 4.3 s simulated in 12 s (0.36x real time)``; ``realism: 3/9 variants, 40 s``.
        ``compiled``: the part of ``elapsed`` [s] spent compiling kernels, not simulating."""
        text = f"{self.label}: {self.count(done).strip()}"
        if failed:
            text += f" ({failed} failed)"
        if self.simulated is not None:
            simulated = self.simulated * done / self.total
            running = max(elapsed - compiled, 0.0)
            if not simulated and compiled >= 0.5:
                return f"{text}, compiling nsdrake's kernels ({compiled:.0f} s)"
            rate = simulated / running if running > 0 else float("inf")
            line = f"{text}, {simulated:.3g} s simulated in {running:.0f} s ({rate:.2g}x real time)"
            return line + (f", after {compiled:.0f} s compiling nsdrake's kernels" if compiled >= 0.5 else "")
        return f"{text}, {elapsed:.0f} s"

    def _draw(self, done: float, failed: int) -> None:
        k = int(round(self.width * done / self.total)) if self.total else self.width
        tail = f" ({failed} failed)" if failed else ""
        elapsed = self.clock() - self.start
        head = f"{self.label} " if not self.unit else ""
        clock = f" {elapsed:5.1f} s" if not self.unit else ""
        count = self.count(done) if not self.unit else f"{done:g}/{self.total:g}"
        self.stream.write(f"\r{head}[{'#' * k}{'.' * (self.width - k)}] {count}{tail}{clock}")
        self.partial = done < self.total
        if not self.partial:
            self.stream.write("\n")
        self.stream.flush()
