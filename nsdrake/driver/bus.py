"""Opening an LCM bus so that a URL it cannot open is an error, not a silent bus."""

from __future__ import annotations

import os
import sys
import tempfile

from pydrake.lcm import DrakeLcm


class BusError(ValueError):
    """An LCM URL that cannot be opened; the message is one line."""


def open_bus(url: str) -> DrakeLcm:
    """``DrakeLcm(url)``, or BusError with LCM's own reason. Drake's DrakeLcm does not raise
    when LCM cannot open the URL (an unknown provider, a bad multicast address, a log file
    that cannot be opened): LCM prints "Error: …" on the process's standard error and the
    bus then silently sends and receives nothing. That output is captured (at the file
    descriptor, where the C library writes it) and turned into the error."""
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as captured:
        os.dup2(captured.fileno(), 2)
        try:
            lcm = DrakeLcm(url)
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        said = " ".join(captured.read().decode(errors="replace").split())
    if said.startswith("Error") or "error" in said.lower():
        raise BusError(f"cannot open the LCM bus {url}: {said.removeprefix('Error:').strip()}")
    if said:
        sys.stderr.write(said + "\n")
    return lcm
