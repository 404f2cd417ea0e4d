"""Ctrl-C in a real-time loop: a flag the loop reads once per period, not an exception.

Python raises KeyboardInterrupt wherever the main thread happens to be when SIGINT
arrives: inside a Drake call (AdvanceTo, a subscription's handler called from C++),
where it can be swallowed or leave the diagram half-updated, or not at all while a C++
call blocks. A drive must instead stop commanding at the next status and keep what it
computed: :func:`ctrl_c_requests` replaces SIGINT's handler with one that only sets
:attr:`StopRequest.requested`, which the loop reads at each status and in each wait.
"""

from __future__ import annotations

import contextlib
import signal
import threading


class StopRequest:
    """Whether Ctrl-C (SIGINT) arrived since the block began."""

    def __init__(self):
        self.requested = False

    def __call__(self, signum, frame) -> None:  # the signal handler
        self.requested = True


@contextlib.contextmanager
def ctrl_c_requests():
    """A :class:`StopRequest` set by SIGINT for the block (the handler restored after).
    Outside the main thread (where signal handlers cannot be set) the request is never
    set and SIGINT keeps its handler."""
    request = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield request
        return
    previous = signal.signal(signal.SIGINT, request)
    try:
        yield request
    finally:
        signal.signal(signal.SIGINT, previous)
