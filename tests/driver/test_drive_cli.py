"""nsdrake drive and nsdrake sim-driver on the command line (memq:// only)."""

from __future__ import annotations

import dataclasses
import itertools
import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import without_notices
from drake import lcmt_panda_command, lcmt_panda_status
from pydrake.lcm import DrakeLcm

from nsdrake.cli import main
from nsdrake.driver.serve import serve_simulated_driver
from nsdrake.experiment.scenario import load_scenario
from nsdrake.experiment.traces import Traces

ROOT = Path(__file__).resolve().parents[2]


def exit_code(argv) -> int:
    """main's exit status, whether it returns it or argparse exits."""
    try:
        return main(argv)
    except SystemExit as e:
        return e.code


@pytest.mark.slow  # waits out the 5 s default; the fast subset checks the same line after a
# 0.3 s first_status_timeout on a fake bus (test_wire_faults.py::test_no_first_status_ends_without_sending)
def test_nobody_publishing_ends_with_one_line(tmp_path):
    """The issue's own command: `nsdrake drive panda_wipe --lcm memq://` where nobody
    publishes ends after the default wait (5 s) with one line and a non-zero exit, having
    sent nothing. Catches a drive that waits for ever (or exits 0) when no driver answers,
    a process that does not end once it gave up, and a traceback instead of one line."""
    start = time.monotonic()
    result = subprocess.run(
        [sys.executable, "-m", "nsdrake", "drive", "panda_wipe", "--lcm", "memq://"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 1
    assert without_notices(result.stderr) == (
        "nsdrake: error: panda_wipe: drive: before the first command: no lcmt_panda_status on PANDA_STATUS "
        "within 5 s; nothing was sent; stopped commanding after 0 command(s)\n"
    )
    assert time.monotonic() - start >= 5.0
    timing = json.loads((tmp_path / "runs" / "drive-panda_wipe" / "timing.json").read_text())
    assert timing["ticks"] == 0 and timing["commands"] == 0


def test_simulated_driver_writes_the_run_folder(tmp_path, capsys):
    out = tmp_path / "drive"
    code = main(
        [
            "drive",
            "panda_wipe",
            "--simulated-driver",
            "--duration",
            "0.05",
            "--realtime-rate",
            "0",
            "--out",
            str(out),
        ]
    )
    assert code == 1  # 0.05 s ends before contact: the contact figures fail honestly
    for name in ("traces.csv", "metrics.json", "scenario.yaml", "timing.json", "report.html"):
        assert (out / name).is_file(), name
    traces = Traces.read_csv(out / "traces.csv")
    assert len(traces) == 51 and "cmd7" in traces and "f_n_measured" in traces
    timing = json.loads((out / "timing.json").read_text())
    assert timing["ticks"] == timing["commands"] == 51
    assert timing["p50_us"] <= timing["p99_us"] <= timing["p999_us"] <= timing["max_us"]
    assert timing["gc_disabled"] is True
    printed = capsys.readouterr().out
    assert "nsdrake: timing: 51 ticks, status in to command out p50" in printed
    assert timing["statuses_skipped"] == 0 and timing["periods"] == 50  # lockstep: every status answered


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["drive", "panda_wipe"], "one of the arguments --lcm --simulated-driver is required"),
        (["drive", "panda_wipe", "--lcm", "memq://", "--simulated-driver"], "not allowed with argument"),
        (
            ["drive", "fig3", "--simulated-driver"],
            "the Panda driver speaks 7 joints; the scenario's arm has 4",
        ),
        (
            ["drive", "panda_wipe", "--simulated-driver", "--realtime-rate", "-1"],
            "--realtime-rate must be >= 0",
        ),
        (
            ["drive", "panda_wipe", "--lcm", "bogus://x"],
            'cannot open the LCM bus bogus://x: LCM provider "bogus"',
        ),
        (["sim-driver", "panda_wipe"], "the following arguments are required: --lcm"),
        (["drive", "panda_wipe", "--lcm", ""], "--lcm: the URL is empty"),
        (
            ["drive", "panda_wipe", "--lcm", "memq://", "--realtime-rate", "0"],
            "paces the simulated driver only",
        ),
        (
            ["sim-driver", "fig3", "--lcm", "udpm://239.255.76.67:7667?ttl=0"],
            "the Panda driver speaks 7 joints",
        ),
        (
            ["sim-driver", "panda_wipe", "--lcm", "memq://"],
            "another process cannot reach the simulated driver",
        ),
        (["sim-driver", "panda_wipe", "--lcm", "bogus://x", "--expire-sec", "0"], "--expire-sec must be"),
        # issue 43: bounded as the scenario's driver.expire_sec is (the same number on both sides)
        (
            ["sim-driver", "panda_wipe", "--lcm", "bogus://x", "--expire-sec", "1e9"],
            "--expire-sec: must be at most 0.1 s (a stale torque held longer",
        ),
        (
            ["sim-driver", "panda_wipe", "--lcm", "bogus://x", "--expire-sec", "0.0015"],
            "--expire-sec: must be at least two control periods (0.002 s",
        ),
        (
            ["sim-driver", "panda_wipe", "--lcm", "bogus://x", "--low-pass-freq", "1e9"],
            "--low-pass-freq: must be a cutoff in (0, 1000] Hz",
        ),
        (
            ["drive", "panda_wipe", "--simulated-driver", "--realtime-rate", "1e-9"],
            "--realtime-rate: 1e-09 would wait 1e+06 s of wall clock for each 1 ms control period; "
            "give at least 0.001",
        ),
        (
            ["drive", "panda_wipe", "--simulated-driver", "--realtime-rate", "0.00099"],
            "--realtime-rate: 0.00099 would wait 1.01 s",
        ),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, words):
    assert exit_code([*argv, "--out", str(tmp_path / "x")] if argv[0] == "drive" else argv) == 2
    err = capsys.readouterr().err
    assert err.startswith("nsdrake: error: ") and err.count("\n") == 1 and words in err, err
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize(
    ("setting", "words"),
    [
        ("first_status_timeout: 1e9", "driver.first_status_timeout: must be at most 600 s"),
        ("status_timeout_periods: 1.0e12", "driver.status_timeout_periods: removed: the silence bound is now "
         "driver.expire_sec"),
        ("expire_sec: 1.0e12", "driver.expire_sec: must be at most 0.1 s"),
        ("expire_sec: 0.0015", "driver.expire_sec: must be at least two control periods (0.002 s"),
        ("expire_sec: 0", "driver.expire_sec: must be a finite number > 0"),
        ("start_tolerance: 1.0e9", "driver.start_tolerance: must be at most 0.00435 rad"),
        ("start_tolerance: 0.0044", "driver.start_tolerance: must be at most 0.00435 rad"),
        ("max_joint_step: 0.01", "driver.max_joint_step: must be at most 0.002484 rad"),
        ("max_joint_step: -1", "driver.max_joint_step: must be a finite number >= 0"),
        ("force_torque_channel: PANDA_STATUS", "force_torque_channel: must differ from status_channel"),
        ("command_channel: PANDA_FORCE_TORQUE", "force_torque_channel: must differ from command_channel"),
        ("status_channel: PANDA_COMMAND", "driver.command_channel: must differ from status_channel"),
    ],
)  # fmt: skip
def test_driver_settings_out_of_range_are_refused(tmp_path, capsys, setting, words):
    """Issue 34, item 2 (its fourth round's cases among them): a first wait of 1e9 s (a
    drive that hangs for ever), the removed silence setting, an expiry beyond what a held
    torque allows or under two periods, a start tolerance beyond two periods of the slowest
    joint (1e9: the full torque at the first command on an arm 1 rad away), a joint step
    beyond the slowest joint's, and channels shared: one line, exit 2, nothing run (the
    out folder not made)."""
    config = tmp_path / "c.yaml"
    config.write_text(f"driver: {{{setting}}}\n")
    out = tmp_path / "out"
    argv = ["drive", "panda_wipe", "--simulated-driver", "--config", str(config), "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and words in err, err
    assert not out.exists()


def test_driver_settings_at_their_bounds_are_taken():
    """The bounds themselves are taken (catches a refusal one ulp early): the start
    tolerance of two periods of the slowest joint, the joint step of one, the expiry of
    two periods and of 0.1 s."""
    from nsdrake.driver.controller_side import check_drive_scenario
    from nsdrake.driver.panda import VELOCITY_LIMIT, joint_step_allowance

    for setting in (
        {"start_tolerance": 2 * float(VELOCITY_LIMIT.min()) * 1e-3},
        {"max_joint_step": float(joint_step_allowance(1e-3).min())},
        {"expire_sec": 0.002},
        {"expire_sec": 0.1},
    ):
        s = load_scenario("panda_wipe", duration=0.01)
        check_drive_scenario(dataclasses.replace(s, driver=dataclasses.replace(s.driver, **setting)))


def test_a_bad_driver_setting_is_refused(tmp_path, capsys):
    config = tmp_path / "c.yaml"
    config.write_text("driver: {force_source: wrist}\n")
    assert main(["drive", "panda_wipe", "--simulated-driver", "--config", str(config)]) == 2
    err = capsys.readouterr().err
    assert "driver.force_source: must be one of sensor, external_torque, got 'wrist'" in err


class AnsweringController:
    """Answers each status on ``lcm`` at once with a zero torque command carrying its
    utime, until ``stop_after`` statuses; ``bad`` (status index -> a function that spoils
    the command, or bytes sent instead) for a controller that misbehaves."""

    def __init__(self, lcm, stop_after: int = 10**9, bad=None):
        self.lcm, self.statuses, self.stop_after, self.bad = lcm, [], stop_after, bad or {}
        self._subscription = lcm.Subscribe("PANDA_STATUS", self._answer)

    def _answer(self, data: bytes):
        status = lcmt_panda_status.decode(data)
        self.statuses.append(status)
        if len(self.statuses) > self.stop_after:
            return
        command = lcmt_panda_command()
        command.utime, command.control_mode_expected = status.utime, lcmt_panda_status.CONTROL_MODE_TORQUE
        command.num_joint_torque, command.joint_torque = 7, [0.0] * 7
        spoil = self.bad.get(len(self.statuses))
        if isinstance(spoil, bytes):
            self.lcm.Publish("PANDA_COMMAND", spoil)
            return
        if spoil is not None:
            spoil(command)
        self.lcm.Publish("PANDA_COMMAND", command.encode())


def test_each_status_of_the_standalone_driver_carries_the_state_of_its_own_robot_utime(monkeypatch):
    """nsdrake sim-driver sends the station's status of t_k at t_k, stamped robot_utime
    t_k, from the first period on (catches a status sent a period late: sent at t_k+1
    stamped t_k+1, it made two periods from measurement to applied torque where
    drake-franka-driver takes one). The station's own status carries its diagram's time in
    utime, before the driver re-stamps it with the wall clock."""
    import nsdrake.driver.serve as serve

    inner_stamps = []
    messages = serve.SimulatedDriver.messages

    def recorded(driver):
        status, force_torque = messages(driver)
        inner_stamps.append(lcmt_panda_status.decode(status).utime)
        return status, force_torque

    monkeypatch.setattr(serve.SimulatedDriver, "messages", recorded)
    lcm = DrakeLcm("memq://")
    controller = AnsweringController(lcm)
    serve_simulated_driver(load_scenario("panda_wipe"), lcm, duration=0.02, low_pass_freq=1000.0)
    sent = [s.robot_utime - serve.ROBOT_UP_US for s in controller.statuses]
    assert sent[:3] == [0, 1000, 2000] and len(sent) >= 20
    assert sent == inner_stamps[: len(sent)]
    assert controller.statuses[0].robot_utime > 0  # 0 would say "no robot clock" to the controller


@pytest.mark.parametrize(
    ("bad", "words"),
    [
        (lambda c: setattr(c, "control_mode_expected", 1), "not a torque command of 7 joints"),
        (lambda c: setattr(c, "joint_torque", [0.0] * 6 + [float("nan")]), "joint_torque[6] is nan"),
    ],
    ids=["position mode", "NaN torque"],
)
def test_the_standalone_driver_stops_on_a_command_it_cannot_apply(bad, words):
    """A command in another mode or with a NaN torque at the fifth status: the simulated
    driver stops with one line naming it, as drake-franka-driver's torque loop throws and
    libfranka refuses a non-finite torque (catches a traceback from the plant, or the
    command applied)."""
    from nsdrake.driver.serve import SimulatedDriverStopError

    lcm = DrakeLcm("memq://")
    AnsweringController(lcm, bad={5: bad})
    with pytest.raises(SimulatedDriverStopError) as caught:
        serve_simulated_driver(load_scenario("panda_wipe"), lcm, duration=0.02, low_pass_freq=1000.0)
    assert words in str(caught.value) and "\n" not in str(caught.value)
    assert caught.value.result.commands == 5


def test_the_standalone_driver_drops_undecodable_commands_and_counts_them():
    """Bytes that are no lcmt_panda_command at the fifth status: dropped and counted in the
    driver's line, the run goes on (as LCM's typed subscription drops them; catches a
    decode error ending the driver with a traceback)."""
    lcm = DrakeLcm("memq://")
    AnsweringController(lcm, bad={5: b"not a command"})
    served = serve_simulated_driver(load_scenario("panda_wipe"), lcm, duration=0.02, low_pass_freq=1000.0)
    assert served.undecodable == 1 and served.periods == 20
    assert served.line().endswith("; 1 undecodable command messages dropped")


def test_the_standalone_simulated_driver_applies_each_command_one_period_late():
    """nsdrake sim-driver's loop on memq:// with a controller that answers every status at
    once with a zero command (the robot holds still: it adds g): 100 periods after the
    first command, each applying a fresh command (in one process the answer to the status
    just published is already in), statuses stamped on the wall clock
    (utime) and the robot's clock (robot_utime, 1 ms apart), kMove."""
    scenario = load_scenario("panda_wipe")
    lcm = DrakeLcm("memq://")
    controller = AnsweringController(lcm)
    served = serve_simulated_driver(scenario, lcm, duration=0.1, low_pass_freq=1000.0)
    assert served.periods == 100 and served.fresh == 100 and served.stale == served.expired == 0, served
    assert served.fresh_fraction == 1.0 and "100 of them applied a fresh command (100.00%)" in served.line()
    statuses = controller.statuses
    assert np.all(np.diff([s.robot_utime for s in statuses]) == 1000)
    assert abs(statuses[-1].utime - time.time() * 1e6) < 5e6 and statuses[-1].robot_mode == 2
    assert statuses[-1].control_command_success_rate == 1.0
    assert np.max(np.abs(np.array(statuses[-1].joint_position) - np.array(statuses[0].joint_position))) < 1e-9


def test_the_simulated_driver_falls_back_to_damping_when_commands_expire():
    """The controller stops answering after 30 statuses: the driver applies its last
    command while younger than expire_sec (20 ms of wall clock here, the scenario's
    driver.expire_sec, which the driver reads as the controller does), then damping
    (catches a driver that applies a dead controller's last torque for ever, drops it at
    once, or ignores the scenario's expiry: 50 ms leaves fewer than 20 periods damped)."""
    scenario = load_scenario("panda_wipe")
    scenario = dataclasses.replace(scenario, driver=dataclasses.replace(scenario.driver, expire_sec=0.02))
    lcm = DrakeLcm("memq://")
    AnsweringController(lcm, stop_after=30)
    # the driver's wall clock [µs] advancing 500 µs each time it is read (a stamp and an
    # expiry check a period: 1 ms a period, whatever the machine's load)
    wall = itertools.count(0, 500)
    served = serve_simulated_driver(
        scenario, lcm, duration=0.1, low_pass_freq=1000.0, wall_utime=lambda: next(wall)
    )
    assert served.periods == 100 and served.fresh == 31, served  # 30 answers, the last also a period on
    assert served.commanded_periods == 30 and served.fresh_fraction == 1.0  # the controller's part: all fresh
    # about 20 periods stale (with 50 ms: about 50), then damping to the end
    assert 5 <= served.stale <= 25 and served.expired == 100 - 31 - served.stale, served


def test_the_pacing_answers_ctrl_c_within_its_slice():
    """The simulated driver's pacing (nsdrake/driver/run.py's Pacer) waits for the wall
    clock, at least t / rate (0.05 s of robot time at rate 1), and returns once Ctrl-C's
    flag is set although its target lies 1000 s ahead (catches Drake's Simulator pacing,
    which sleeps in C++ where Ctrl-C is not read: issue 34's `--realtime-rate 1e-9`
    answered only SIGKILL)."""
    from nsdrake.driver.run import Pacer
    from nsdrake.driver.stop import StopRequest

    stop = StopRequest()
    pacer = Pacer(1.0, stop)
    pacer.wait(0.0)
    start = time.perf_counter()
    pacer.wait(0.05)
    assert time.perf_counter() - start >= 0.049
    waiting = threading.Thread(target=pacer.wait, args=(1000.0,), daemon=True)
    waiting.start()
    time.sleep(0.1)
    assert waiting.is_alive()
    stop.requested = True
    waiting.join(timeout=30.0)
    assert not waiting.is_alive()


def test_a_paced_drive_is_paced():
    """--realtime-rate 0.02: a drive of 0.05 s of robot time (50 ticks) takes at least
    2.5 s of wall clock (catches the Pacer never called: unpaced, the 50 ticks take a few
    ms each)."""
    from nsdrake.driver.run import prepare

    drive = prepare(load_scenario("panda_wipe", duration=0.05), realtime_rate=0.02)
    start = time.perf_counter()
    run = drive.run()
    assert run.failure is None and time.perf_counter() - start >= 2.5


@pytest.mark.parametrize(
    ("option", "words"),
    [
        ({"expire_sec": 1e9}, "--expire-sec: must be at most 0.1 s"),
        ({"expire_sec": True}, "--expire-sec: must be a finite number > 0, got True"),
        ({"low_pass_freq": 0.0}, "--low-pass-freq: must be a cutoff in (0, 1000] Hz"),
    ],
)
def test_the_simulated_driver_s_own_call_bounds_its_options(option, words):
    """serve_simulated_driver, called from Python, refuses what the command line refuses
    (one line naming the option), before it builds or publishes anything (catches a bound
    kept in the CLI's parser alone)."""
    from nsdrake.driver.serve import SimulatedDriverOptionError

    lcm = DrakeLcm("memq://")
    heard = []
    lcm.Subscribe("PANDA_STATUS", heard.append)
    with pytest.raises(SimulatedDriverOptionError) as info:
        serve_simulated_driver(load_scenario("panda_wipe", duration=0.01), lcm, **option)
    assert str(info.value).startswith(words) and "\n" not in str(info.value)
    lcm.HandleSubscriptions(0)
    assert heard == []


def test_a_drive_keeps_every_parser_warning_in_full_in_its_folder(tmp_path, capsys):
    """As a run's (tests/control/test_model_sources.py), a drive's folder keeps every warning
    Drake's parser gave on the arm's file in model_warnings.txt: panda_wipe's arm with a
    friction Drake ignores on each of its seven joints gives seven, under the file's name.
    A drive that writes only its log's one line per file (the file missing) fails this."""
    text = (ROOT / "urdf" / "panda.urdf").read_text()
    for k in range(1, 8):
        joint = f'<joint name="panda_joint{k}" type="revolute">'
        assert joint in text
        text = text.replace(joint, f'{joint}<dynamics friction="0.5"/>')
    (tmp_path / "panda.urdf").write_text(text)
    config = tmp_path / "c.yaml"
    config.write_text(f"arm: {{urdf: {tmp_path / 'panda.urdf'}}}\n")
    out = tmp_path / "drive"
    argv = ["drive", "panda_wipe", "--config", str(config), "--simulated-driver", "--duration", "0.005"]
    main([*argv, "--realtime-rate", "0", "--out", str(out)])
    lines = (out / "model_warnings.txt").read_text().splitlines()
    assert lines[0] == "# panda.urdf: 7 warning(s) of Drake's parser", lines
    assert len(lines) == 8 and all("warning:" in line and "'friction'" in line for line in lines[1:])
    assert "model_warnings.txt" in (out / ".nsdrake-run").read_text()  # --overwrite knows it as nsdrake's
