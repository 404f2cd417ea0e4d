"""Ctrl-C during `nsdrake drive … --simulated-driver` (issue 24, item 1): the drive stops
commanding at the next status, keeps what it computed (traces, timing, metrics marked
interrupted) and exits 130 with one line. Run as a user's command, in its own process."""

from __future__ import annotations

import json
import os
import pty
import select
import signal
import subprocess
import sys
import time

from conftest import without_notices
from test_interrupt import wait_for_progress

from nsdrake.experiment.traces import Traces


def test_ctrl_c_mid_drive_keeps_the_traces_marked_interrupted(tmp_path):
    """SIGINT to the drive's process group once its progress bar shows 5% of a 20 s
    real-time drive. Catches the
    folder removed on Ctrl-C (the claim undone as if nothing had been written), SIGINT
    swallowed inside Drake's calls (the drive runs on to its end: exit 1 or 0 after
    20 s of driving, 20 000 rows), a traceback, a status of "ok" or "failed", and traces
    that miss commands that were sent (rows ≠ commands)."""
    out = tmp_path / "drive"
    terminal, stderr = pty.openpty()  # a terminal for stderr: the progress bar says when it drives
    process = subprocess.Popen(
        [sys.executable, "-m", "nsdrake", "drive", "panda_wipe", "--simulated-driver", "--duration", "20"]
        + ["--out", str(out)],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=stderr,
        text=True,
        start_new_session=True,  # its own process group, as a shell's job
    )
    os.close(stderr)
    shown = b""
    try:
        wait_for_progress(terminal, process, 5)
        os.killpg(process.pid, signal.SIGINT)
        stdout, _ = process.communicate(timeout=60)
        while select.select([terminal], [], [], 0.2)[0]:
            try:
                shown += os.read(terminal, 4096)
            except OSError:  # the other end closed
                break
    finally:
        process.kill()
        os.close(terminal)
    # the bar's last drawing ends with a carriage return and a newline; then the message
    err = without_notices(shown.decode(errors="replace").replace("\r\n", "\n").split("\r")[-1])
    err = err.lstrip("\n")
    assert process.returncode == 130, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith("nsdrake: drive at t = ")
    assert "interrupted (Ctrl-C); stopped commanding after" in err
    assert "marked interrupted" in err
    commands = int(err.split("stopped commanding after ")[1].split(" ")[0])
    t_stop = float(err.split("at t = ")[1].split(" s")[0])
    assert 0.2 < t_stop < 15.0  # stopped mid-drive, well before its 20 s
    timing = json.loads((out / "timing.json").read_text())
    assert timing["status"] == "interrupted" and timing["commands"] == commands
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["status"] == "interrupted"
    traces = Traces.read_csv(out / "traces.csv")
    assert len(traces) == commands  # one row per command sent, none lost, none invented
    assert abs(traces["t"][-1] - t_stop) <= 1.5e-3
    assert "nsdrake: timing:" in stdout


def test_ctrl_c_while_waiting_for_the_first_status_on_memq_is_an_interrupt(tmp_path):
    """`nsdrake drive --lcm memq://` (the `lcm` package's bus, nothing else on it): SIGINT
    half a second after it says it drives, while it waits for the first status, ends with
    one line, exit 130, the folder kept with timing.json marked interrupted (catches the
    interrupted wait reported as "the LCM bus failed", exit 1: issue 34, item 1; over UDP
    at random moments: test_udp.py)."""
    out = tmp_path / "drive"
    process = subprocess.Popen(
        [sys.executable, "-m", "nsdrake", "drive", "panda_wipe", "--lcm", "memq://", "--out", str(out)],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        line = process.stdout.readline()
        assert line.startswith("nsdrake: driving panda_wipe"), line
        time.sleep(0.5)
        process.send_signal(signal.SIGINT)
        _, err = process.communicate(timeout=120)
    finally:
        process.kill()
    err = without_notices(err)
    assert process.returncode == 130, err
    assert err == (
        "nsdrake: drive before the first command: interrupted (Ctrl-C); stopped commanding after 0 "
        f"command(s); what was computed is in {out}/, marked interrupted\n"
    )
    assert json.loads((out / "timing.json").read_text())["status"] == "interrupted"
