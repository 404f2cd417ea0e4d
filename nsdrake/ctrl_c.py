"""Ctrl-C answers within a second, even while numba compiles nsdrake's kernels.

A KeyboardInterrupt raised into numba's compiler does not stop it: it lands in a ctypes
callback or a finalizer, where Python prints "Exception ignored …" and drops it; the
compile goes on (tens of seconds) and then fails on its own broken state ("no compiled
object yet for <Library …>"), a traceback and exit 1. And a Python signal handler runs
only between bytecodes, so not while LLVM optimizes a large function in C.

So, for the duration of a command (:func:`answering`):

- a SIGINT that arrives while a kernel compiles and before the command computed anything
  (:meth:`CtrlC.computed`: a run's first hundredth) ends the process at once: the claims
  of output folders are undone (:func:`nsdrake.experiment.output.release_unused`: only
  an empty claimed folder is removed, nothing a user wrote), one line on stderr, exit 130.
  Nothing is lost (nothing was simulated) and numba's cache stays whole (it writes each
  file whole, by rename). The signal is seen by a thread woken through
  :func:`signal.set_wakeup_fd`, which runs while the main thread is in LLVM's C code
  (llvmlite's calls release the GIL), and by the Python handler, whichever comes first;
- a SIGINT while a kernel compiles after the command computed something is kept for the
  next :meth:`CtrlC.report` (the run's next hundredth), where it raises KeyboardInterrupt
  and the run stops keeping its traces, as at any other time (a command that does not
  report gets the KeyboardInterrupt at once, as before);
- any other SIGINT raises KeyboardInterrupt, as Python's default handler does.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from pathlib import Path

from nsdrake.control.kernels import compiling
from nsdrake.experiment.output import record_written, release_unused

INTERRUPTED = 130  # exit status after Ctrl-C (128 + SIGINT), as a shell reports it
LINE = "nsdrake: interrupted while compiling nsdrake's kernels, before anything was simulated\n"


class CtrlC:
    """The state :func:`answering` keeps for the command under way."""

    def __init__(self):
        self.claims: list[tuple[Path, list[Path]]] = []  # (folder, the folders made for it)
        self.computed = False  # the command holds results that an exit at once would lose
        self.reporting = False  # the command calls report() as it computes
        self.pending = False  # a Ctrl-C kept for the next report
        self._stopping = threading.Lock()

    def report(self) -> None:
        """Called by the command as it computes (each hundredth of a run): from now on it
        has something to keep; raises KeyboardInterrupt for a Ctrl-C kept meanwhile."""
        self.computed = self.reporting = True
        if self.pending:
            self.pending = False
            raise KeyboardInterrupt

    def handler(self, signum, frame) -> None:
        if compiling():
            if not self.computed:
                self.stop_now()
            if self.reporting or not self.computed:  # (not computed: the watcher is exiting)
                self.pending = True
                return
        raise KeyboardInterrupt

    def stop_now(self) -> None:
        """Undoes the claims, prints the one line, exits 130; from any thread, once."""
        if not self._stopping.acquire(blocking=False):
            return  # the other path is already at it
        for folder, created in self.claims:
            record_written(folder)  # releases the claim (a folder holding files keeps them, listed)
            release_unused(folder, created)
        with contextlib.suppress(Exception):  # e.g. a reentrant flush from the handler
            sys.stdout.flush()
        with contextlib.suppress(OSError):
            os.write(2, LINE.encode())
        os._exit(INTERRUPTED)


_current: CtrlC | None = None


def current() -> CtrlC | None:
    """The state of the command under way in this process, or None."""
    return _current


@contextlib.contextmanager
def answering():
    """Installs the SIGINT handling of the module docstring for the block (restored after).
    Outside the main thread, where handlers cannot be set, yields a state nothing uses."""
    global _current
    state = CtrlC()
    if threading.current_thread() is not threading.main_thread():
        yield state
        return
    read, write = os.pipe()
    os.set_blocking(write, False)
    watcher = threading.Thread(target=_watch, args=(read, state), name="nsdrake-ctrl-c", daemon=True)
    previous_handler = signal.getsignal(signal.SIGINT)
    previous_fd = signal.set_wakeup_fd(write, warn_on_full_buffer=False)
    _current = state
    watcher.start()
    try:
        # the handler last, inside the try: a SIGINT the moment it is set raises here, and
        # everything above is undone (the caller sees a KeyboardInterrupt, as from its block)
        signal.signal(signal.SIGINT, state.handler)
        yield state
    finally:
        _current = None
        signal.set_wakeup_fd(previous_fd)
        signal.signal(signal.SIGINT, previous_handler)
        os.write(write, b"\0")  # ends the watcher (no signal has number 0)
        watcher.join()
        os.close(write)


def _watch(read: int, state: CtrlC) -> None:
    try:
        while True:
            data = os.read(read, 64)
            if not data or 0 in data:
                return
            if signal.SIGINT in data and compiling() and not state.computed:
                state.stop_now()
    finally:
        os.close(read)
