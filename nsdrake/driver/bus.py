"""The LCM bus of a drive: one small interface over the ``lcm`` package (a real URL)
and Drake's ``DrakeLcm`` (both sides in one process over ``memq://``).

Why the ``lcm`` package for a URL: a ``DrakeLcm`` subscription holds one pending
message (queue capacity 1 in Drake's ``drake_lcm.cc``, and pydrake gives no handle to
raise it); over UDP the first queued message is kept and newer ones are dropped, so a
controller that was busy for a period answers the *oldest* status. The ``lcm``
package's subscription takes a queue capacity (:data:`QUEUE`): every status that
arrives during a tick is delivered, and the loop acts on the newest.
"""

from __future__ import annotations

import os
import sys
import tempfile

from pydrake.lcm import DrakeLcm

QUEUE = 1000  # messages a subscription holds between two reads (a second of a 1 kHz stream)


class BusError(ValueError):
    """An LCM URL that cannot be opened; the message is one line."""


def _captured_stderr(make):
    """``make()`` with the process's standard error (file descriptor 2, where LCM's C
    library writes "Error: …") captured; returns (result or the exception, what was said)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            result = make()
        except Exception as e:  # noqa: BLE001 (reported with what LCM said)
            result = e
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        said = " ".join(captured.read().decode(errors="replace").split())
    return result, said


def _checked(url: str, make):
    result, said = _captured_stderr(make)
    if isinstance(result, Exception) or said.startswith("Error") or "error" in said.lower():
        reason = said.removeprefix("Error:").strip() or str(result)
        raise BusError(f"cannot open the LCM bus {url}: {reason}")
    if said:
        sys.stderr.write(said + "\n")
    return result


def open_bus(url: str) -> DrakeLcm:
    """``DrakeLcm(url)``, or BusError with LCM's own reason. Drake's DrakeLcm does not raise
    when LCM cannot open the URL (an unknown provider, a bad multicast address, a log file
    that cannot be opened): LCM prints "Error: …" on the process's standard error and the
    bus then silently sends and receives nothing. That output is turned into the error; and
    the URL is first opened with the ``lcm`` package, which raises where LCM fails (an
    invalid URL, a tcpq:// server that refuses the connection), since LCM's line for those
    does not always begin with "Error"."""
    import lcm

    _checked(url, lambda: lcm.LCM(url))
    return _checked(url, lambda: DrakeLcm(url))


class Bus:
    """What the controller loop needs of a bus: ``subscribe(channel, handler(bytes))``,
    ``handle(timeout_ms)`` (delivers every queued message, waiting up to ``timeout_ms``
    for the first; returns how many) and ``publish(channel, data)``."""

    def subscribe(self, channel: str, handler) -> None:
        raise NotImplementedError

    def handle(self, timeout_ms: int) -> int:
        raise NotImplementedError

    def publish(self, channel: str, data) -> None:
        raise NotImplementedError


class LcmBus(Bus):
    """A bus of the ``lcm`` package at ``url`` (module docstring): each subscription's
    queue holds :data:`QUEUE` messages."""

    def __init__(self, url: str):
        import lcm

        self.url = url
        self.lcm = _checked(url, lambda: lcm.LCM(url))
        self._subscriptions = []

    def subscribe(self, channel: str, handler) -> None:
        subscription = self.lcm.subscribe(channel, lambda _channel, data: handler(data))
        subscription.set_queue_capacity(QUEUE)
        self._subscriptions.append(subscription)

    def handle(self, timeout_ms: int) -> int:
        count = 0
        while self.lcm.handle_timeout(timeout_ms if count == 0 else 0) > 0:
            count += 1
        return count

    def publish(self, channel: str, data) -> None:
        self.lcm.publish(channel, bytes(data))


class DrakeBus(Bus):
    """A ``DrakeLcm`` (``memq://`` with the simulated driver in the same process: memq
    delivers every queued message)."""

    def __init__(self, lcm: DrakeLcm):
        self.lcm = lcm
        self._subscriptions = []

    def subscribe(self, channel: str, handler) -> None:
        self._subscriptions.append(self.lcm.Subscribe(channel, handler))

    def handle(self, timeout_ms: int) -> int:
        count = self.lcm.HandleSubscriptions(timeout_ms)
        while count and (more := self.lcm.HandleSubscriptions(0)):
            count += more
        return count

    def publish(self, channel: str, data) -> None:
        self.lcm.Publish(channel, bytes(data))
